//! PyTorch's default initialisation, seeded by the caller's random generator, or no
//! initialisation for a network whose weights are read next ([`Unset`]).
//!
//! `nn.Linear` and `nn.Conv{1,2}d` draw their weight with `kaiming_uniform_(a = √5)`: gain
//! `√(2 / (1 + a²)) = √(1/3)`, bound `gain · √(3 / fan_in) = 1/√fan_in`; and their bias from
//! `U(−1/√fan_in, 1/√fan_in)`. For a 1×1 convolution `fan_in` is the input channel count, so both
//! layers draw from the same law. (The values differ from PyTorch's: its generator is not ours.)

use crate::Scalar;
use ndarray::{Array, Dimension, ShapeBuilder};
use rand::Rng;

/// The PyTorch default bound `1/√fan_in` of a linear layer's weight and bias.
pub fn default_bound(fan_in: usize) -> f64 {
    1.0 / (fan_in.max(1) as f64).sqrt()
}

/// Where a new layer's parameters come from. Layers take one of these instead of a random
/// generator so that loading a model need not draw every parameter only to overwrite it (most
/// of the time it took to load one).
pub trait Init {
    /// An array of `shape` with entries uniform in `[-bound, bound)` (zeros for [`Unset`]).
    fn uniform<T: Scalar, D: Dimension, S: ShapeBuilder<Dim = D>>(
        &mut self,
        shape: S,
        bound: f64,
    ) -> Array<T, D>;
}

/// A random generator draws PyTorch's default initialisation, entry after entry in row order.
impl<R: Rng + ?Sized> Init for R {
    fn uniform<T: Scalar, D: Dimension, S: ShapeBuilder<Dim = D>>(
        &mut self,
        shape: S,
        bound: f64,
    ) -> Array<T, D> {
        Array::from_shape_simple_fn(shape, || T::from_f64(self.gen_range(-bound..bound)))
    }
}

/// Parameters left at zero, for a layer whose values are set next (read from a file).
#[derive(Clone, Copy, Debug, Default)]
pub struct Unset;

impl Init for Unset {
    fn uniform<T: Scalar, D: Dimension, S: ShapeBuilder<Dim = D>>(
        &mut self,
        shape: S,
        _bound: f64,
    ) -> Array<T, D> {
        Array::zeros(shape)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;
    use rand::{rngs::StdRng, SeedableRng};

    #[test]
    fn bound_is_one_over_sqrt_fan_in_and_draws_fill_it() {
        // kaiming_uniform(a=√5): √(2/6) · √(3/64) = √(1/64) = 0.125.
        assert_eq!(default_bound(64), 0.125);
        let w: Array2<f64> = StdRng::seed_from_u64(7).uniform((256, 64), 0.125);
        let (lo, hi) = w
            .iter()
            .fold((1.0f64, -1.0f64), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        assert!(lo >= -0.125 && hi < 0.125);
        assert!(
            lo < -0.124 && hi > 0.124,
            "draws cover the interval: {lo} {hi}"
        );
        let var = w.iter().map(|v| v * v).sum::<f64>() / w.len() as f64;
        assert!(
            (var - 0.125f64.powi(2) / 3.0).abs() < 3e-4,
            "variance of U(±b) is b²/3: {var}"
        );
    }

    #[test]
    fn unset_leaves_zeros_and_draws_nothing() {
        let w: Array2<f32> = Unset.uniform((3, 4), 0.5);
        assert_eq!(w, Array2::<f32>::zeros((3, 4)));
    }

    #[test]
    fn same_seed_same_values() {
        let a: Array2<f32> = StdRng::seed_from_u64(1).uniform((3, 4), 0.5);
        let b: Array2<f32> = StdRng::seed_from_u64(1).uniform((3, 4), 0.5);
        assert_eq!(a, b);
    }
}
