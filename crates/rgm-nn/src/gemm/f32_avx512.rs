//! An f32 matrix product on AVX-512 (the processors that have it: Intel Skylake-SP and later,
//! AMD Zen 4 and later), for the shapes the network runs: a few hundred rows, K and N of 16 to
//! 1,024. The BLAS this workspace builds (OpenBLAS 0.3.20) runs its AVX2 kernels on every
//! processor, so on those with 512-bit multiply-add units half of their width stays idle.
//!
//! Goto's blocking: for each panel of at most [`NC`] columns of B and [`KC`] rows of K, B is
//! packed into 32-column strips (`(KC, 32)` each, rows contiguous, zeros past the last
//! column); then each strip of 8 rows of A, read in place at its strides (8 KiB at most, it
//! stays in L1 while it meets every B strip of the panel), is multiplied by each B strip into
//! an 8 × 32 block of sixteen 16-lane accumulators, whose write-back into C is clipped at the
//! edges. Every product runs on the calling thread.
//!
//! The result is the f32 product up to the order of the additions: each entry of C is
//! accumulated over K in order within a panel of [`KC`], panels added in order.

use ndarray::{ArrayView2, ArrayViewMut2, Axis};
use std::cell::RefCell;

/// Rows of a micro-tile (and of a packed A strip).
const MR: usize = 8;
/// Columns of a micro-tile (and of a packed B strip): two 16-lane vectors.
const NR: usize = 32;
/// Depth of one panel: an A strip (8 KiB) and a B strip (32 KiB) meet in L1.
const KC: usize = 256;
/// Columns of B packed at once: 256 × 512 × 4 bytes = 512 KiB of L2.
const NC: usize = 512;

/// Whether this processor runs [`f32_mat_mul`] (AVX-512 F). Checked once per process.
pub fn available() -> bool {
    use std::sync::OnceLock;
    static AVAILABLE: OnceLock<bool> = OnceLock::new();
    *AVAILABLE.get_or_init(|| std::arch::is_x86_feature_detected!("avx512f"))
}

/// The packed operands, kept per thread so that repeated products allocate nothing.
#[derive(Default)]
struct Packed {
    a: Vec<f32>, // (KC, 8) one strip of A, for the rows at its edge and odd strides
    b: Vec<f32>, // (NC/32, KC, 32) strips of B
}

thread_local! {
    static PACKED: RefCell<Packed> = RefCell::new(Packed::default());
}

/// An operand or result in memory: element (i, j) at `ptr + i·rows + j·cols`.
#[derive(Clone, Copy)]
struct Strided<P> {
    ptr: P,
    rows: isize,
    cols: isize,
}

/// `c = alpha · a · b + beta · c` in f32, `a`: (M, K), `b`: (K, N), `c`: (M, N), any strides;
/// `beta = 0` ignores what `c` held. Panics if the shapes disagree or the processor lacks
/// AVX-512 ([`available`]).
pub fn f32_mat_mul(
    alpha: f32,
    a: ArrayView2<'_, f32>,
    b: ArrayView2<'_, f32>,
    beta: f32,
    mut c: ArrayViewMut2<'_, f32>,
) {
    let (m, n) = super::check_shapes("f32_mat_mul", &a, &b, &c);
    let k = a.ncols();
    assert!(available(), "f32_mat_mul needs AVX-512 F");
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        scale(c.view_mut(), beta); // alpha · (empty sum) = 0
        return;
    }
    // A is read in place where a strip's 8 rows or its K values lie at one stride each (every
    // view ndarray makes); only the last strip, when M is not a multiple of 8, is packed.
    let (a_rows, a_cols) = (a.strides()[0], a.strides()[1]);
    let c_mem = Strided {
        ptr: c.as_mut_ptr(),
        rows: c.strides()[0],
        cols: c.strides()[1],
    };
    PACKED.with(|packed| {
        let packed = &mut *packed.borrow_mut();
        for j0 in (0..n).step_by(NC) {
            let nc = NC.min(n - j0);
            for p0 in (0..k).step_by(KC) {
                let kc = KC.min(k - p0);
                pack_b(
                    b.slice(ndarray::s![p0..p0 + kc, j0..j0 + nc]),
                    &mut packed.b,
                );
                // The first panel along K applies beta; the later ones add to it.
                let beta = if p0 == 0 { beta } else { 1.0 };
                for i0 in (0..m).step_by(MR) {
                    let rows = MR.min(m - i0);
                    let a_mem = if rows == MR {
                        Strided {
                            // SAFETY: (i0, p0) is inside `a`.
                            ptr: unsafe {
                                a.as_ptr()
                                    .offset(i0 as isize * a_rows + p0 as isize * a_cols)
                            },
                            rows: a_rows,
                            cols: a_cols,
                        }
                    } else {
                        pack_a(a.slice(ndarray::s![i0.., p0..p0 + kc]), &mut packed.a);
                        Strided {
                            ptr: packed.a.as_ptr(),
                            rows: 1,
                            cols: MR as isize,
                        }
                    };
                    for (sj, b_strip) in packed.b.chunks_exact(kc * NR).enumerate() {
                        let j = j0 + sj * NR;
                        let cols = NR.min(n - j);
                        let c_tile = Strided {
                            // SAFETY: (i0, j) is inside `c`.
                            ptr: unsafe {
                                c_mem
                                    .ptr
                                    .offset(i0 as isize * c_mem.rows + j as isize * c_mem.cols)
                            },
                            ..c_mem
                        };
                        // SAFETY: `available()` was checked above; `a_mem` reaches kc columns
                        // of 8 rows, the strip kc rows of 32, `c_tile` rows × cols of `c`.
                        unsafe {
                            micro_tile(kc, a_mem, b_strip, alpha, beta, c_tile, (rows, cols))
                        };
                    }
                }
            }
        }
    });
}

/// `c = beta · c`, with `beta = 0` writing zeros whatever `c` held.
fn scale(mut c: ArrayViewMut2<'_, f32>, beta: f32) {
    if beta == 0.0 {
        c.fill(0.0);
    } else if beta != 1.0 {
        c.mapv_inplace(|x| beta * x);
    }
}

/// Packs the first kc columns of `a` (at most 8 rows) into `out` (kc, 8): for each k, the
/// values of the rows at column k, zero past the last row.
fn pack_a(a: ArrayView2<'_, f32>, out: &mut Vec<f32>) {
    let kc = a.ncols();
    out.clear();
    out.resize(kc * MR, 0.0);
    for ((i, k), &x) in a.indexed_iter() {
        out[k * MR + i] = x;
    }
}

/// Packs `b` (kc, nc) into `out` as 32-column strips: strip s holds, for each k, the 32 values
/// of row k at columns 32s..32s + 32 (zero past column nc).
fn pack_b(b: ArrayView2<'_, f32>, out: &mut Vec<f32>) {
    let (kc, nc) = b.dim();
    let strips = nc.div_ceil(NR);
    out.clear();
    out.resize(strips * kc * NR, 0.0);
    if b.strides()[1] == 1 {
        // Rows contiguous: 32 values at a time.
        for (k, row) in b.axis_iter(Axis(0)).enumerate() {
            let row = row.to_slice().expect("unit column stride");
            for (s, cols) in row.chunks(NR).enumerate() {
                let dst = &mut out[(s * kc + k) * NR..][..cols.len()];
                for (d, &x) in dst.iter_mut().zip(cols) {
                    *d = x;
                }
            }
        }
    } else {
        // Columns contiguous (a transposed view, as `inp · weightᵀ`) or strided.
        for (j, col) in b.axis_iter(Axis(1)).enumerate() {
            let base = (j / NR) * kc * NR + j % NR;
            for (k, &x) in col.iter().enumerate() {
                out[base + k * NR] = x;
            }
        }
    }
}

/// One 8 × 32 block: `c = alpha · (a · b_strip) + beta · c` over the first `rows × cols` of
/// the block (`beta = 0` ignores what `c` held). `a` is 8 rows × kc; rows past `rows` may be
/// anything finite or packed zeros, as they are never written.
///
/// # Safety
/// The processor must have AVX-512 F; `a` reaches 8 rows of kc values, `b` holds `kc · 32`
/// values, `c` reaches `rows × cols` values, `rows ≤ 8`, `cols ≤ 32`.
#[target_feature(enable = "avx512f")]
unsafe fn micro_tile(
    kc: usize,
    a: Strided<*const f32>,
    b: &[f32],
    alpha: f32,
    beta: f32,
    c: Strided<*mut f32>,
    (rows, cols): (usize, usize),
) {
    use std::arch::x86_64::*;
    debug_assert!(b.len() == kc * NR && rows <= MR && cols <= NR);
    let mut acc = [_mm512_setzero_ps(); 2 * MR]; // (8, 2) vectors: row r, columns 16h..16h + 16
    let offsets: [isize; MR] = std::array::from_fn(|r| r as isize * a.rows);
    let (mut pa, mut pb) = (a.ptr, b.as_ptr());
    for _ in 0..kc {
        // SAFETY: pa and pb stay inside A's strip and B's packed strip for kc steps.
        let (b0, b1) = unsafe { (_mm512_loadu_ps(pb), _mm512_loadu_ps(pb.add(16))) };
        for r in 0..MR {
            // SAFETY: as above.
            let x = _mm512_set1_ps(unsafe { *pa.offset(offsets[r]) });
            acc[2 * r] = _mm512_fmadd_ps(x, b0, acc[2 * r]);
            acc[2 * r + 1] = _mm512_fmadd_ps(x, b1, acc[2 * r + 1]);
        }
        // SAFETY: one step past the last value at most, never read.
        unsafe {
            pa = pa.offset(a.cols);
            pb = pb.add(NR);
        }
    }
    let valpha = _mm512_set1_ps(alpha);
    if c.cols == 1 {
        let vbeta = _mm512_set1_ps(beta);
        for r in 0..rows {
            for h in 0..2 {
                let len = cols.saturating_sub(16 * h).min(16);
                if len == 0 {
                    break;
                }
                let mask: __mmask16 = if len == 16 { !0 } else { (1u16 << len) - 1 };
                // SAFETY: row r, columns 16h.. of the block are inside `c`.
                let at = unsafe { c.ptr.offset(r as isize * c.rows + 16 * h as isize) };
                let mut v = _mm512_mul_ps(valpha, acc[2 * r + h]);
                if beta != 0.0 {
                    // SAFETY: the mask covers the `len` values of this row from `at`.
                    let old = unsafe { _mm512_maskz_loadu_ps(mask, at) };
                    v = _mm512_fmadd_ps(vbeta, old, v);
                }
                // SAFETY: as above.
                unsafe { _mm512_mask_storeu_ps(at, mask, v) };
            }
        }
    } else {
        let mut block = [0f32; MR * NR]; // (8, 32) row-major
        for (v, chunk) in acc.iter().zip(block.chunks_exact_mut(16)) {
            // SAFETY: each chunk is 16 floats.
            unsafe { _mm512_storeu_ps(chunk.as_mut_ptr(), _mm512_mul_ps(valpha, *v)) };
        }
        for r in 0..rows {
            for j in 0..cols {
                // SAFETY: (r, j) is inside the block of `c`.
                let x = unsafe { &mut *c.ptr.offset(r as isize * c.rows + j as isize * c.cols) };
                let v = block[r * NR + j];
                *x = if beta == 0.0 { v } else { v + beta * *x };
            }
        }
    }
}
