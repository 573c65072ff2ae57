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

use crate::scalar::Then;
use ndarray::{ArrayView1, ArrayView2, ArrayViewMut2};
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
    a: Vec<f32>,    // (KC, 8) one strip of A, for the rows at its edge and odd strides
    b: Vec<f32>,    // (NC/32, KC, 32) strips of B
    bias: Vec<f32>, // (N rounded up to 32) the bias of `f32_mat_mul_bias`, zero-padded
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
/// AVX-512 (`available`).
pub fn f32_mat_mul(
    alpha: f32,
    a: ArrayView2<'_, f32>,
    b: ArrayView2<'_, f32>,
    beta: f32,
    c: ArrayViewMut2<'_, f32>,
) {
    product(alpha, a, b, beta, Finish::default(), c);
}

/// `c = a · b` finished by `then` in the product's write-back (see [`Then`]): the values
/// `then_by_passes` gives, bit for bit, without its passes over C. Panics as
/// [`f32_mat_mul`], or if `then`'s bias or `y` does not match C.
pub fn f32_mat_mul_then(
    a: ArrayView2<'_, f32>,
    b: ArrayView2<'_, f32>,
    then: Then<'_, f32>,
    c: ArrayViewMut2<'_, f32>,
) {
    let n = b.ncols();
    match then {
        Then::Layer { bias, relu } => {
            if let Some(bias) = &bias {
                assert_eq!(
                    bias.len(),
                    n,
                    "f32_mat_mul_then: bias of {} values, {n} columns",
                    bias.len()
                );
            }
            let finish = Finish {
                bias,
                relu,
                ..Finish::default()
            };
            product(1.0, a, b, 0.0, finish, c);
        }
        Then::ReluGrad(y) => {
            assert_eq!(
                y.dim(),
                c.dim(),
                "f32_mat_mul_then: y {:?}, c {:?}",
                y.shape(),
                c.shape()
            );
            if y.strides()[1] != 1 || c.strides()[1] != 1 {
                // The masked write-back reads rows of y and writes rows of C as vectors; the
                // passes run this f32 product (the default compute settings).
                return super::then_by_passes(a, b, then, c, crate::Compute::default());
            }
            let finish = Finish {
                keep: Some((y.as_ptr(), y.strides()[0])),
                ..Finish::default()
            };
            product(1.0, a, b, 0.0, finish, c);
        }
    }
}

/// What the write-back of [`product`] does besides `alpha · a · b + beta · c`.
#[derive(Clone, Copy, Default)]
struct Finish<'a> {
    /// Added to every row (N values), with the first panel along K.
    bias: Option<ArrayView1<'a, f32>>,
    /// `max(·, 0)` on the final values, with the last panel along K.
    relu: bool,
    /// `(y, y's row stride)`: the final values kept only where `y` (M, N, rows contiguous,
    /// C's rows contiguous too) is positive, with the last panel along K.
    keep: Option<(*const f32, isize)>,
}

/// `c = alpha · a · b + beta · c`, finished as `finish` says: [`f32_mat_mul`] and
/// [`f32_mat_mul_then`].
fn product(
    alpha: f32,
    a: ArrayView2<'_, f32>,
    b: ArrayView2<'_, f32>,
    beta: f32,
    finish: Finish<'_>,
    mut c: ArrayViewMut2<'_, f32>,
) {
    let (m, n) = super::check_shapes("f32_mat_mul", &a, &b, &c);
    let k = a.ncols();
    assert!(available(), "f32_mat_mul needs AVX-512 F");
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        scale(c.view_mut(), beta); // alpha · (empty sum) = 0, kept or not
        if let Some(bias) = finish.bias {
            c += &bias;
        }
        if finish.relu {
            c.mapv_inplace(|x| if x > 0.0 { x } else { 0.0 });
        }
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
        // The bias padded with zeros to whole 32-column strips, so that every tile reads 32.
        let bias = finish.bias.map(|bias| {
            packed.bias.clear();
            packed.bias.extend(bias.iter());
            packed.bias.resize(n.next_multiple_of(NR), 0.0);
            &packed.bias[..]
        });
        for j0 in (0..n).step_by(NC) {
            let nc = NC.min(n - j0);
            for p0 in (0..k).step_by(KC) {
                let kc = KC.min(k - p0);
                // SAFETY: `available()` was checked above.
                let b_packed = unsafe {
                    pack_b(
                        b.slice(ndarray::s![p0..p0 + kc, j0..j0 + nc]),
                        &mut packed.b,
                    )
                };
                // The first panel along K applies beta and the bias; the later ones add to it;
                // the last applies the ReLU.
                let (beta, bias) = if p0 == 0 { (beta, bias) } else { (1.0, None) };
                let last = p0 + kc == k;
                let keep = finish.keep.filter(|_| last);
                let tile: Tile = match (finish.relu && last, keep.is_some()) {
                    (false, false) => micro_tile::<false, false>,
                    (true, false) => micro_tile::<true, false>,
                    (false, true) => micro_tile::<false, true>,
                    (true, true) => micro_tile::<true, true>,
                };
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
                    for (sj, b_strip) in b_packed.chunks_exact(kc * NR).enumerate() {
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
                        // (i0, j) of y, which has C's shape (unread without it).
                        let (y, y_rows) = keep.unwrap_or((std::ptr::null(), 0));
                        let y_tile = (y.wrapping_offset(i0 as isize * y_rows + j as isize), y_rows);
                        // SAFETY: `available()` was checked above; `a_mem` reaches kc columns
                        // of 8 rows, the strip kc rows of 32, `c_tile` (and `y_tile` where
                        // `tile` reads it) rows × cols of `c` (and y), whose rows are
                        // contiguous where y is read.
                        let tile_bias = bias.map(|bias| &bias[j..j + NR]);
                        unsafe {
                            tile(
                                kc,
                                a_mem,
                                b_strip,
                                alpha,
                                beta,
                                tile_bias,
                                y_tile,
                                c_tile,
                                (rows, cols),
                            )
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

/// Packs `b` (kc, nc) into `out` as 32-column strips and returns them: strip s holds, for each
/// k, the 32 values of row k at columns 32s..32s + 32 (zero past column nc). Every value of the
/// returned strips is written, so `out` is only grown, never cleared.
///
/// # Safety
/// The processor must have AVX-512 F.
#[target_feature(enable = "avx512f")]
unsafe fn pack_b<'o>(b: ArrayView2<'_, f32>, out: &'o mut Vec<f32>) -> &'o [f32] {
    use std::arch::x86_64::*;
    let (kc, nc) = b.dim();
    let strips = nc.div_ceil(NR);
    let len = strips * kc * NR;
    if out.len() < len {
        out.resize(len, 0.0);
    }
    let out = &mut out[..len];
    // The first `n` of 16 lanes (all for n ≥ 16, none for n = 0).
    let mask = |n: usize| -> __mmask16 {
        if n >= 16 {
            !0
        } else {
            (1u16 << n) - 1
        }
    };
    let (rows, cols) = (b.strides()[0], b.strides()[1]);
    let base = b.as_ptr();
    /// Rows between a row being packed and the row fetched for later.
    const AHEAD: isize = 8;
    if cols == 1 {
        // Rows contiguous: 16 values at a time, masked at the last column (zeros beyond); strip
        // by strip, so that each strip is written in order.
        for s in 0..strips {
            for k in 0..kc {
                // SAFETY: row k of `b` holds nc values from here.
                let row = unsafe { base.offset(k as isize * rows) };
                // The strip's piece of the row AHEAD rows further, fetched while these are
                // copied (a prefetch does not fault, wherever it points).
                let ahead = row.wrapping_offset(AHEAD * rows).wrapping_add(s * NR);
                _mm_prefetch::<_MM_HINT_T0>(ahead as *const i8);
                _mm_prefetch::<_MM_HINT_T0>(ahead.wrapping_add(16) as *const i8);
                for h in 0..2 {
                    let j = s * NR + 16 * h;
                    let m = mask(nc.saturating_sub(j));
                    // SAFETY: the mask keeps the load inside the row; the store stays in the
                    // strip's row k.
                    unsafe {
                        let v = _mm512_maskz_loadu_ps(m, row.add(j.min(nc)));
                        _mm512_storeu_ps(out.as_mut_ptr().add((s * kc + k) * NR + 16 * h), v);
                    }
                }
            }
        }
    } else if rows == 1 {
        // Columns contiguous (a transposed view, as `inp · weightᵀ` and the attention scores):
        // 16 columns × 16 rows read as 16 column vectors, transposed in registers into the
        // strip's 16 row pieces.
        let mut block = [_mm512_setzero_ps(); 16];
        for s in 0..strips {
            for h in 0..2 {
                let j0 = s * NR + 16 * h;
                for k0 in (0..kc).step_by(16) {
                    let m = mask(kc - k0);
                    for (c, v) in block.iter_mut().enumerate() {
                        *v = if j0 + c < nc {
                            // SAFETY: column j0 + c holds kc values; the mask stops at kc.
                            unsafe {
                                _mm512_maskz_loadu_ps(
                                    m,
                                    base.offset((j0 + c) as isize * cols + k0 as isize),
                                )
                            }
                        } else {
                            _mm512_setzero_ps()
                        };
                    }
                    // SAFETY: the processor has AVX-512 F (this function's contract).
                    unsafe { transpose_16x16(&mut block) };
                    for (r, v) in block.iter().enumerate().take((kc - k0).min(16)) {
                        // SAFETY: row k0 + r < kc of strip s, lanes 16h..16h + 16.
                        unsafe {
                            _mm512_storeu_ps(
                                out.as_mut_ptr().add((s * kc + k0 + r) * NR + 16 * h),
                                *v,
                            )
                        };
                    }
                }
            }
        }
    } else {
        // Strided both ways (views of every n-th element): one value at a time.
        out.fill(0.0);
        for ((k, j), &x) in b.indexed_iter() {
            out[((j / NR) * kc + k) * NR + j % NR] = x;
        }
    }
    out
}

/// Transposes the 16 × 16 block whose row i is `r[i]`: afterwards `r[i]` holds column i.
///
/// # Safety
/// The processor must have AVX-512 F.
#[inline]
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn transpose_16x16(r: &mut [std::arch::x86_64::__m512; 16]) {
    use std::arch::x86_64::*;
    // 1. Interleave rows 2i and 2i + 1 by single values: t[2i] holds, per 128-bit lane,
    //    (r2i[0], r2i+1[0], r2i[1], r2i+1[1]), t[2i + 1] the lane's upper halves.
    let mut t = [_mm512_setzero_ps(); 16];
    for i in 0..8 {
        t[2 * i] = _mm512_unpacklo_ps(r[2 * i], r[2 * i + 1]);
        t[2 * i + 1] = _mm512_unpackhi_ps(r[2 * i], r[2 * i + 1]);
    }
    // 2. Interleave those by pairs: each 128-bit lane now holds one column of 4 rows.
    let (lo, hi) = (
        |a: __m512, b: __m512| {
            _mm512_castpd_ps(_mm512_unpacklo_pd(_mm512_castps_pd(a), _mm512_castps_pd(b)))
        },
        |a: __m512, b: __m512| {
            _mm512_castpd_ps(_mm512_unpackhi_pd(_mm512_castps_pd(a), _mm512_castps_pd(b)))
        },
    );
    for g in 0..4 {
        let (a, b) = (4 * g, 4 * g + 2);
        r[4 * g] = lo(t[a], t[b]);
        r[4 * g + 1] = hi(t[a], t[b]);
        r[4 * g + 2] = lo(t[a + 1], t[b + 1]);
        r[4 * g + 3] = hi(t[a + 1], t[b + 1]);
    }
    // 3. and 4. Gather the 128-bit lanes of the four groups of four rows.
    for g in 0..2 {
        for i in 0..4 {
            let (a, b) = (8 * g + i, 8 * g + 4 + i);
            t[8 * g + i] = _mm512_shuffle_f32x4::<0x88>(r[a], r[b]);
            t[8 * g + 4 + i] = _mm512_shuffle_f32x4::<0xdd>(r[a], r[b]);
        }
    }
    for i in 0..8 {
        r[i] = _mm512_shuffle_f32x4::<0x88>(t[i], t[8 + i]);
        r[8 + i] = _mm512_shuffle_f32x4::<0xdd>(t[i], t[8 + i]);
    }
}

/// A [`micro_tile`] instance, chosen per panel.
type Tile = unsafe fn(
    usize,
    Strided<*const f32>,
    &[f32],
    f32,
    f32,
    Option<&[f32]>,
    (*const f32, isize),
    Strided<*mut f32>,
    (usize, usize),
);

/// One 8 × 32 block: `c = alpha · (a · b_strip) + beta · c (+ bias)`, then `max(·, 0)` if
/// `RELU`, then `⊙ [y > 0]` if `KEEP` (`y` = y's block and row stride), over the first
/// `rows × cols` of the block (`beta = 0` ignores what `c` held; `bias` holds the block's 32
/// columns' values). `a` is 8 rows × kc; rows past `rows` may be anything finite or packed
/// zeros, as they are never written. One instance per finish: the plain one's write-back
/// stays short enough to unroll, with the accumulators in their registers.
///
/// # Safety
/// The processor must have AVX-512 F; `a` reaches 8 rows of kc values, `b` holds `kc · 32`
/// values, `c` (and y if `KEEP`) reaches `rows × cols` values, `rows ≤ 8`, `cols ≤ 32`; if
/// `KEEP`, C's rows are contiguous.
// Each scalar its own argument, so that all arrive in registers (an aggregate of them would
// pass through memory, and loading it stalls each call).
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx512f")]
unsafe fn micro_tile<const RELU: bool, const KEEP: bool>(
    kc: usize,
    a: Strided<*const f32>,
    b: &[f32],
    alpha: f32,
    beta: f32,
    bias: Option<&[f32]>,
    (y, y_rows): (*const f32, isize),
    c: Strided<*mut f32>,
    (rows, cols): (usize, usize),
) {
    use std::arch::x86_64::*;
    debug_assert!(b.len() == kc * NR && rows <= MR && cols <= NR);
    debug_assert!(!KEEP || c.cols == 1);
    if c.cols == 1 {
        // The block's rows of C and the next block's to the right, fetched while the products
        // run (the write-backs read or write them; C is often far from this core's caches).
        for r in 0..rows {
            // SAFETY: a prefetch does not fault; row r of the block starts inside `c`.
            let at = unsafe { c.ptr.offset(r as isize * c.rows) };
            _mm_prefetch::<_MM_HINT_T0>(at as *const i8);
            _mm_prefetch::<_MM_HINT_T0>(at.wrapping_add(16) as *const i8);
            _mm_prefetch::<_MM_HINT_T0>(at.wrapping_add(32) as *const i8);
            _mm_prefetch::<_MM_HINT_T0>(at.wrapping_add(48) as *const i8);
            if KEEP {
                // y's row too (a ReLU output of the forward pass, long out of cache).
                let y_at = y.wrapping_offset(r as isize * y_rows);
                _mm_prefetch::<_MM_HINT_T0>(y_at as *const i8);
                _mm_prefetch::<_MM_HINT_T0>(y_at.wrapping_add(16) as *const i8);
            }
        }
    }
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
        // The columns of each half of the block that lie in C.
        let masks: [__mmask16; 2] = std::array::from_fn(|h| {
            let len = cols.saturating_sub(16 * h).min(16);
            if len == 16 {
                !0
            } else {
                (1u16 << len) - 1
            }
        });
        // Row r of the block, if it lies in C.
        macro_rules! write_row {
            ($r:literal) => {
                if $r < rows {
                    for (h, &mask) in masks.iter().enumerate() {
                        if mask == 0 {
                            continue;
                        }
                        // SAFETY: row r, columns 16h.. of the block are inside `c`.
                        let at = unsafe { c.ptr.offset($r * c.rows + 16 * h as isize) };
                        let mut v = _mm512_mul_ps(valpha, acc[2 * $r + h]);
                        if beta != 0.0 {
                            // SAFETY: the mask covers the `len` values of this row from `at`.
                            let old = unsafe { _mm512_maskz_loadu_ps(mask, at) };
                            v = _mm512_fmadd_ps(vbeta, old, v);
                        }
                        if let Some(bias) = bias {
                            // SAFETY: `bias` holds 32 values.
                            let bias = unsafe { _mm512_loadu_ps(bias.as_ptr().add(16 * h)) };
                            v = _mm512_add_ps(v, bias);
                        }
                        if RELU {
                            // max(v, 0) gives 0 for NaN and -0, as ReLU.
                            v = _mm512_max_ps(v, _mm512_setzero_ps());
                        }
                        if KEEP {
                            // SAFETY: as `at`, in y.
                            let y = unsafe {
                                _mm512_maskz_loadu_ps(mask, y.offset($r * y_rows + 16 * h as isize))
                            };
                            let positive = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(y, _mm512_setzero_ps());
                            v = _mm512_maskz_mov_ps(positive, v);
                        }
                        // SAFETY: as above.
                        unsafe { _mm512_mask_storeu_ps(at, mask, v) };
                    }
                }
            };
        }
        // Unrolled by hand, so that every accumulator stays in its register (a loop over the
        // rows keeps them on the stack once the write-back grows).
        const _: () = assert!(MR == 8, "one write_row! per row");
        write_row!(0);
        write_row!(1);
        write_row!(2);
        write_row!(3);
        write_row!(4);
        write_row!(5);
        write_row!(6);
        write_row!(7);
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
                let v = if beta == 0.0 { v } else { v + beta * *x };
                let v = bias.map_or(v, |bias| v + bias[j]);
                *x = match RELU {
                    true if v > 0.0 => v,
                    true => 0.0, // NaN and -0 too, as ReLU
                    false => v,
                };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{s, Array2};

    #[test]
    fn every_layout_of_b_packs_to_the_same_strips() {
        if !available() {
            eprintln!("no AVX-512 F: the kernel does not run here");
            return;
        }
        // K = 300: a full panel of 256 and one of 44 (two blocks of 16 and a remainder);
        // N = 45: a full strip and one of 13 columns.
        let (m, k, n) = (37, 300, 45);
        let value = |i: usize, j: usize| ((i * 31 + j * 17) % 23) as f32 - 11.0;
        let a = Array2::from_shape_fn((m, k), |(i, j)| value(i, j));
        let b = Array2::from_shape_fn((k, n), |(i, j)| value(j, i + 1));
        let bt = b.t().to_owned(); // (N, K) stored: `.t()` has contiguous columns
        let wide = Array2::from_shape_fn((k, 2 * n), |(i, j)| match j % 2 {
            0 => b[(i, j / 2)],
            _ => f32::NAN,
        });
        let strided = wide.slice(s![.., ..;2]);
        let product = |b: ArrayView2<'_, f32>| {
            let mut c = Array2::zeros((m, n));
            f32_mat_mul(1.0, a.view(), b, 0.0, c.view_mut());
            c
        };
        let plain = product(b.view());
        assert_eq!(product(bt.t()), plain, "transposed view");
        assert_eq!(product(strided), plain, "strided view");
    }

    #[test]
    fn the_register_transpose_moves_each_value_to_its_mirror() {
        if !available() {
            eprintln!("no AVX-512 F: the transpose does not run here");
            return;
        }
        use std::arch::x86_64::*;
        let value = |i: usize, j: usize| (16 * i + j) as f32;
        let mut block: [__m512; 16] = std::array::from_fn(|i| {
            let row: [f32; 16] = std::array::from_fn(|j| value(i, j));
            // SAFETY: AVX-512 F is available; `row` holds 16 values.
            unsafe { _mm512_loadu_ps(row.as_ptr()) }
        });
        // SAFETY: as above.
        unsafe { transpose_16x16(&mut block) };
        for (i, v) in block.iter().enumerate() {
            let mut row = [0f32; 16];
            // SAFETY: as above.
            unsafe { _mm512_storeu_ps(row.as_mut_ptr(), *v) };
            let want: [f32; 16] = std::array::from_fn(|j| value(j, i));
            assert_eq!(row, want, "row {i}");
        }
    }
}
