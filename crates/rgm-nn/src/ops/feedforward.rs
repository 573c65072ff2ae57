//! The transformer's position-wise feed-forward: `Linear(C, F) → ReLU → Linear(F, C)`.

use super::linear::Linear;
use crate::init::Init;
use crate::param::{join_name, ParamView, ParamViewMut};
use crate::{Compute, Parameters, Result, Scalar};
use ndarray::{Array2, ArrayView2, ArrayViewMut2};

/// `out = ReLU(inp W1ᵀ + b1) W2ᵀ + b2`; parameters named `w_1`, `w_2` as in the reference.
#[derive(Clone, Debug)]
pub struct FeedForward<T: Scalar> {
    pub w_1: Linear<T>, // C → F
    pub w_2: Linear<T>, // F → C
}

/// The hidden activations and the backward's scratch.
#[derive(Clone, Debug, Default)]
pub struct FeedForwardCache<T> {
    pub active: Array2<T>, // (R, F) after the ReLU (the ReLU's backward needs no more)
    dhidden: Array2<T>,    // (R, F) before the ReLU
}

impl<T: Scalar> FeedForward<T> {
    /// PyTorch-initialised `C → F → C` with biases.
    pub fn new(c: usize, f: usize, init: &mut impl Init) -> Self {
        let w_1 = Linear::new(c, f, true, init);
        Self {
            w_1,
            w_2: Linear::new(f, c, true, init),
        }
    }

    /// `out`, `inp`: (R, C). The ReLU runs in `w_1`'s write-back.
    pub fn forward(
        &self,
        out: ArrayViewMut2<'_, T>,
        inp: ArrayView2<'_, T>,
        cache: &mut FeedForwardCache<T>,
        compute: Compute,
    ) -> Result<()> {
        let shape = (inp.nrows(), self.w_1.c_out());
        if cache.active.dim() != shape {
            cache.active = Array2::zeros(shape);
        }
        self.w_1
            .forward_relu(cache.active.view_mut(), inp, compute)?;
        self.w_2.forward(out, cache.active.view(), compute)
    }

    /// Chains the backwards of `w_2` through the ReLU and of `w_1` (see each). Inputs as given
    /// to forward.
    pub fn backward(
        &mut self,
        dinp: ArrayViewMut2<'_, T>,
        dout: ArrayView2<'_, T>,
        inp: ArrayView2<'_, T>,
        cache: &mut FeedForwardCache<T>,
        compute: Compute,
    ) -> Result<()> {
        let shape = cache.active.dim();
        if cache.dhidden.dim() != shape {
            cache.dhidden = Array2::zeros(shape);
        }
        self.w_2.backward_through_relu(
            cache.dhidden.view_mut(),
            dout,
            cache.active.view(),
            compute,
        )?;
        self.w_1.backward(dinp, cache.dhidden.view(), inp, compute)
    }
}

impl<T: Scalar> Parameters<T> for FeedForward<T> {
    fn visit_params_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ParamView<'a, T>)) {
        self.w_1.visit_params_ref(&join_name(prefix, "w_1"), f);
        self.w_2.visit_params_ref(&join_name(prefix, "w_2"), f);
    }

    fn visit_params(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ParamViewMut<'_, T>)) {
        self.w_1.visit_params(&join_name(prefix, "w_1"), f);
        self.w_2.visit_params(&join_name(prefix, "w_2"), f);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::{assert_gradients, ix1, ix2, uniform};
    use ndarray::ArrayD;

    #[test]
    fn backward_matches_finite_differences() {
        let inputs = vec![
            uniform(&[5, 3], 111),
            uniform(&[6, 3], 112),
            uniform(&[6], 113),
            uniform(&[3, 6], 114),
            uniform(&[3], 115),
        ];
        let layer = |i: &[ArrayD<f64>]| FeedForward {
            w_1: Linear::from_values(ix2(&i[1]), Some(ix1(&i[2]))).unwrap(),
            w_2: Linear::from_values(ix2(&i[3]), Some(ix1(&i[4]))).unwrap(),
        };
        let run = |i: &[ArrayD<f64>]| {
            let (mut out, mut cache) = (Array2::zeros((5, 3)), FeedForwardCache::default());
            layer(i)
                .forward(
                    out.view_mut(),
                    ix2(&i[0]).view(),
                    &mut cache,
                    Compute::default(),
                )
                .unwrap();
            (out, cache)
        };
        // No hidden unit may sit within the step of the ReLU kink, or the check is ill-posed.
        let mut hidden = Array2::zeros((5, 6));
        layer(&inputs)
            .w_1
            .forward(
                hidden.view_mut(),
                ix2(&inputs[0]).view(),
                Compute::default(),
            )
            .unwrap();
        assert!(hidden.iter().all(|h: &f64| h.abs() > 1e-3));
        assert_gradients(
            "feed_forward",
            1e-6,
            &inputs,
            &mut |i| run(i).0.into_dyn(),
            &mut |i, dout| {
                let (_, mut cache) = run(i);
                let mut ff = layer(i);
                let mut dx = Array2::zeros((5, 3));
                ff.backward(
                    dx.view_mut(),
                    ix2(dout).view(),
                    ix2(&i[0]).view(),
                    &mut cache,
                    Compute::default(),
                )
                .unwrap();
                let (w1, w2) = (ff.w_1, ff.w_2);
                vec![
                    dx.into_dyn(),
                    w1.weight.grad.into_dyn(),
                    w1.bias.unwrap().grad.into_dyn(),
                    w2.weight.grad.into_dyn(),
                    w2.bias.unwrap().grad.into_dyn(),
                ]
            },
        );
    }
}
