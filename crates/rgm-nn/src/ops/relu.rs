//! ReLU, elementwise on any shape.

use crate::error::{check_shape, check_shapes};
use crate::{Result, Scalar};
use ndarray::{ArrayView, ArrayViewMut, Dimension, Zip};

/// `max(x, 0)`, and 0 for NaN.
fn relu<T: Scalar>(x: T) -> T {
    if x > T::zero() {
        x
    } else {
        T::zero()
    }
}

/// `out = max(inp, 0)`.
pub fn relu_forward<T: Scalar, D: Dimension>(
    mut out: ArrayViewMut<'_, T, D>,
    inp: ArrayView<'_, T, D>,
) -> Result<()> {
    check_shape("relu forward", "out", out.shape(), inp.shape())?;
    Zip::from(&mut out).and(&inp).for_each(|o, &x| *o = relu(x));
    Ok(())
}

/// `x = max(x, 0)` in place: [`relu_forward`] where the input is not needed afterwards (its
/// backward reads the output only), one pass over memory fewer.
pub fn relu_in_place<T: Scalar, D: Dimension>(mut x: ArrayViewMut<'_, T, D>) {
    x.mapv_inplace(relu);
}

/// Differentiates `out = max(inp, 0)`: `dinp += dout · [out > 0]` (zero gradient at 0, as
/// PyTorch). `out` is the forward's output.
pub fn relu_backward<T: Scalar, D: Dimension>(
    mut dinp: ArrayViewMut<'_, T, D>,
    dout: ArrayView<'_, T, D>,
    out: ArrayView<'_, T, D>,
) -> Result<()> {
    check_shapes(
        "relu backward",
        out.shape(),
        &[("dinp", dinp.shape()), ("dout", dout.shape())],
    )?;
    Zip::from(&mut dinp)
        .and(&dout)
        .and(&out)
        // A select, not a branch: the loop vectorises.
        .for_each(|d, &g, &y| *d += if y > T::zero() { g } else { T::zero() });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::{assert_gradients, uniform};
    use ndarray::{array, Array2, ArrayD};

    #[test]
    fn forward_and_backward_by_hand() {
        let x = array![[-1.0, 0.0, 2.0]];
        let mut y = x.clone();
        relu_forward(y.view_mut(), x.view()).unwrap();
        assert_eq!(y, array![[0.0, 0.0, 2.0]]);
        let mut dx = array![[1.0, 1.0, 1.0]];
        relu_backward(dx.view_mut(), array![[5.0, 5.0, 5.0]].view(), y.view()).unwrap();
        assert_eq!(dx, array![[1.0, 1.0, 6.0]]);
    }

    #[test]
    fn in_place_is_the_forward() {
        let x = array![[-1.0, 0.0, 2.0, -0.0, f64::NAN, 1e-300]];
        let mut y = Array2::zeros((1, 6));
        relu_forward(y.view_mut(), x.view()).unwrap();
        let mut z = x.clone();
        relu_in_place(z.view_mut());
        assert_eq!(z.mapv(f64::to_bits), y.mapv(f64::to_bits));
        assert_eq!(z, array![[0.0, 0.0, 2.0, 0.0, 0.0, 1e-300]]);
    }

    #[test]
    fn backward_matches_finite_differences() {
        // Random inputs stay away from the kink at 0 by far more than the step.
        let x = uniform(&[6, 4], 11).mapv(|v: f64| if v.abs() < 0.01 { 0.5 } else { v });
        assert_gradients(
            "relu",
            1e-6,
            &[x],
            &mut |i| {
                let mut out = ArrayD::zeros(i[0].shape());
                relu_forward(out.view_mut(), i[0].view()).unwrap();
                out
            },
            &mut |i, dout| {
                let mut out = ArrayD::zeros(i[0].shape());
                relu_forward(out.view_mut(), i[0].view()).unwrap();
                let mut dinp = ArrayD::zeros(i[0].shape());
                relu_backward(dinp.view_mut(), dout.view(), out.view()).unwrap();
                vec![dinp]
            },
        );
    }
}
