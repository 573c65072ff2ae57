//! An f32 matrix product on AVX-512 (the processors that have it: Intel Skylake-SP and later,
//! AMD Zen 4 and later), for the shapes the network runs: a few hundred rows, K and N of 16 to
//! 1,024. The BLAS this workspace builds (OpenBLAS 0.3.20) runs its AVX2 kernels on every
//! processor, so on those with 512-bit multiply-add units half of their width stays idle.
//!
//! Goto's blocking: for each panel of at most [`NC`] columns of B and [`KC`] rows of K, B is
//! packed into 32-column strips (`(KC, 32)` each, rows contiguous); for each block of at most
//! [`MC`] rows of A, A is packed into 8-row strips (`(KC, 8)` each, a column of the strip
//! contiguous); the micro-kernel multiplies one A strip by one B strip into an 8 × 32 block of
//! sixteen 16-lane accumulators. Rows and columns past the edges are packed as zeros, so the
//! kernel has one shape; only its write-back into C is clipped. Every product runs on the
//! calling thread.
//!
//! The result is the f32 product up to the order of the additions: each entry of C is
//! accumulated over K in order within a panel of [`KC`], panels added in order.

use ndarray::{ArrayView2, ArrayViewMut2, Axis};
use std::cell::RefCell;

/// Rows of a micro-tile (and of a packed A strip).
const MR: usize = 8;
/// Columns of a micro-tile (and of a packed B strip): two 16-lane vectors.
const NR: usize = 32;
/// Depth of one packed panel: an A strip (8 KiB) and a B strip (32 KiB) meet in L1.
const KC: usize = 256;
/// Rows of A packed at once: 128 × 256 × 4 bytes = 128 KiB, in L2 beside the B panel.
const MC: usize = 128;
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
    a: Vec<f32>, // (MC/8, KC, 8) strips of A
    b: Vec<f32>, // (NC/32, KC, 32) strips of B
}

thread_local! {
    static PACKED: RefCell<Packed> = RefCell::new(Packed::default());
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
    let ((m, k), n) = (a.dim(), b.ncols());
    assert!(
        b.nrows() == k && c.dim() == (m, n),
        "f32_mat_mul: a {:?} · b {:?} into c {:?}",
        a.shape(),
        b.shape(),
        c.shape()
    );
    assert!(available(), "f32_mat_mul needs AVX-512 F");
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        scale(c.view_mut(), beta); // alpha · (empty sum) = 0
        return;
    }
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
                for i0 in (0..m).step_by(MC) {
                    let mc = MC.min(m - i0);
                    pack_a(
                        a.slice(ndarray::s![i0..i0 + mc, p0..p0 + kc]),
                        &mut packed.a,
                    );
                    for (si, a_strip) in packed.a.chunks_exact(kc * MR).enumerate() {
                        let rows = (i0 + si * MR)..(i0 + si * MR + MR).min(i0 + mc);
                        for (sj, b_strip) in packed.b.chunks_exact(kc * NR).enumerate() {
                            let cols = (j0 + sj * NR)..(j0 + sj * NR + NR).min(j0 + nc);
                            let dst = c.slice_mut(ndarray::s![rows.clone(), cols]);
                            // SAFETY: `available()` was checked above; the strips hold kc
                            // packed columns of 8 and rows of 32 (chunks_exact).
                            unsafe { micro_tile(kc, a_strip, b_strip, alpha, beta, dst) };
                        }
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

/// Packs `a` (mc, kc) into `out` as 8-row strips: strip s holds, for each k, the 8 values of
/// rows 8s..8s + 8 at column k (zero past row mc).
fn pack_a(a: ArrayView2<'_, f32>, out: &mut Vec<f32>) {
    let (mc, kc) = a.dim();
    let strips = mc.div_ceil(MR);
    out.clear();
    out.resize(strips * kc * MR, 0.0);
    if a.strides()[0] == 1 {
        // Columns contiguous (a transposed view, as `doutᵀ · inp`): 8 values at a time.
        for (k, col) in a.axis_iter(Axis(1)).enumerate() {
            let col = col.to_slice().expect("unit row stride");
            for (s, rows) in col.chunks(MR).enumerate() {
                out[(s * kc + k) * MR..][..rows.len()].copy_from_slice(rows);
            }
        }
    } else {
        for (i, row) in a.axis_iter(Axis(0)).enumerate() {
            let base = (i / MR) * kc * MR + i % MR;
            for (k, &x) in row.iter().enumerate() {
                out[base + k * MR] = x;
            }
        }
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
                out[(s * kc + k) * NR..][..cols.len()].copy_from_slice(cols);
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

/// One 8 × 32 block: `c = alpha · (a_strip · b_strip) + beta · c` over the rows and columns `c`
/// has (at most 8 × 32; `beta = 0` ignores what `c` held).
///
/// # Safety
/// The processor must have AVX-512 F; `a` holds `kc · 8` and `b` `kc · 32` values.
#[target_feature(enable = "avx512f")]
unsafe fn micro_tile(
    kc: usize,
    a: &[f32],
    b: &[f32],
    alpha: f32,
    beta: f32,
    mut c: ArrayViewMut2<'_, f32>,
) {
    use std::arch::x86_64::*;
    debug_assert!(a.len() == kc * MR && b.len() == kc * NR);
    let mut acc = [_mm512_setzero_ps(); 2 * MR]; // (8, 2) vectors: row r, columns 16h..16h + 16
    let (mut pa, mut pb) = (a.as_ptr(), b.as_ptr());
    for _ in 0..kc {
        // SAFETY: pa and pb stay inside the strips: kc steps of 8 and of 32 values.
        let (b0, b1) = unsafe { (_mm512_loadu_ps(pb), _mm512_loadu_ps(pb.add(16))) };
        for r in 0..MR {
            // SAFETY: as above.
            let x = _mm512_set1_ps(unsafe { *pa.add(r) });
            acc[2 * r] = _mm512_fmadd_ps(x, b0, acc[2 * r]);
            acc[2 * r + 1] = _mm512_fmadd_ps(x, b1, acc[2 * r + 1]);
        }
        // SAFETY: one step past the last value at most, never read.
        unsafe {
            pa = pa.add(MR);
            pb = pb.add(NR);
        }
    }
    let (rows, cols) = c.dim();
    let valpha = _mm512_set1_ps(alpha);
    if c.strides()[1] == 1 {
        let vbeta = _mm512_set1_ps(beta);
        for r in 0..rows {
            let row = c.row_mut(r).into_slice().expect("unit column stride");
            for h in 0..2 {
                let len = cols.saturating_sub(16 * h).min(16);
                if len == 0 {
                    break;
                }
                let mask: __mmask16 = if len == 16 { !0 } else { (1u16 << len) - 1 };
                let at = row[16 * h..].as_mut_ptr();
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
        for (r, chunk) in block.chunks_exact_mut(16).enumerate() {
            // SAFETY: each chunk is 16 floats.
            unsafe { _mm512_storeu_ps(chunk.as_mut_ptr(), _mm512_mul_ps(valpha, acc[r])) };
        }
        for ((r, col), x) in c.indexed_iter_mut() {
            let v = block[r * NR + col];
            *x = if beta == 0.0 { v } else { v + beta * *x };
        }
    }
}
