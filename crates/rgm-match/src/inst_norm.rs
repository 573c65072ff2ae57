//! Instance normalisation of the whole N×M affinity matrix as one channel (PyTorch's
//! `InstanceNorm2d(1, affine=True)` on a 1×1×N×M input).

use crate::error::{check_shape, Result};
use ndarray::{arr1, ArrayView2, ArrayViewMut2, Ix1, Zip};
use rgm_nn::param::{join_name, ParamView, ParamViewMut};
use rgm_nn::{Param, Parameters, Scalar};

/// Settings of the instance normalisation.
#[derive(Clone, Debug, PartialEq)]
pub struct InstNormConfig {
    /// Added to the biased variance before the square root (spec: 1e-5, PyTorch's default).
    pub eps: f64,
}

impl Default for InstNormConfig {
    fn default() -> Self {
        Self { eps: 1e-5 }
    }
}

/// out = γ·(inp − μ)·rstd + β over all N·M entries, with the reference's names
/// `InstNorm_layer_b.{weight,bias}`, each of shape (1).
#[derive(Clone, Debug)]
pub struct InstNorm<T: Scalar> {
    pub weight: Param<T, Ix1>, // (1) γ
    pub bias: Param<T, Ix1>,   // (1) β
    pub eps: T,
}

/// What [`InstNorm::backward`] needs from the forward pass.
#[derive(Clone, Copy, Debug, Default)]
pub struct InstNormCache<T> {
    mean: T,
    rstd: T, // 1 / √(var + eps)
}

impl<T: Scalar> InstNorm<T> {
    /// PyTorch's initialisation of an affine InstanceNorm: γ = 1, β = 0.
    pub fn new(cfg: &InstNormConfig) -> Self {
        Self {
            weight: Param::new(arr1(&[T::one()])),
            bias: Param::new(arr1(&[T::zero()])),
            eps: T::from_f64(cfg.eps),
        }
    }

    /// out = γ·x̂ + β with x̂ = (inp − μ)·rstd, μ the mean over all N·M entries, var their biased
    /// variance and rstd = 1/√(var + eps).
    pub fn forward(
        &self,
        mut out: ArrayViewMut2<'_, T>, // (N, M)
        inp: ArrayView2<'_, T>,        // (N, M)
        cache: &mut InstNormCache<T>,
    ) -> Result<()> {
        check_shape("inst_norm forward", "out", out.shape(), inp.shape())?;
        // Sums over all N·M entries (514,089 for 717 points) in f64: accumulated in f32 they
        // lose about 5 digits, enough to move C̃ by 4.5e-5 after two Sinkhorns.
        let count = inp.len() as f64;
        let mean = inp.iter().map(|&v| Scalar::to_f64(v)).sum::<f64>() / count;
        let var = inp
            .iter()
            .map(|&v| (Scalar::to_f64(v) - mean).powi(2))
            .sum::<f64>()
            / count;
        let (mean, rstd) = (
            T::from_f64(mean),
            T::from_f64(1.0 / (var + Scalar::to_f64(self.eps)).sqrt()),
        );
        let (gamma, beta) = (self.weight.value[0], self.bias.value[0]);
        Zip::from(&mut out)
            .and(&inp)
            .for_each(|o, &v| *o = gamma * ((v - mean) * rstd) + beta);
        *cache = InstNormCache { mean, rstd };
        Ok(())
    }

    /// Differentiates out = γ·x̂ + β: dβ += Σ dout, dγ += Σ dout·x̂, and, since μ and rstd depend
    /// on every entry, dinp += γ·rstd·(dout − mean(dout) − x̂·mean(dout·x̂)).
    pub fn backward(
        &mut self,
        mut dinp: ArrayViewMut2<'_, T>, // (N, M)
        dout: ArrayView2<'_, T>,        // (N, M)
        inp: ArrayView2<'_, T>,         // (N, M)
        cache: &InstNormCache<T>,
    ) -> Result<()> {
        const OP: &str = "inst_norm backward";
        check_shape(OP, "dout", dout.shape(), inp.shape())?;
        check_shape(OP, "dinp", dinp.shape(), inp.shape())?;
        let count = T::from_f64(inp.len() as f64);
        let xhat = |v: T| (v - cache.mean) * cache.rstd;
        // Sums over all N·M entries in f64, as in the forward pass.
        let dout_sum = T::from_f64(dout.iter().map(|&g| Scalar::to_f64(g)).sum::<f64>());
        let dout_xhat_sum = T::from_f64(
            Zip::from(&dout)
                .and(&inp)
                .fold(0.0, |acc, &g, &v| acc + Scalar::to_f64(g * xhat(v))),
        );
        self.bias.grad[0] += dout_sum;
        self.weight.grad[0] += dout_xhat_sum;
        let (dout_mean, dout_xhat_mean) = (dout_sum / count, dout_xhat_sum / count);
        let k = self.weight.value[0] * cache.rstd;
        Zip::from(&mut dinp)
            .and(&dout)
            .and(&inp)
            .for_each(|d, &g, &v| {
                *d += k * (g - dout_mean - xhat(v) * dout_xhat_mean);
            });
        Ok(())
    }
}

impl<T: Scalar> Parameters<T> for InstNorm<T> {
    fn visit_params_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ParamView<'a, T>)) {
        f(&join_name(prefix, "weight"), self.weight.view());
        f(&join_name(prefix, "bias"), self.bias.view());
    }

    fn visit_params(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ParamViewMut<'_, T>)) {
        f(&join_name(prefix, "weight"), self.weight.view_mut());
        f(&join_name(prefix, "bias"), self.bias.view_mut());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference;
    use ndarray::{Array2, ArrayD};
    use rgm_nn::gradcheck::{assert_gradients, ix2, uniform};

    fn layer(gamma: f64, beta: f64) -> InstNorm<f64> {
        let mut norm = InstNorm::new(&InstNormConfig::default());
        norm.weight.value[0] = gamma;
        norm.bias.value[0] = beta;
        norm
    }

    #[test]
    fn forward_matches_reference() {
        let mut out = Array2::zeros((3, 4));
        layer(1.5, -0.25)
            .forward(
                out.view_mut(),
                reference::s().view(),
                &mut InstNormCache::default(),
            )
            .unwrap();
        assert!(out.abs_diff_eq(&reference::inst_norm(), 1e-14), "{out}");
    }

    #[test]
    fn parameter_names_match_the_reference_state_dict() {
        let mut norm = layer(1.0, 0.0);
        let mut names = vec![];
        norm.visit_params("InstNorm_layer_1", &mut |name, p| {
            names.push((name.to_string(), p.value.shape().to_vec()))
        });
        let expected = [
            ("InstNorm_layer_1.weight", vec![1]),
            ("InstNorm_layer_1.bias", vec![1]),
        ];
        assert_eq!(names, expected.map(|(n, s)| (n.to_string(), s)));
    }

    #[test]
    fn constant_input_gives_the_shift() {
        // var = 0: eps keeps rstd finite and x̂ = 0.
        let mut out = Array2::zeros((2, 3));
        layer(2.0, 0.7)
            .forward(
                out.view_mut(),
                Array2::from_elem((2, 3), 4.0).view(),
                &mut InstNormCache::default(),
            )
            .unwrap();
        assert!(out.iter().all(|&v| v == 0.7));
    }

    #[test]
    fn backward_matches_finite_differences() {
        let inputs = [
            uniform(&[3, 5], 1) * 2.0,
            ArrayD::from_elem(vec![1], 1.3),
            ArrayD::from_elem(vec![1], -0.2),
        ];
        let run = |i: &[ArrayD<f64>]| {
            let norm = layer(i[1][[0]], i[2][[0]]);
            let mut cache = InstNormCache::default();
            let mut out = Array2::zeros((3, 5));
            norm.forward(out.view_mut(), ix2(&i[0]).view(), &mut cache)
                .unwrap();
            (norm, cache, out)
        };
        assert_gradients(
            "inst_norm",
            1e-7,
            &inputs,
            &mut |i| run(i).2.into_dyn(),
            &mut |i, dout| {
                let (mut norm, cache, _) = run(i);
                let mut dinp = Array2::zeros((3, 5));
                norm.backward(dinp.view_mut(), ix2(dout).view(), ix2(&i[0]).view(), &cache)
                    .unwrap();
                vec![
                    dinp.into_dyn(),
                    norm.weight.grad.into_dyn(),
                    norm.bias.grad.into_dyn(),
                ]
            },
        );
    }
}
