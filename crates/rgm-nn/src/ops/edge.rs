//! The DGCNN edge-feature gather: for every point `n` and each of its K neighbours `i = idx[n, k]`
//! the row `(x_i, x_n)` — neighbour coordinates first, then the centre's (spec §2.1).

use crate::error::check_shape;
use crate::{NnError, Result, Scalar};
use ndarray::{s, ArrayView2, ArrayViewMut2};

/// `out[n*K + k] = (x[idx[n, k]], x[n])`. `out`: (N*K, 2D), `x`: (N, D), `idx`: (N, K) with
/// entries in 0..N (an out-of-range index is an error).
pub fn edge_features_forward<T: Scalar>(
    mut out: ArrayViewMut2<'_, T>,
    x: ArrayView2<'_, T>,
    idx: ArrayView2<'_, usize>,
) -> Result<()> {
    let ((n, d), k) = (x.dim(), idx.ncols());
    check_shape("edge_features forward", "idx", idx.shape(), &[n, k])?;
    check_shape("edge_features forward", "out", out.shape(), &[n * k, 2 * d])?;
    for p in 0..n {
        for j in 0..k {
            let i = idx[[p, j]];
            if i >= n {
                return Err(NnError::IndexOutOfRange {
                    op: "edge_features forward",
                    index: i,
                    len: n,
                });
            }
            let mut row = out.row_mut(p * k + j);
            row.slice_mut(s![..d]).assign(&x.row(i));
            row.slice_mut(s![d..]).assign(&x.row(p));
        }
    }
    Ok(())
}

/// Differentiates the gather by scattering back: `dx[idx[n, k]] += dout[n*K + k, ..D]` and
/// `dx[n] += dout[n*K + k, D..]`. `dx`: (N, D), `dout`: (N*K, 2D).
pub fn edge_features_backward<T: Scalar>(
    mut dx: ArrayViewMut2<'_, T>,
    dout: ArrayView2<'_, T>,
    idx: ArrayView2<'_, usize>,
) -> Result<()> {
    let ((n, d), k) = (dx.dim(), idx.ncols());
    check_shape("edge_features backward", "idx", idx.shape(), &[n, k])?;
    check_shape(
        "edge_features backward",
        "dout",
        dout.shape(),
        &[n * k, 2 * d],
    )?;
    for p in 0..n {
        for j in 0..k {
            let i = idx[[p, j]];
            if i >= n {
                return Err(NnError::IndexOutOfRange {
                    op: "edge_features backward",
                    index: i,
                    len: n,
                });
            }
            let row = dout.row(p * k + j);
            let mut di = dx.row_mut(i);
            di += &row.slice(s![..d]);
            let mut dp = dx.row_mut(p);
            dp += &row.slice(s![d..]);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::{assert_gradients, ix2, uniform};
    use ndarray::{array, Array2};

    #[test]
    fn rows_are_neighbour_then_centre() {
        let x = array![[1.0, 2.0], [3.0, 4.0]];
        let idx = array![[0, 1], [1, 0]];
        let mut out = Array2::zeros((4, 4));
        edge_features_forward(out.view_mut(), x.view(), idx.view()).unwrap();
        assert_eq!(
            out,
            array![
                [1.0, 2.0, 1.0, 2.0],
                [3.0, 4.0, 1.0, 2.0],
                [3.0, 4.0, 3.0, 4.0],
                [1.0, 2.0, 3.0, 4.0]
            ]
        );
    }

    #[test]
    fn backward_matches_finite_differences() {
        // Repeated neighbours (point 2 used by everyone) make the scatter add up.
        let idx = array![[0, 2, 1], [1, 2, 2], [2, 0, 2], [3, 2, 0]];
        assert_gradients(
            "edge_features",
            1e-6,
            &[uniform(&[4, 3], 31)],
            &mut |i| {
                let mut out = Array2::zeros((12, 6));
                edge_features_forward(out.view_mut(), ix2(&i[0]).view(), idx.view()).unwrap();
                out.into_dyn()
            },
            &mut |_, dout| {
                let mut dx = Array2::zeros((4, 3));
                edge_features_backward(dx.view_mut(), ix2(dout).view(), idx.view()).unwrap();
                vec![dx.into_dyn()]
            },
        );
    }

    #[test]
    fn out_of_range_index_is_an_error() {
        let mut out = Array2::<f32>::zeros((2, 2));
        let err = edge_features_forward(
            out.view_mut(),
            Array2::zeros((2, 1)).view(),
            array![[0], [2]].view(),
        )
        .unwrap_err();
        assert_eq!(
            err.to_string(),
            "edge_features forward: index 2 out of range for 2 rows"
        );
    }
}
