//! Concatenation along channels: `(R, C_1), (R, C_2), ... → (R, C_1 + C_2 + ...)`.
//!
//! A caller that owns the output can skip the copy by letting each producer write into its
//! column block (`out.slice_mut(s![.., a..b])`); these functions are for when it cannot.

use crate::error::check_shape;
use crate::{Result, Scalar};
use ndarray::{s, ArrayView2, ArrayViewMut2};

/// `out = [inp_1 | inp_2 | ...]` along columns.
pub fn concat_forward<T: Scalar>(
    mut out: ArrayViewMut2<'_, T>,
    inputs: &[ArrayView2<'_, T>],
) -> Result<()> {
    let rows = out.nrows();
    let total: usize = inputs.iter().map(|x| x.ncols()).sum();
    check_shape("concat forward", "out", out.shape(), &[rows, total])?;
    let mut start = 0;
    for x in inputs {
        check_shape("concat forward", "input", x.shape(), &[rows, x.ncols()])?;
        out.slice_mut(s![.., start..start + x.ncols()]).assign(x);
        start += x.ncols();
    }
    Ok(())
}

/// Differentiates the concatenation: each `dinp_i += ` its column block of `dout`.
pub fn concat_backward<T: Scalar>(
    dinputs: &mut [ArrayViewMut2<'_, T>],
    dout: ArrayView2<'_, T>,
) -> Result<()> {
    let rows = dout.nrows();
    let total: usize = dinputs.iter().map(|x| x.ncols()).sum();
    check_shape("concat backward", "dout", dout.shape(), &[rows, total])?;
    let mut start = 0;
    for d in dinputs.iter_mut() {
        let c = d.ncols();
        check_shape("concat backward", "dinput", d.shape(), &[rows, c])?;
        *d += &dout.slice(s![.., start..start + c]);
        start += c;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array2};

    // Concatenation is linear with 0/1 coefficients: hand values prove both directions exactly.
    #[test]
    fn forward_and_backward_by_hand() {
        let (a, b) = (array![[1.0], [2.0]], array![[3.0, 4.0], [5.0, 6.0]]);
        let mut out = Array2::zeros((2, 3));
        concat_forward(out.view_mut(), &[a.view(), b.view()]).unwrap();
        assert_eq!(out, array![[1.0, 3.0, 4.0], [2.0, 5.0, 6.0]]);
        let (mut da, mut db) = (Array2::ones((2, 1)), Array2::zeros((2, 2)));
        concat_backward(&mut [da.view_mut(), db.view_mut()], out.view()).unwrap();
        assert_eq!(da, array![[2.0], [3.0]]);
        assert_eq!(db, b);
    }

    #[test]
    fn width_mismatch_is_an_error() {
        let mut out = Array2::<f32>::zeros((2, 4));
        assert!(concat_forward(out.view_mut(), &[Array2::zeros((2, 3)).view()]).is_err());
    }
}
