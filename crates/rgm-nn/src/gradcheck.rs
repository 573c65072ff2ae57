//! Test support: checks a hand-written backward pass against central finite differences, in f64.
//! Used by every op's tests here and by the crates above for their own ops.
//!
//! The scalar loss is `L = Σ out ⊙ R` for a fixed random `R` of the output's shape, so the
//! backward pass is called with `dout = R` and must return `dL/dinput` for every input.

use ndarray::{Array1, Array2, Array3, ArrayD, Ix1, Ix2, Ix3, IxDyn};
use rand::{rngs::StdRng, Rng, SeedableRng};

/// Central-difference step, scaled by `max(1, |x|)`.
const STEP: f64 = 1e-5;

/// An array of `shape` with entries uniform in [-1, 1), reproducible from `seed`.
pub fn uniform(shape: &[usize], seed: u64) -> ArrayD<f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    ArrayD::from_shape_simple_fn(IxDyn(shape), || rng.gen_range(-1.0..1.0))
}

/// An op's forward as the check calls it: inputs → output.
pub type ForwardFn<'a> = dyn FnMut(&[ArrayD<f64>]) -> ArrayD<f64> + 'a;

/// An op's backward as the check calls it: (inputs, dout) → one gradient per input.
pub type BackwardFn<'a> = dyn FnMut(&[ArrayD<f64>], &ArrayD<f64>) -> Vec<ArrayD<f64>> + 'a;

/// The 1-D array held by `a` (panics if `a` is not 1-D: test inputs only).
pub fn ix1(a: &ArrayD<f64>) -> Array1<f64> {
    a.clone()
        .into_dimensionality::<Ix1>()
        .expect("a 1-D test input")
}

/// The 2-D array held by `a` (panics if `a` is not 2-D: test inputs only).
pub fn ix2(a: &ArrayD<f64>) -> Array2<f64> {
    a.clone()
        .into_dimensionality::<Ix2>()
        .expect("a 2-D test input")
}

/// The 3-D array held by `a` (panics if `a` is not 3-D: test inputs only).
pub fn ix3(a: &ArrayD<f64>) -> Array3<f64> {
    a.clone()
        .into_dimensionality::<Ix3>()
        .expect("a 3-D test input")
}

/// The relative error of each input's analytic gradient: `max|analytic − numeric| /
/// max|numeric|`. `forward` maps the inputs to the output; `backward(inputs, dout)` returns one
/// gradient per input (the same shapes). Returns an error message when a gradient has the wrong
/// shape or when a numeric gradient is identically zero (the check would prove nothing).
pub fn relative_errors(
    inputs: &[ArrayD<f64>],
    forward: &mut ForwardFn<'_>,
    backward: &mut BackwardFn<'_>,
) -> Result<Vec<f64>, String> {
    let out = forward(inputs);
    let r = uniform(out.shape(), 0x5eed); // dL/dout
    let loss = |out: &ArrayD<f64>| -> f64 { out.iter().zip(r.iter()).map(|(o, r)| o * r).sum() };
    let analytic = backward(inputs, &r);
    if analytic.len() != inputs.len() {
        return Err(format!(
            "backward returned {} gradients for {} inputs",
            analytic.len(),
            inputs.len()
        ));
    }
    let mut moved = inputs.to_vec();
    let mut errors = Vec::with_capacity(inputs.len());
    for (i, grad) in analytic.iter().enumerate() {
        if grad.shape() != inputs[i].shape() {
            return Err(format!(
                "gradient {i} has shape {:?}, input {:?}",
                grad.shape(),
                inputs[i].shape()
            ));
        }
        let (mut worst_diff, mut largest) = (0.0f64, 0.0f64);
        for j in 0..inputs[i].len() {
            let x = inputs[i].as_slice_memory_order().expect("standard layout")[j];
            let h = STEP * x.abs().max(1.0);
            moved[i].as_slice_memory_order_mut().unwrap()[j] = x + h;
            let plus = loss(&forward(&moved));
            moved[i].as_slice_memory_order_mut().unwrap()[j] = x - h;
            let minus = loss(&forward(&moved));
            moved[i].as_slice_memory_order_mut().unwrap()[j] = x;
            let numeric = (plus - minus) / (2.0 * h);
            let a = grad.as_slice_memory_order().expect("standard layout")[j];
            worst_diff = worst_diff.max((a - numeric).abs());
            largest = largest.max(numeric.abs());
        }
        if largest == 0.0 {
            return Err(format!("numeric gradient of input {i} is identically zero"));
        }
        errors.push(worst_diff / largest);
    }
    Ok(errors)
}

/// Panics (naming `what` and the input) unless every input's relative error is below `tol`.
pub fn assert_gradients(
    what: &str,
    tol: f64,
    inputs: &[ArrayD<f64>],
    forward: &mut ForwardFn<'_>,
    backward: &mut BackwardFn<'_>,
) {
    let errors =
        relative_errors(inputs, forward, backward).unwrap_or_else(|e| panic!("{what}: {e}"));
    for (i, e) in errors.iter().enumerate() {
        assert!(
            *e < tol,
            "{what}: input {i} relative gradient error {e:e} >= {tol:e}"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // y = x², so dy/dx = 2x: the right backward passes, a wrong one (3x) is caught.
    #[test]
    fn catches_a_wrong_gradient() {
        let x = uniform(&[3, 2], 1);
        let mut fwd = |i: &[ArrayD<f64>]| i[0].mapv(|v| v * v);
        let right = relative_errors(std::slice::from_ref(&x), &mut fwd, &mut |i, d| {
            vec![&i[0] * 2.0 * d]
        })
        .unwrap();
        assert!(right[0] < 1e-8, "{right:?}");
        let wrong = relative_errors(&[x], &mut fwd, &mut |i, d| vec![&i[0] * 3.0 * d]).unwrap();
        assert!(wrong[0] > 0.4, "{wrong:?}");
    }

    #[test]
    fn refuses_a_vacuous_check() {
        let x = uniform(&[2], 2);
        let e = relative_errors(&[x], &mut |i| i[0].mapv(|_| 1.0), &mut |i, _| {
            vec![i[0].mapv(|_| 0.0)]
        });
        assert!(e.is_err());
    }
}
