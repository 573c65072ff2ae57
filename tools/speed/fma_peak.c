/* One core's peak rate of the instructions rgm's matrix products are made of: 512- and 256-bit
 * f32 multiply-adds and, where the processor has AVX-512 BF16, 512-bit bf16 dot products, each
 * on 12 independent accumulators (enough to hide their latency) kept in registers (the inner
 * loops unrolled), nothing loaded from memory.
 *
 *   gcc -O2 -mavx512f -mfma -mavx512bf16 -o /tmp/fma_peak tools/speed/fma_peak.c
 *   chrt -f 50 /tmp/fma_peak          # or taskset -c 1; compare with docs/speed.md
 */
#include <immintrin.h>
#include <stdio.h>
#include <time.h>

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

#define STEPS 200000000L
#define ACCUMULATORS 12

int main(void) {
    __m512 z[ACCUMULATORS], zb = _mm512_set1_ps(1.0000001f), zc = _mm512_set1_ps(1e-7f);
    __m256 y[ACCUMULATORS], yb = _mm256_set1_ps(1.0000001f), yc = _mm256_set1_ps(1e-7f);
    for (int i = 0; i < ACCUMULATORS; i++) {
        z[i] = _mm512_set1_ps(i);
        y[i] = _mm256_set1_ps(i);
    }
    /* STEPS rounds of `op` on every accumulator, each op `flops` floating-point operations. */
#define TIME(label, flops, op)                                                        \
    do {                                                                              \
        double t0 = now();                                                            \
        for (long n = 0; n < STEPS; n++) {                                            \
            _Pragma("GCC unroll 12") for (int i = 0; i < ACCUMULATORS; i++) op;       \
        }                                                                             \
        printf("%s: %.1f GFLOP/s\n", label, STEPS * ACCUMULATORS * (flops) / (now() - t0) / 1e9); \
    } while (0)
    TIME("f32 512-bit FMA", 16.0 * 2, z[i] = _mm512_fmadd_ps(z[i], zb, zc));
    TIME("f32 256-bit FMA", 8.0 * 2, y[i] = _mm256_fmadd_ps(y[i], yb, yc));
    __m512bh one = (__m512bh)_mm512_set1_epi16(0x3f80), tiny = (__m512bh)_mm512_set1_epi16(0x3380);
    TIME("bf16 512-bit dot products", 32.0 * 2, z[i] = _mm512_dpbf16_ps(z[i], one, tiny));
    /* The accumulators are printed so that the loops are not optimised away. */
    float sum = 0, lanes[8];
    for (int i = 0; i < ACCUMULATORS; i++) {
        sum += _mm512_reduce_add_ps(z[i]);
        _mm256_storeu_ps(lanes, y[i]);
        for (int j = 0; j < 8; j++) sum += lanes[j];
    }
    printf("(checksum %g)\n", sum);
    return 0;
}
