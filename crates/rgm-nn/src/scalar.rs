//! The element types the ops run in: f32 for compute, f64 for the gradient checks (the trait and
//! what its products take; `gemm::scalars` implements it for both, on gemm's kernels).

use crate::Compute;
use ndarray::{ArrayView1, ArrayView2, ArrayViewMut2, LinalgScalar, ScalarOperand};
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

/// How [`crate::gemm::mat_mul_then`] finishes the product `a · b` (M, N).
#[derive(Clone, Copy, Debug)]
pub enum Then<'a, T> {
    /// A layer: `bias` (N, if any) added to every row, then `max(·, 0)` if `relu`.
    Layer {
        bias: Option<ArrayView1<'a, T>>,
        relu: bool,
    },
    /// ReLU's backward through the product: the entries kept where `y` (M, N), a ReLU's
    /// output, is positive and zero elsewhere (zero gradient at 0, as PyTorch).
    ReluGrad(ArrayView2<'a, T>),
}
