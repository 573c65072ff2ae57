//! [`Scalar`] for f32 and f64: which of gemm's kernels and which exponential each runs.

use ndarray::linalg::general_mat_mul;
use ndarray::{ArrayView2, ArrayViewMut2};

use crate::exp::exp_f32_in_place;
use crate::scalar::{Scalar, Then};
use crate::Compute;

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
        super::mat_mul_f32(alpha, a, b, beta, c, compute);
    }
    fn mat_mul_then(
        a: ArrayView2<'_, Self>,
        b: ArrayView2<'_, Self>,
        then: Then<'_, Self>,
        c: ArrayViewMut2<'_, Self>,
        compute: Compute,
    ) {
        super::mat_mul_then_f32(a, b, then, c, compute);
    }
    fn exp_in_place(xs: &mut [Self]) {
        exp_f32_in_place(xs);
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
        super::then_by_passes(a, b, then, c, compute);
    }
    fn exp_in_place(xs: &mut [Self]) {
        xs.iter_mut().for_each(|x| *x = x.exp());
    }
}
