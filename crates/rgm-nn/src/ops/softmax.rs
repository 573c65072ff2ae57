//! Softmax along each row of a score matrix.

use crate::error::{check_shape, check_shapes};
use crate::lanes::exp_shifted_sum;
use crate::{Result, Scalar};
use ndarray::{ArrayView1, ArrayView2, ArrayViewMut1, ArrayViewMut2, Zip};

/// Replaces a row by its softmax, shifted by the row maximum so no exponent overflows.
pub(crate) fn softmax_slice<T: Scalar>(xs: &mut [T]) {
    let max = crate::lanes::max(xs, T::neg_infinity());
    let inv = T::one() / exp_shifted_sum(xs, max);
    xs.iter_mut().for_each(|x| *x *= inv);
}

/// [`softmax_slice`] of a row, strided rows through a contiguous copy.
pub(crate) fn softmax_in_place<T: Scalar>(mut row: ArrayViewMut1<'_, T>) {
    match row.as_slice_mut() {
        Some(xs) => softmax_slice(xs),
        None => {
            let mut xs = row.to_vec();
            softmax_slice(&mut xs);
            row.assign(&ArrayView1::from(&xs));
        }
    }
}

/// `Σ_k dout_k out_k` of one row, shared by both forms of the softmax backward: eight running
/// sums over contiguous rows (a plain fold does not vectorise, and a BLAS call per row costs
/// more than the row), ndarray's dot otherwise.
fn row_dot<T: Scalar>(dout: ArrayView1<'_, T>, out: ArrayView1<'_, T>) -> T {
    match (dout.as_slice(), out.as_slice()) {
        (Some(d), Some(y)) => crate::lanes::dot(d, y),
        _ => dout.dot(&out),
    }
}

/// Adds the softmax backward of one row: `dinp_j += out_j · (dout_j − Σ_k dout_k out_k)`.
fn softmax_backward_row<T: Scalar>(
    mut dinp: ArrayViewMut1<'_, T>,
    dout: ArrayView1<'_, T>,
    out: ArrayView1<'_, T>,
) {
    let dot = row_dot(dout, out);
    Zip::from(&mut dinp)
        .and(&dout)
        .and(&out)
        .for_each(|d, &g, &y| *d += y * (g - dot));
}

/// Replaces a row's output gradient by its input gradient: `d_j ← out_j · (d_j − Σ_k d_k out_k)`.
pub(crate) fn softmax_backward_in_place<T: Scalar>(
    mut d: ArrayViewMut1<'_, T>,
    out: ArrayView1<'_, T>,
) {
    let dot = row_dot(d.view(), out);
    Zip::from(&mut d)
        .and(&out)
        .for_each(|d, &y| *d = y * (*d - dot));
}

/// `out[r, j] = exp(inp[r, j]) / Σ_k exp(inp[r, k])`. `out`, `inp`: (R, C).
pub fn softmax_rows_forward<T: Scalar>(
    mut out: ArrayViewMut2<'_, T>,
    inp: ArrayView2<'_, T>,
) -> Result<()> {
    check_shape("softmax_rows forward", "out", out.shape(), inp.shape())?;
    out.assign(&inp);
    for row in out.rows_mut() {
        softmax_in_place(row);
    }
    Ok(())
}

/// Differentiates the row softmax (Jacobian `diag(y) − y yᵀ` per row):
/// `dinp += out ⊙ (dout − Σ_row dout ⊙ out)`. `out` is the forward's output.
pub fn softmax_rows_backward<T: Scalar>(
    mut dinp: ArrayViewMut2<'_, T>,
    dout: ArrayView2<'_, T>,
    out: ArrayView2<'_, T>,
) -> Result<()> {
    check_shapes(
        "softmax_rows backward",
        out.shape(),
        &[("dinp", dinp.shape()), ("dout", dout.shape())],
    )?;
    for ((d, g), y) in dinp.rows_mut().into_iter().zip(dout.rows()).zip(out.rows()) {
        softmax_backward_row(d, g, y);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::{assert_gradients, ix2, uniform};
    use ndarray::{array, Array2};

    #[test]
    fn forward_by_hand_and_large_scores_do_not_overflow() {
        // softmax(0, ln 3) = (1/4, 3/4); adding 1000 to a row changes nothing (but the rounding of
        // 1000 + ln 3).
        let x = array![[0.0, 3.0f64.ln()], [1000.0, 1000.0 + 3.0f64.ln()]];
        let mut y = Array2::zeros((2, 2));
        softmax_rows_forward(y.view_mut(), x.view()).unwrap();
        for r in 0..2 {
            assert!(
                (y[[r, 0]] - 0.25).abs() < 1e-12 && (y[[r, 1]] - 0.75).abs() < 1e-12,
                "{y}"
            );
        }
    }

    #[test]
    fn backward_matches_finite_differences() {
        let fwd = |x: &Array2<f64>| {
            let mut y = Array2::zeros(x.dim());
            softmax_rows_forward(y.view_mut(), x.view()).unwrap();
            y
        };
        // Rows of 5 and of 19 (two rounds of the row dot's eight running sums and three more).
        for cols in [5, 19] {
            assert_gradients(
                "softmax_rows",
                1e-6,
                &[uniform(&[4, cols], 51) * 3.0],
                &mut |i| fwd(&ix2(&i[0])).into_dyn(),
                &mut |i, dout| {
                    let y = fwd(&ix2(&i[0]));
                    let mut dx = Array2::zeros(y.dim());
                    softmax_rows_backward(dx.view_mut(), ix2(dout).view(), y.view()).unwrap();
                    vec![dx.into_dyn()]
                },
            );
        }
    }
}
