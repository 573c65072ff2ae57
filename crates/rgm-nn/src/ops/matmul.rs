//! Matrix products (single and batched) through BLAS. A transpose is a view (`a.t()`), free in
//! both directions: pass `b.t()` to multiply by `bᵀ`, and `db.reversed_axes()` to receive its
//! gradient.

use crate::error::check_shape;
use crate::gemm::mat_mul;
use crate::{Compute, Result, Scalar};
use ndarray::{ArrayView2, ArrayView3, ArrayViewMut2, ArrayViewMut3, Axis};

/// `out = a · b`. `out`: (P, R), `a`: (P, Q), `b`: (Q, R).
pub fn matmul_forward<T: Scalar>(
    mut out: ArrayViewMut2<'_, T>,
    a: ArrayView2<'_, T>,
    b: ArrayView2<'_, T>,
    compute: Compute,
) -> Result<()> {
    check_shape("matmul forward", "b", b.shape(), &[a.ncols(), b.ncols()])?;
    check_shape(
        "matmul forward",
        "out",
        out.shape(),
        &[a.nrows(), b.ncols()],
    )?;
    mat_mul(T::one(), &a, &b, T::zero(), &mut out, compute);
    Ok(())
}

/// Differentiates `out = a · b`: `da += dout · bᵀ`, `db += aᵀ · dout`.
pub fn matmul_backward<T: Scalar>(
    mut da: ArrayViewMut2<'_, T>,
    mut db: ArrayViewMut2<'_, T>,
    dout: ArrayView2<'_, T>,
    a: ArrayView2<'_, T>,
    b: ArrayView2<'_, T>,
    compute: Compute,
) -> Result<()> {
    check_shape("matmul backward", "b", b.shape(), &[a.ncols(), b.ncols()])?;
    check_shape(
        "matmul backward",
        "dout",
        dout.shape(),
        &[a.nrows(), b.ncols()],
    )?;
    check_shape("matmul backward", "da", da.shape(), a.shape())?;
    check_shape("matmul backward", "db", db.shape(), b.shape())?;
    mat_mul(T::one(), &dout, &b.t(), T::one(), &mut da, compute);
    mat_mul(T::one(), &a.t(), &dout, T::one(), &mut db, compute);
    Ok(())
}

/// `out[i] = a[i] · b[i]` for every batch item. `out`: (B, P, R), `a`: (B, P, Q), `b`: (B, Q, R).
pub fn bmm_forward<T: Scalar>(
    mut out: ArrayViewMut3<'_, T>,
    a: ArrayView3<'_, T>,
    b: ArrayView3<'_, T>,
    compute: Compute,
) -> Result<()> {
    check_shape("bmm forward", "b", &b.shape()[..1], &a.shape()[..1])?;
    check_shape("bmm forward", "out", &out.shape()[..1], &a.shape()[..1])?;
    for ((o, a), b) in out
        .axis_iter_mut(Axis(0))
        .zip(a.axis_iter(Axis(0)))
        .zip(b.axis_iter(Axis(0)))
    {
        matmul_forward(o, a, b, compute)?;
    }
    Ok(())
}

/// Differentiates the batched product item by item (see [`matmul_backward`]).
pub fn bmm_backward<T: Scalar>(
    mut da: ArrayViewMut3<'_, T>,
    mut db: ArrayViewMut3<'_, T>,
    dout: ArrayView3<'_, T>,
    a: ArrayView3<'_, T>,
    b: ArrayView3<'_, T>,
    compute: Compute,
) -> Result<()> {
    let batch = &a.shape()[..1];
    for (what, shape) in [
        ("b", b.shape()),
        ("dout", dout.shape()),
        ("da", da.shape()),
        ("db", db.shape()),
    ] {
        check_shape("bmm backward", what, &shape[..1], batch)?;
    }
    let items = da.axis_iter_mut(Axis(0)).zip(db.axis_iter_mut(Axis(0)));
    for (((da, db), dout), (a, b)) in items
        .zip(dout.axis_iter(Axis(0)))
        .zip(a.axis_iter(Axis(0)).zip(b.axis_iter(Axis(0))))
    {
        matmul_backward(da, db, dout, a, b, compute)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::{assert_gradients, ix2, ix3, uniform};
    use ndarray::{array, Array2, Array3};

    #[test]
    fn forward_by_hand_with_a_transposed_view() {
        let (a, b) = (
            array![[1.0, 2.0], [3.0, 4.0]],
            array![[1.0, 0.0], [1.0, 1.0]],
        );
        let mut out = Array2::zeros((2, 2));
        matmul_forward(out.view_mut(), a.view(), b.t(), Compute::default()).unwrap();
        // a · bᵀ = [[1 2],[3 4]] · [[1 1],[0 1]]
        assert_eq!(out, array![[1.0, 3.0], [3.0, 7.0]]);
    }

    #[test]
    fn backward_matches_finite_differences_through_a_transpose() {
        // out = a · bᵀ with b stored (R, Q): the gradient of b arrives through reversed axes.
        // P = 9, R = 10 exceed ndarray's BLAS cut-off (7): dgemm sees the transposed views.
        assert_gradients(
            "matmul",
            1e-6,
            &[uniform(&[9, 4], 41), uniform(&[10, 4], 42)],
            &mut |i| {
                let mut out = Array2::zeros((9, 10));
                matmul_forward(
                    out.view_mut(),
                    ix2(&i[0]).view(),
                    ix2(&i[1]).t(),
                    Compute::default(),
                )
                .unwrap();
                out.into_dyn()
            },
            &mut |i, dout| {
                let (mut da, mut db) = (Array2::zeros((9, 4)), Array2::zeros((10, 4)));
                matmul_backward(
                    da.view_mut(),
                    db.view_mut().reversed_axes(),
                    ix2(dout).view(),
                    ix2(&i[0]).view(),
                    ix2(&i[1]).t(),
                    Compute::default(),
                )
                .unwrap();
                vec![da.into_dyn(), db.into_dyn()]
            },
        );
    }

    #[test]
    fn batched_backward_matches_finite_differences() {
        assert_gradients(
            "bmm",
            1e-6,
            &[uniform(&[2, 3, 4], 43), uniform(&[2, 4, 2], 44)],
            &mut |i| {
                let mut out = Array3::zeros((2, 3, 2));
                bmm_forward(
                    out.view_mut(),
                    ix3(&i[0]).view(),
                    ix3(&i[1]).view(),
                    Compute::default(),
                )
                .unwrap();
                out.into_dyn()
            },
            &mut |i, dout| {
                let (mut da, mut db) = (Array3::zeros((2, 3, 4)), Array3::zeros((2, 4, 2)));
                bmm_backward(
                    da.view_mut(),
                    db.view_mut(),
                    ix3(dout).view(),
                    ix3(&i[0]).view(),
                    ix3(&i[1]).view(),
                    Compute::default(),
                )
                .unwrap();
                vec![da.into_dyn(), db.into_dyn()]
            },
        );
    }
}
