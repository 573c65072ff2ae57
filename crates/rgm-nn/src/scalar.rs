//! The element types the ops run in: f32 for compute, f64 for the gradient checks.

use crate::gemm::Then;
use crate::Compute;
use ndarray::linalg::general_mat_mul;
use ndarray::{ArrayView2, ArrayViewMut2, LinalgScalar, ScalarOperand};
use num_traits::{Float, NumAssign};

/// A float element type of the ops (implemented for f32 and f64).
pub trait Scalar:
    Float
    + NumAssign
    + LinalgScalar
    + ScalarOperand
    + std::iter::Sum
    + std::fmt::Debug
    + std::fmt::Display
    + Send
    + Sync
    + 'static
{
    /// The value nearest to `v`.
    fn from_f64(v: f64) -> Self;
    /// The value widened to f64.
    fn to_f64(self) -> f64;
    /// `c = alpha · a · b + beta · c` in this type's way: see [`crate::gemm::mat_mul`], which
    /// the ops call.
    fn mat_mul(
        alpha: Self,
        a: ArrayView2<'_, Self>,
        b: ArrayView2<'_, Self>,
        beta: Self,
        c: ArrayViewMut2<'_, Self>,
        compute: Compute,
    );
    /// `c = a · b` finished by `then` in this type's way: see [`crate::gemm::mat_mul_then`].
    fn mat_mul_then(
        a: ArrayView2<'_, Self>,
        b: ArrayView2<'_, Self>,
        then: Then<'_, Self>,
        c: ArrayViewMut2<'_, Self>,
        compute: Compute,
    );
    /// Replaces every value by its exponential: libm's in f64, [`crate::exp`]'s vectorised
    /// polynomial (≤ 2 ulp) in f32.
    fn exp_in_place(xs: &mut [Self]);
}

impl Scalar for f32 {
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
    /// AVX-512 or BLAS, or bf16 on AMX when `compute` asks for
    /// [`crate::Precision::Bf16`].
    fn mat_mul(
        alpha: Self,
        a: ArrayView2<'_, Self>,
        b: ArrayView2<'_, Self>,
        beta: Self,
        c: ArrayViewMut2<'_, Self>,
        compute: Compute,
    ) {
        crate::gemm::mat_mul_f32(alpha, a, b, beta, c, compute);
    }
    fn mat_mul_then(
        a: ArrayView2<'_, Self>,
        b: ArrayView2<'_, Self>,
        then: Then<'_, Self>,
        c: ArrayViewMut2<'_, Self>,
        compute: Compute,
    ) {
        crate::gemm::mat_mul_then_f32(a, b, then, c, compute);
    }
    fn exp_in_place(xs: &mut [Self]) {
        crate::exp::exp_f32_in_place(xs);
    }
}

impl Scalar for f64 {
    fn from_f64(v: f64) -> Self {
        v
    }
    fn to_f64(self) -> f64 {
        self
    }
    /// Always BLAS: f64 runs the gradient checks, whatever `compute` says.
    fn mat_mul(
        alpha: Self,
        a: ArrayView2<'_, Self>,
        b: ArrayView2<'_, Self>,
        beta: Self,
        mut c: ArrayViewMut2<'_, Self>,
        _compute: Compute,
    ) {
        general_mat_mul(alpha, &a, &b, beta, &mut c);
    }
    fn mat_mul_then(
        a: ArrayView2<'_, Self>,
        b: ArrayView2<'_, Self>,
        then: Then<'_, Self>,
        c: ArrayViewMut2<'_, Self>,
        compute: Compute,
    ) {
        crate::gemm::then_by_passes(a, b, then, c, compute);
    }
    fn exp_in_place(xs: &mut [Self]) {
        xs.iter_mut().for_each(|x| *x = x.exp());
    }
}
