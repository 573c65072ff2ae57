//! The matrix products of the network, f32 (BLAS) against bf16 (AMX tile units, where the
//! processor has them), on the calling thread; and the AMX unit's register-only peak
//! (`tdpbf16ps` on tiles already loaded: no memory traffic). Throughput is FLOP/s (criterion's
//! "elem/s"). Run on one core with one BLAS thread for the per-core figures of `docs/bench.md`:
//!
//! `OPENBLAS_NUM_THREADS=1 taskset -c 2 cargo bench -p rgm-benches --bench gemm`
//!
//! Shapes `(M, K, N)` of `c = a · b`, named by where the network runs them: the 1×1 convolutions
//! of the paper preset at 1,024 points (`rows×C_in->C_out`, the weight given transposed as the
//! layers pass it), their weight gradients (`doutᵀ · inp`, A transposed, K = the rows), the
//! attention's scores and weighted values (717 points, 4 heads of 256), and the `fast` preset's
//! training shapes at 384 points (K = 20 neighbours).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use ndarray::linalg::general_mat_mul;
use ndarray::{Array2, ArrayView2};
use rand::{rngs::StdRng, Rng, SeedableRng};
use rgm_nn::gemm::{
    bf16_available, f32_avx512_available, f32_mat_mul, mat_mul, register_peak_loop,
};
use rgm_nn::{Compute, Precision};

/// A (rows, cols) f32 matrix uniform in [-1, 1), reproducible from `seed`.
fn uniform(rows: usize, cols: usize, seed: u64) -> Array2<f32> {
    let mut rng = StdRng::seed_from_u64(seed);
    Array2::from_shape_simple_fn((rows, cols), || rng.gen_range(-1.0..1.0))
}

/// How an operand is stored: as given (row-major) or transposed (a `.t()` view).
#[derive(Clone, Copy)]
enum Layout {
    Plain,
    Transposed,
}

/// (name, M, K, N, layout of A, layout of B).
const SHAPES: [(&str, usize, usize, usize, Layout, Layout); 14] = {
    use Layout::{Plain as P, Transposed as T};
    [
        ("square_1024", 1024, 1024, 1024, P, P),
        ("linear_20480x64->64", 20480, 64, 64, P, T),
        ("linear_20480x128->256", 20480, 128, 256, P, T),
        ("linear_1024x512->512", 1024, 512, 512, P, T),
        ("linear_1024x1024->1024", 1024, 1024, 1024, P, T),
        ("dweight_64x20480x64", 64, 20480, 64, T, P),
        ("attention_scores_717x256x717", 717, 256, 717, P, T),
        ("attention_values_717x717x256", 717, 717, 256, P, P),
        ("fast_linear_7680x32->32", 7680, 32, 32, P, T),
        ("fast_linear_384x256->256", 384, 256, 256, P, T),
        ("fast_attention_scores_384x64x384", 384, 64, 384, P, T),
        // One block of 128 query rows (the training step's attention runs by such blocks).
        ("fast_attention_scores_block_128x64x384", 128, 64, 384, P, T),
        ("fast_attention_scores_block_128x32x384", 128, 32, 384, P, T),
        ("fast_attention_dvalues_384x384x32", 384, 384, 32, T, P),
    ]
};

fn operand(rows: usize, cols: usize, layout: Layout, seed: u64) -> Array2<f32> {
    match layout {
        Layout::Plain => uniform(rows, cols, seed),
        Layout::Transposed => uniform(cols, rows, seed), // viewed with .t()
    }
}

fn view(a: &Array2<f32>, layout: Layout) -> ArrayView2<'_, f32> {
    match layout {
        Layout::Plain => a.view(),
        Layout::Transposed => a.t(),
    }
}

fn gemm(c: &mut Criterion) {
    let mut group = c.benchmark_group("gemm");
    group.sample_size(10);
    let precisions: &[Precision] = if bf16_available() {
        &[Precision::F32, Precision::Bf16]
    } else {
        eprintln!("no AMX here: bf16 rows are not run");
        &[Precision::F32]
    };
    for (name, m, k, n, la, lb) in SHAPES {
        let (a, b) = (operand(m, k, la, 1), operand(k, n, lb, 2)); // (M, K), (K, N) as viewed
        let mut out = Array2::<f32>::zeros((m, n)); // (M, N)
        group.throughput(Throughput::Elements(2 * (m * k * n) as u64));
        for &p in precisions {
            let compute = Compute::with_precision(p);
            group.bench_function(BenchmarkId::new(p.name(), name), |bench| {
                bench.iter(|| mat_mul(1.0, &view(&a, la), &view(&b, lb), 0.0, &mut out, compute))
            });
        }
        group.bench_function(BenchmarkId::new("blas", name), |bench| {
            bench.iter(|| general_mat_mul(1.0, &view(&a, la), &view(&b, lb), 0.0, &mut out))
        });
        if f32_avx512_available() {
            group.bench_function(BenchmarkId::new("f32_avx512", name), |bench| {
                bench.iter(|| f32_mat_mul(1.0, view(&a, la), view(&b, lb), 0.0, out.view_mut()))
            });
        }
    }
    group.finish();
}

/// The AMX register peak: 10,000 steps of 4 `tdpbf16ps` (16 × 16 × 32 each) per iteration.
fn amx_peak(c: &mut Criterion) {
    let Some(madds) = register_peak_loop(1) else {
        eprintln!("no AMX here: no register peak");
        return;
    };
    let mut group = c.benchmark_group("amx_peak");
    group.sample_size(10);
    group.throughput(Throughput::Elements(2 * madds * 10_000));
    group.bench_function("tdpbf16ps_registers", |bench| {
        bench.iter(|| register_peak_loop(10_000))
    });
    group.finish();
}

criterion_group!(benches, gemm, amx_peak);
criterion_main!(benches);
