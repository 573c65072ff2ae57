//! The matrix product every op calls, [`mat_mul`]: f32 on AVX-512 where the processor has it
//! ([`f32_mat_mul`]) and BLAS elsewhere, f64 on BLAS, or bf16 on the processor's AMX tile units
//! (or its AVX-512 BF16 dot products where it has no AMX) when the [`Compute`] it is given asks
//! for [`Precision::Bf16`].
//!
//! The bf16 product ([`bf16_mat_mul`]) takes and returns f32: both inputs are rounded to bf16
//! (nearest even) while they are packed, the products are accumulated in f32. It runs on the
//! calling thread (training runs one network per worker thread; inference calls BLAS with one
//! thread by default), in three steps:
//! 1. pack A (M, K) into 32-row strips, each a run of 32 × 32 slices along K (2 KiB, two tiles);
//! 2. pack B (K, N) into 32-column strips, each a run of 32 × 32 slices along K in the VNNI
//!    pairs layout that `tdpbf16ps` and `vdpbf16ps` read (see `kernels`); M, N and K are
//!    padded with zeros to multiples of 32, so edges need no special kernel;
//! 3. for each column panel of B small enough to stay in L2 (≤ 256 KiB), for each A strip (at
//!    most 32 KiB for K ≤ 512: it stays in L1 across the panel), multiply the strip by each B
//!    strip of the panel into a 32 × 32 f32 block of C, the kernel applying alpha and beta:
//!    whole blocks of a C with unit column stride in place, the others (C's edges, a C with
//!    strided rows) in a scratch block that holds C's block first and goes back clipped. Every
//!    entry is thus computed alike wherever it lies, and a product summed in parts along K (at
//!    multiples of 32, alpha 1, beta 1) has the whole product's bits.
//!
//! Packing is vectorised for operands with a unit stride either way (a transposed view goes
//! through 16 × 16 register transposes) where the processor has AVX-512 BF16, and reads other
//! views one value at a time in the order they lie in memory. Where it transposes fewer values,
//! the product is computed as `cᵀ = bᵀ · aᵀ`, with the same bits.
//!
//! The file is long because its unit tests sit beside the code they check (as everywhere in
//! rgm); the code itself is one job, kept in one place.

#[cfg(target_arch = "x86_64")]
mod f32_avx512;
mod kernels;
mod scalars;

#[cfg(target_arch = "x86_64")]
pub use f32_avx512::{f32_mat_mul, f32_mat_mul_then};
pub use kernels::{backend, register_peak_loop};

/// Whether this processor runs [`f32_mat_mul`] (x86-64 with AVX-512 F).
pub fn f32_avx512_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        f32_avx512::available()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

use crate::bf16::bf16_bits;
use crate::compute::{Compute, Precision};
use crate::scalar::{Scalar, Then};
use ndarray::linalg::general_mat_mul;
use ndarray::{
    s, ArrayBase, ArrayView2, ArrayViewMut2, Axis, Data, DataMut, Ix2, ShapeBuilder, Zip,
};
use std::cell::RefCell;
use std::sync::atomic::{AtomicU64, Ordering};

/// Multiply-adds of the matrix products this process computed through [`mat_mul`] and
/// [`mat_mul_then`], and of those [`count_multiply_adds`] was told of: what a training step's
/// achieved FLOP/s is measured by (`benches/examples/speed.rs`; 2 FLOPs a multiply-add).
static MULTIPLY_ADDS: AtomicU64 = AtomicU64::new(0);

/// The multiply-adds of every matrix product so far (see `MULTIPLY_ADDS`).
pub fn multiply_adds() -> u64 {
    MULTIPLY_ADDS.load(Ordering::Relaxed)
}

/// Counts `m · k · n` multiply-adds of a product computed elsewhere (BLAS through ndarray), so
/// that [`multiply_adds`] holds every product of a step.
pub fn count_multiply_adds(m: usize, k: usize, n: usize) {
    MULTIPLY_ADDS.fetch_add((m * k * n) as u64, Ordering::Relaxed);
}

/// `c = alpha · a · b + beta · c`, `a`: (M, K), `b`: (K, N), `c`: (M, N), in `compute`'s
/// precision for f32 (f64 is always BLAS). `beta = 0` ignores what `c` held.
/// Panics if the shapes do not agree (as `general_mat_mul`, which it replaces).
pub fn mat_mul<T, S1, S2, S3>(
    alpha: T,
    a: &ArrayBase<S1, Ix2>,
    b: &ArrayBase<S2, Ix2>,
    beta: T,
    c: &mut ArrayBase<S3, Ix2>,
    compute: Compute,
) where
    T: Scalar,
    S1: Data<Elem = T>,
    S2: Data<Elem = T>,
    S3: DataMut<Elem = T>,
{
    count_multiply_adds(a.nrows(), a.ncols(), b.ncols());
    T::mat_mul(alpha, a.view(), b.view(), beta, c.view_mut(), compute);
}

/// `c = a · b` finished as `then` says, in `compute`'s precision for f32; what `c` held is
/// ignored. Where the f32 product runs on AVX-512 the bias, the ReLU and ReLU's backward are
/// applied in the product's write-back, bit for bit what `then_by_passes` gives with passes
/// over C. Panics if the shapes disagree.
pub fn mat_mul_then<T, S1, S2, S3>(
    a: &ArrayBase<S1, Ix2>,
    b: &ArrayBase<S2, Ix2>,
    then: Then<'_, T>,
    c: &mut ArrayBase<S3, Ix2>,
    compute: Compute,
) where
    T: Scalar,
    S1: Data<Elem = T>,
    S2: Data<Elem = T>,
    S3: DataMut<Elem = T>,
{
    count_multiply_adds(a.nrows(), a.ncols(), b.ncols());
    T::mat_mul_then(a.view(), b.view(), then, c.view_mut(), compute);
}

/// [`mat_mul_then`] as [`mat_mul`] and passes over C (every type and product but the f32 one
/// on AVX-512): for a layer, C filled with the bias, the product added to it, the ReLU; for
/// ReLU's backward, the product, then the entries where `y ≤ 0` set to zero.
pub(crate) fn then_by_passes<T: Scalar>(
    a: ArrayView2<'_, T>,
    b: ArrayView2<'_, T>,
    then: Then<'_, T>,
    mut c: ArrayViewMut2<'_, T>,
    compute: Compute,
) {
    let kept = |x: T, y: T| if y > T::zero() { x } else { T::zero() };
    match then {
        Then::Layer { bias, relu } => {
            match bias {
                Some(bias) => {
                    c.assign(&bias);
                    T::mat_mul(T::one(), a, b, T::one(), c.view_mut(), compute);
                }
                None => T::mat_mul(T::one(), a, b, T::zero(), c.view_mut(), compute),
            }
            if relu {
                c.mapv_inplace(|x| kept(x, x));
            }
        }
        Then::ReluGrad(y) => {
            T::mat_mul(T::one(), a, b, T::zero(), c.view_mut(), compute);
            Zip::from(c).and(y).for_each(|c, &y| *c = kept(*c, y));
        }
    }
}

/// [`mat_mul_then`] for f32: in the AVX-512 product's write-back when [`mat_mul_f32`] would
/// run that product, [`then_by_passes`] otherwise.
pub(crate) fn mat_mul_then_f32(
    a: ArrayView2<'_, f32>,
    b: ArrayView2<'_, f32>,
    then: Then<'_, f32>,
    c: ArrayViewMut2<'_, f32>,
    compute: Compute,
) {
    let bf16 = compute.precision == Precision::Bf16 && bf16_available();
    if !bf16 && f32_avx512_available() {
        #[cfg(target_arch = "x86_64")]
        f32_mat_mul_then(a, b, then, c);
    } else {
        then_by_passes(a, b, then, c, compute);
    }
}

/// [`mat_mul`] for f32: bf16 when `compute`'s precision is bf16 and [`bf16_available`];
/// otherwise the f32 product, on AVX-512 where the processor has it ([`f32_mat_mul`]: the
/// BLAS this workspace builds runs AVX2 kernels only), BLAS elsewhere.
pub(crate) fn mat_mul_f32(
    alpha: f32,
    a: ArrayView2<'_, f32>,
    b: ArrayView2<'_, f32>,
    beta: f32,
    c: ArrayViewMut2<'_, f32>,
    compute: Compute,
) {
    mat_mul_f32_in(compute.precision, bf16_available(), alpha, a, b, beta, c);
}

/// [`mat_mul_f32`] with the precision and the processor's bf16 support given (so that the
/// fallback is tested on every machine).
fn mat_mul_f32_in(
    precision: Precision,
    bf16_here: bool,
    alpha: f32,
    a: ArrayView2<'_, f32>,
    b: ArrayView2<'_, f32>,
    beta: f32,
    mut c: ArrayViewMut2<'_, f32>,
) {
    if precision == Precision::Bf16 && bf16_here {
        bf16_mat_mul(alpha, a, b, beta, c);
    } else if f32_avx512_available() {
        #[cfg(target_arch = "x86_64")]
        {
            // A large product in two halves of its rows side by side when the pool has a
            // second thread: each entry is computed as in one product (the kernel's order of
            // additions does not depend on the rows), so the bits do not depend on the threads.
            let m = a.nrows();
            if m >= 2
                && m * a.ncols() * b.ncols() >= SIDE_BY_SIDE_MULTIPLY_ADDS
                && rayon::current_num_threads() > 1
            {
                let (a_top, a_bottom) = a.split_at(Axis(0), m / 2);
                let (c_top, c_bottom) = c.split_at(Axis(0), m / 2);
                rayon::join(
                    || f32_mat_mul(alpha, a_top, b, beta, c_top),
                    || f32_mat_mul(alpha, a_bottom, b, beta, c_bottom),
                );
            } else {
                f32_mat_mul(alpha, a, b, beta, c);
            }
        }
    } else {
        general_mat_mul(alpha, &a, &b, beta, &mut c);
    }
}

/// Multiply-adds from which an f32 product on AVX-512 is split by rows ([`mat_mul_f32`]).
const SIDE_BY_SIDE_MULTIPLY_ADDS: usize = 1 << 22;

/// Whether [`bf16_mat_mul`] can run here: an x86-64 processor with AMX-BF16 under Linux that
/// granted the tile registers to this process (asked once, on the first call), or one with
/// AVX-512 BF16. [`backend`] says which.
pub fn bf16_available() -> bool {
    backend().is_some()
}

/// The packed operands and the result block, kept per thread so that repeated products of
/// stable shapes allocate nothing.
#[derive(Default)]
struct Scratch {
    a: Vec<u16>, // (M/32, K/32, 32, 32) padded
    b: Vec<u16>, // (N/32, K/32, 2, 16, 16, 2) padded
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// Bytes of B's packed columns one pass keeps in L2 while every A strip meets them.
const B_PANEL_BYTES: usize = 256 * 1024;

/// (M, N) of `c = a · b`; panics, naming `op`, unless `a` is (M, K), `b` (K, N), `c` (M, N).
fn check_shapes(
    op: &str,
    a: &ArrayView2<'_, f32>,
    b: &ArrayView2<'_, f32>,
    c: &ArrayViewMut2<'_, f32>,
) -> (usize, usize) {
    let ((m, k), n) = (a.dim(), b.ncols());
    assert!(
        b.nrows() == k && c.dim() == (m, n),
        "{op}: a {:?} · b {:?} into c {:?}",
        a.shape(),
        b.shape(),
        c.shape()
    );
    (m, n)
}

/// `c = alpha · a · b + beta · c` with a and b rounded to bf16 and f32 accumulation, on AMX (or
/// AVX-512 BF16). `a`: (M, K), `b`: (K, N), `c`: (M, N), any strides. Panics if the shapes
/// disagree or bf16 is not [`bf16_available`].
pub fn bf16_mat_mul(
    alpha: f32,
    a: ArrayView2<'_, f32>,
    b: ArrayView2<'_, f32>,
    beta: f32,
    mut c: ArrayViewMut2<'_, f32>,
) {
    let (m, n) = check_shapes("bf16_mat_mul", &a, &b, &c);
    if m == 0 || n == 0 {
        return;
    }
    let mut kernel = kernels::Kernel::new().expect("bf16_mat_mul needs AMX or AVX-512 BF16");
    packed_mat_mul(alpha, a, b, beta, c.view_mut(), |a, b, out, alpha, beta| {
        kernel.block(a, b, out, alpha, beta)
    });
}

/// `out = alpha · block + beta · out` (`beta = 0` ignores what `out` held) from a block function
/// that can only set or add (`plain(out, accumulate)`: the AMX tiles): straight into `out` when
/// alpha = 1 and beta ∈ {0, 1}, through a scratch block and [`finish`] otherwise.
fn scaled_block(
    mut plain: impl FnMut(ArrayViewMut2<'_, f32>, bool),
    out: ArrayViewMut2<'_, f32>,
    alpha: f32,
    beta: f32,
) {
    if alpha == 1.0 && (beta == 0.0 || beta == 1.0) {
        return plain(out, beta == 1.0);
    }
    let mut block = [0f32; 32 * 32]; // (32, 32) row-major
    let mut got = ArrayViewMut2::from_shape((32, 32), &mut block[..]).expect("32²");
    plain(got.view_mut(), false);
    finish(out, got.view(), alpha, beta);
}

/// `dst = alpha · got + beta · dst`, or `alpha · got` when `beta = 0` (whatever `dst` held).
fn finish(dst: ArrayViewMut2<'_, f32>, got: ArrayView2<'_, f32>, alpha: f32, beta: f32) {
    if beta == 0.0 {
        Zip::from(dst).and(got).for_each(|c, &g| *c = alpha * g);
    } else {
        Zip::from(dst)
            .and(got)
            .for_each(|c, &g| *c = alpha * g + beta * *c);
    }
}

/// The bf16 product with `block_of(a_strip, b_strip, out, alpha, beta)` computing one 32 × 32
/// block `out = alpha · a · b + beta · out` from packed strips into a (32, 32) view (a kernel,
/// or the tests' reference): [`packed_mat_mul_as_given`], or the same for `cᵀ = bᵀ · aᵀ` where
/// that does less [`layout_work`]. Kernels and reference add each entry's products in the same
/// order whichever operand is A, so the bits are the same either way.
fn packed_mat_mul(
    alpha: f32,
    a: ArrayView2<'_, f32>,
    b: ArrayView2<'_, f32>,
    beta: f32,
    c: ArrayViewMut2<'_, f32>,
    block_of: impl FnMut(&[u16], &[u16], ArrayViewMut2<'_, f32>, f32, f32),
) {
    if layout_work(b.t(), a.t(), c.t()) < layout_work(a, b, c.view()) {
        packed_mat_mul_as_given(alpha, b.t(), a.t(), beta, c.reversed_axes(), block_of);
    } else {
        packed_mat_mul_as_given(alpha, a, b, beta, c, block_of);
    }
}

/// Values of `c = a · b` that take the slow paths: those of an operand not stored row by row
/// (packed through 16 × 16 register transposes, or one by one) and those of a C not stored row
/// by row (written through a scratch block). The attention's `Pᵀ · dO` has a (384, 384)
/// operand stored column by column, its transpose `dOᵀ · P` only a (32, 384) one and C.
fn layout_work(a: ArrayView2<'_, f32>, b: ArrayView2<'_, f32>, c: ArrayView2<'_, f32>) -> usize {
    [
        (a.strides()[1], a.dim()),
        (b.strides()[1], b.dim()),
        (c.strides()[1], c.dim()),
    ]
    .iter()
    .filter(|&&(column_stride, (_, cols))| column_stride != 1 && cols > 1)
    .map(|(_, (rows, cols))| rows * cols)
    .sum()
}

/// [`packed_mat_mul`] with the operands as given: packing, blocking, edges and the write-back
/// into C. Whole blocks of a C with unit column stride go straight into C; the others (C's
/// edges, a C with strided rows) go through a scratch block that holds C's block first, so
/// that every entry is computed alike wherever it lies.
fn packed_mat_mul_as_given(
    alpha: f32,
    a: ArrayView2<'_, f32>,
    b: ArrayView2<'_, f32>,
    beta: f32,
    mut c: ArrayViewMut2<'_, f32>,
    mut block_of: impl FnMut(&[u16], &[u16], ArrayViewMut2<'_, f32>, f32, f32),
) {
    let ((m, k), n) = (a.dim(), b.ncols());
    let kp = k.next_multiple_of(32);
    let strip = kp * 32; // elements of one packed 32-row strip of A or 32-column strip of B
    let panel_strips = (B_PANEL_BYTES / (2 * strip).max(1)).max(1);
    let row_stride = c.strides()[0];
    let direct = c.strides()[1] == 1 && row_stride >= 32;
    SCRATCH.with(|scratch| {
        let scratch = &mut *scratch.borrow_mut();
        let packed_a = pack_a(a, kp, &mut scratch.a);
        let packed_b = pack_b(b, kp, &mut scratch.b);
        let mut block = [0f32; 32 * 32]; // (32, 32) row-major
        let (m_strips, n_strips) = (m.div_ceil(32), n.div_ceil(32));
        for first in (0..n_strips).step_by(panel_strips) {
            for mi in 0..m_strips {
                let a_strip = &packed_a[mi * strip..][..strip];
                let rows = mi * 32..(mi * 32 + 32).min(m);
                let panel_end = (first + panel_strips).min(n_strips);
                for ni in first..panel_end {
                    let b_strip = &packed_b[ni * strip..][..strip];
                    let cols = ni * 32..(ni * 32 + 32).min(n);
                    if direct && rows.len() == 32 && cols.len() == 32 {
                        // The next block's rows of C, fetched while this block is computed.
                        let (next_mi, next_ni) = match ni + 1 < panel_end {
                            true => (mi, ni + 1),
                            false => (mi + 1, first),
                        };
                        if next_mi < m_strips {
                            let at = (next_mi * 32) as isize * row_stride + (next_ni * 32) as isize;
                            let next = c.as_ptr().wrapping_offset(at);
                            kernels::prefetch_block(next, m - next_mi * 32, row_stride);
                        }
                        // SAFETY: rows × cols is a 32 × 32 block inside C, which `c` borrows
                        // mutably; C's rows are `row_stride` apart with unit column stride (a
                        // view made here rather than by `slice_mut`, whose checks cost more
                        // than the smallest blocks' products).
                        let dst = unsafe {
                            let at = c
                                .as_mut_ptr()
                                .offset(rows.start as isize * row_stride + cols.start as isize);
                            ArrayViewMut2::from_shape_ptr(
                                (32, 32).strides((row_stride as usize, 1)),
                                at,
                            )
                        };
                        block_of(a_strip, b_strip, dst, alpha, beta);
                        continue;
                    }
                    let mut got = ArrayViewMut2::from_shape((32, 32), &mut block[..]).expect("32²");
                    let inside = s![..rows.len(), ..cols.len()];
                    let mut dst = c.slice_mut(s![rows.clone(), cols]);
                    if beta != 0.0 {
                        got.slice_mut(inside).assign(&dst);
                    }
                    block_of(a_strip, b_strip, got.view_mut(), alpha, beta);
                    dst.assign(&got.slice(inside));
                }
            }
        }
    });
}

/// Packs `a` (M, K) as bf16 into `out`: 32-row strips, each Kp/32 slices of 32 × 32 (row-major),
/// zero-padded to whole strips and to `kp` columns. Vectorised where the processor has AVX-512
/// BF16 and a stride is 1 ([`kernels::pack_a`]), one value at a time otherwise.
fn pack_a<'o>(a: ArrayView2<'_, f32>, kp: usize, out: &'o mut Vec<u16>) -> &'o [u16] {
    packed(
        out,
        a.nrows().next_multiple_of(32) * kp,
        |out| kernels::pack_a(a, kp, out),
        |out| pack_a_one_by_one(a, kp, out),
    )
}

/// [`pack_a`] one value at a time, into a zeroed `out`.
fn pack_a_one_by_one(a: ArrayView2<'_, f32>, kp: usize, out: &mut [u16]) {
    for_each_in_memory_order(a, |i, k, x| {
        out[(i / 32) * kp * 32 + (k / 32) * 1024 + (i % 32) * 32 + k % 32] = bf16_bits(x);
    });
}

/// Packs `b` (K, N) as bf16 into `out`: 32-column strips, each Kp/32 slices of two 16-column
/// tiles in VNNI pairs (pair row r, column j: rows 2r and 2r + 1 side by side), zero-padded;
/// vectorised as in [`pack_a`].
fn pack_b<'o>(b: ArrayView2<'_, f32>, kp: usize, out: &'o mut Vec<u16>) -> &'o [u16] {
    packed(
        out,
        b.ncols().next_multiple_of(32) * kp,
        |out| kernels::pack_b(b, kp, out),
        |out| pack_b_one_by_one(b, kp, out),
    )
}

/// `len` packed values in `buf`, starting on a 64-byte boundary (every 32-element row of a
/// packed slice then fills one cache line, so its loads and stores never straddle two): by
/// `vector` where it runs (it writes every value), else zeroed and filled by `one_by_one` (which
/// writes only the operand's values).
fn packed(
    buf: &mut Vec<u16>,
    len: usize,
    vector: impl FnOnce(&mut [u16]) -> bool,
    one_by_one: impl FnOnce(&mut [u16]),
) -> &[u16] {
    buf.resize(len + 32, 0);
    let skip = buf.as_ptr().align_offset(64);
    let out = &mut buf[skip..][..len];
    if !vector(out) {
        out.fill(0);
        one_by_one(out);
    }
    out
}

/// [`pack_b`] one value at a time, into a zeroed `out`.
fn pack_b_one_by_one(b: ArrayView2<'_, f32>, kp: usize, out: &mut [u16]) {
    for_each_in_memory_order(b, |k, j, x| {
        let strip = (j / 32) * kp * 32 + (k / 32) * 1024 + ((j % 32) / 16) * 512;
        out[strip + ((k % 32) / 2) * 32 + (j % 16) * 2 + k % 2] = bf16_bits(x);
    });
}

/// Calls `f(row, column, value)` for every element of `v`, row by row when its rows are
/// contiguous-ish (the column stride is the smaller) and column by column otherwise.
fn for_each_in_memory_order(v: ArrayView2<'_, f32>, mut f: impl FnMut(usize, usize, f32)) {
    let [row_stride, col_stride] = [v.strides()[0], v.strides()[1]].map(isize::unsigned_abs);
    if col_stride <= row_stride {
        for (i, row) in v.axis_iter(Axis(0)).enumerate() {
            row.iter().enumerate().for_each(|(j, &x)| f(i, j, x));
        }
    } else {
        for (j, col) in v.axis_iter(Axis(1)).enumerate() {
            col.iter().enumerate().for_each(|(i, &x)| f(i, j, x));
        }
    }
}

#[cfg(test)]
mod tests;
