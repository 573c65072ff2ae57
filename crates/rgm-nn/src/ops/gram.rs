//! Scaled Gram matrix of the rows, `out = α · a · aᵀ`: the soft adjacency's scores
//! `T Tᵀ / √C` (spec §2.2). One op, because `a` appears twice and its two gradient
//! contributions must land in the same buffer.

use crate::error::check_shape;
use crate::gemm::mat_mul;
use crate::{Compute, Result, Scalar};
use ndarray::{ArrayView2, ArrayViewMut2};

/// `out = α · a · aᵀ`. `out`: (N, N), `a`: (N, C).
pub fn gram_forward<T: Scalar>(
    mut out: ArrayViewMut2<'_, T>,
    a: ArrayView2<'_, T>,
    alpha: T,
    compute: Compute,
) -> Result<()> {
    check_shape("gram forward", "out", out.shape(), &[a.nrows(), a.nrows()])?;
    mat_mul(alpha, &a, &a.t(), T::zero(), &mut out, compute);
    Ok(())
}

/// Differentiates `out = α a aᵀ`: `da += α (dout + doutᵀ) · a`. `da`: (N, C), `dout`: (N, N).
pub fn gram_backward<T: Scalar>(
    mut da: ArrayViewMut2<'_, T>,
    dout: ArrayView2<'_, T>,
    a: ArrayView2<'_, T>,
    alpha: T,
    compute: Compute,
) -> Result<()> {
    let n = a.nrows();
    check_shape("gram backward", "dout", dout.shape(), &[n, n])?;
    check_shape("gram backward", "da", da.shape(), a.shape())?;
    mat_mul(alpha, &dout, &a, T::one(), &mut da, compute);
    mat_mul(alpha, &dout.t(), &a, T::one(), &mut da, compute);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::{assert_gradients, ix2, uniform};
    use ndarray::{array, Array2};

    #[test]
    fn forward_by_hand() {
        // a = [[1 2],[3 4]]: a aᵀ = [[5 11],[11 25]], halved.
        let mut out = Array2::zeros((2, 2));
        gram_forward(
            out.view_mut(),
            array![[1.0, 2.0], [3.0, 4.0]].view(),
            0.5,
            Compute::default(),
        )
        .unwrap();
        assert_eq!(out, array![[2.5, 5.5], [5.5, 12.5]]);
    }

    #[test]
    fn backward_matches_finite_differences() {
        // N = 9 > 7: through dgemm with the transposed view.
        assert_gradients(
            "gram",
            1e-6,
            &[uniform(&[9, 4], 121)],
            &mut |i| {
                let mut out = Array2::zeros((9, 9));
                gram_forward(out.view_mut(), ix2(&i[0]).view(), 0.5, Compute::default()).unwrap();
                out.into_dyn()
            },
            &mut |i, dout| {
                let mut da = Array2::zeros((9, 4));
                gram_backward(
                    da.view_mut(),
                    ix2(dout).view(),
                    ix2(&i[0]).view(),
                    0.5,
                    Compute::default(),
                )
                .unwrap();
                vec![da.into_dyn()]
            },
        );
    }
}
