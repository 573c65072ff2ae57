//! Batch normalisation of each channel over all rows (`nn.BatchNorm1d`/`2d` on RGM's layouts:
//! rows are points × neighbours, or points, of every cloud in the batch).

use crate::error::{check_shape, check_shapes};
use crate::param::{join_name, ParamView, ParamViewMut};
use crate::{NnError, Param, Parameters, Result, Scalar};
use ndarray::{Array1, ArrayView2, ArrayViewD, ArrayViewMut2, ArrayViewMutD, Ix1, Zip};

/// Batch norm with PyTorch's semantics: training mode normalises with the batch mean and
/// *biased* variance and updates the running statistics with `momentum` using the *unbiased*
/// variance; evaluation mode normalises with the running statistics.
#[derive(Clone, Debug)]
pub struct BatchNorm<T: Scalar> {
    pub weight: Param<T, Ix1>,   // (C), γ, initialised to 1
    pub bias: Param<T, Ix1>,     // (C), β, initialised to 0
    pub running_mean: Array1<T>, // (C), initialised to 0
    pub running_var: Array1<T>,  // (C), initialised to 1
    pub momentum: T,             // 0.1
    pub eps: T,                  // 1e-5
}

/// What [`BatchNorm::backward`] needs besides the input: the statistics that normalised it.
#[derive(Clone, Debug, Default)]
pub struct BatchNormCache<T> {
    pub mean: Array1<T>, // (C), batch mean (training) or running mean (evaluation)
    pub var: Array1<T>,  // (C), the batch's biased variance (training only)
    pub rstd: Array1<T>, // (C), 1 / √(var + eps) of the same statistics
    pub training: bool,  // whether mean and rstd came from the batch
}

impl<T: Scalar> BatchNorm<T> {
    /// PyTorch's defaults over `c` channels: γ = 1, β = 0, momentum 0.1, eps 1e-5.
    pub fn new(c: usize) -> Self {
        Self {
            weight: Param::new(Array1::ones(c)),
            bias: Param::new(Array1::zeros(c)),
            running_mean: Array1::zeros(c),
            running_var: Array1::ones(c),
            momentum: T::from_f64(0.1),
            eps: T::from_f64(1e-5),
        }
    }

    pub fn channels(&self) -> usize {
        self.weight.value.len()
    }

    /// `out = γ (inp − μ) rstd + β` per channel. Training mode (`training = true`, needs R ≥ 2):
    /// μ, σ² are the batch mean and biased variance, and the running statistics move by
    /// `running = (1 − momentum) running + momentum · batch` with the unbiased variance
    /// `σ² R / (R − 1)`. Evaluation mode uses the running statistics. `out`, `inp`: (R, C).
    pub fn forward(
        &mut self,
        out: ArrayViewMut2<'_, T>,
        inp: ArrayView2<'_, T>,
        training: bool,
        cache: &mut BatchNormCache<T>,
    ) -> Result<()> {
        self.normalise(out, inp, training, cache)?;
        if training {
            let rows = inp.nrows();
            let unbias = T::from_f64(rows as f64) / T::from_f64((rows - 1) as f64);
            let m = self.momentum;
            Zip::from(&mut self.running_mean)
                .and(&cache.mean)
                .for_each(|r, &b| *r = (T::one() - m) * *r + m * b);
            Zip::from(&mut self.running_var)
                .and(&cache.var)
                .for_each(|r, &v| *r = (T::one() - m) * *r + m * v * unbias);
        }
        Ok(())
    }

    /// [`BatchNorm::forward`] without the running statistics' update, through `&self`: with
    /// the batch's statistics (`batch = true`, needs R ≥ 2) or the running ones. A network
    /// that normalises each cloud by its own statistics at test time runs its clouds side by
    /// side through this.
    pub fn normalise(
        &self,
        mut out: ArrayViewMut2<'_, T>,
        inp: ArrayView2<'_, T>,
        batch: bool,
        cache: &mut BatchNormCache<T>,
    ) -> Result<()> {
        let (rows, c) = inp.dim();
        check_shape(
            "batch_norm forward",
            "inp",
            inp.shape(),
            &[rows, self.channels()],
        )?;
        check_shape("batch_norm forward", "out", out.shape(), &[rows, c])?;
        if cache.mean.len() != c {
            cache.mean = Array1::zeros(c);
            cache.var = Array1::zeros(c);
            cache.rstd = Array1::zeros(c);
        }
        cache.training = batch;
        if batch {
            if rows < 2 {
                return Err(NnError::InvalidArgument {
                    op: "batch_norm forward",
                    why: format!("training needs >= 2 rows, got {rows}"),
                });
            }
            let rf = T::from_f64(rows as f64);
            // Row by row as slices: one vector loop over the channels per row.
            let x = inp.as_standard_layout(); // (R, C)
            let x_rows = || {
                x.as_slice()
                    .expect("standard layout")
                    .chunks_exact(c.max(1))
            };
            let mean = cache
                .mean
                .as_slice_mut()
                .expect("a new array is contiguous");
            mean.fill(T::zero());
            for row in x_rows() {
                mean.iter_mut().zip(row).for_each(|(m, &x)| *m += x);
            }
            mean.iter_mut().for_each(|s| *s /= rf);
            let var = cache.var.as_slice_mut().expect("a new array is contiguous");
            var.fill(T::zero());
            for row in x_rows() {
                for ((v, &x), &m) in var.iter_mut().zip(row).zip(&*mean) {
                    *v += (x - m) * (x - m);
                }
            }
            var.iter_mut().for_each(|s| *s /= rf);
            Zip::from(&mut cache.rstd)
                .and(&cache.var)
                .for_each(|r, &v| *r = T::one() / (v + self.eps).sqrt());
        } else {
            cache.mean.assign(&self.running_mean);
            Zip::from(&mut cache.rstd)
                .and(&self.running_var)
                .for_each(|r, &v| *r = T::one() / (v + self.eps).sqrt());
        }
        // y = x · scale + shift per channel, one pass over the whole matrix.
        let scale = &self.weight.value * &cache.rstd; // (C)
        let shift = Zip::from(&self.bias.value)
            .and(&scale)
            .and(&cache.mean)
            .map_collect(|&b, &a, &m| b - a * m); // (C)
        Zip::from(&mut out)
            .and(&inp)
            .and_broadcast(&scale)
            .and_broadcast(&shift)
            .for_each(|y, &x, &a, &b| *y = x * a + b);
        Ok(())
    }

    /// Differentiates `y = γ x̂ + β`, `x̂ = (x − μ) rstd`:
    /// `dγ += Σ_rows dy x̂`, `dβ += Σ_rows dy`; in training mode (μ and rstd depend on every row)
    /// `dx = γ rstd (dy − mean(dy) − x̂ mean(dy x̂))`, in evaluation mode `dx = γ rstd dy`.
    /// `dinp`, `dout`, `inp`: (R, C).
    pub fn backward(
        &mut self,
        mut dinp: ArrayViewMut2<'_, T>,
        dout: ArrayView2<'_, T>,
        inp: ArrayView2<'_, T>,
        cache: &BatchNormCache<T>,
    ) -> Result<()> {
        let (rows, c) = inp.dim();
        check_shape(
            "batch_norm backward",
            "cache",
            &[cache.mean.len()],
            &[self.channels()],
        )?;
        check_shapes(
            "batch_norm backward",
            &[rows, self.channels()],
            &[
                ("inp", inp.shape()),
                ("dinp", dinp.shape()),
                ("dout", dout.shape()),
            ],
        )?;
        let mut sum_g = Array1::<T>::zeros(c); // (C), Σ_rows dy
        let mut sum_gx = Array1::<T>::zeros(c); // (C), Σ_rows dy x̂
        {
            // Row by row as slices: one vector loop over the channels per row.
            let (dout, inp) = (dout.as_standard_layout(), inp.as_standard_layout()); // (R, C)
            let (mean, rstd) = (
                cache.mean.as_slice().expect("a new array is contiguous"),
                cache.rstd.as_slice().expect("a new array is contiguous"),
            );
            let sg = sum_g.as_slice_mut().expect("a new array is contiguous");
            let sgx = sum_gx.as_slice_mut().expect("a new array is contiguous");
            let rows = dout
                .as_slice()
                .expect("standard layout")
                .chunks_exact(c.max(1));
            for (g, x) in rows.zip(
                inp.as_slice()
                    .expect("standard layout")
                    .chunks_exact(c.max(1)),
            ) {
                for j in 0..c {
                    sg[j] += g[j];
                    sgx[j] += g[j] * (x[j] - mean[j]) * rstd[j];
                }
            }
        }
        self.bias.grad += &sum_g;
        self.weight.grad += &sum_gx;
        let gain = &self.weight.value * &cache.rstd; // (C), γ rstd
        if cache.training {
            // dx = γ rstd (dy − Σdy/R − (x − μ) rstd Σ(dy x̂)/R) = gain dy + slope x + offset.
            let rf = T::from_f64(rows as f64);
            let slope = Zip::from(&gain)
                .and(&cache.rstd)
                .and(&sum_gx)
                .map_collect(|&a, &r, &s| -a * r * s / rf); // (C)
            let offset = Zip::from(&gain)
                .and(&sum_g)
                .and(&slope)
                .and(&cache.mean)
                .map_collect(|&a, &s, &b, &m| -a * s / rf - b * m); // (C)
            Zip::from(&mut dinp)
                .and(&dout)
                .and(&inp)
                .and_broadcast(&gain)
                .and_broadcast(&slope)
                .and_broadcast(&offset)
                .for_each(|d, &g, &x, &a, &b, &o| *d += a * g + b * x + o);
        } else {
            Zip::from(&mut dinp)
                .and(&dout)
                .and_broadcast(&gain)
                .for_each(|d, &g, &a| *d += a * g);
        }
        Ok(())
    }
}

impl<T: Scalar> Parameters<T> for BatchNorm<T> {
    fn visit_params_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ParamView<'a, T>)) {
        f(&join_name(prefix, "weight"), self.weight.view());
        f(&join_name(prefix, "bias"), self.bias.view());
    }

    fn visit_buffers_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ArrayViewD<'a, T>)) {
        f(
            &join_name(prefix, "running_mean"),
            self.running_mean.view().into_dyn(),
        );
        f(
            &join_name(prefix, "running_var"),
            self.running_var.view().into_dyn(),
        );
    }

    fn visit_params(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ParamViewMut<'_, T>)) {
        f(&join_name(prefix, "weight"), self.weight.view_mut());
        f(&join_name(prefix, "bias"), self.bias.view_mut());
    }

    fn visit_buffers(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ArrayViewMutD<'_, T>)) {
        f(
            &join_name(prefix, "running_mean"),
            self.running_mean.view_mut().into_dyn(),
        );
        f(
            &join_name(prefix, "running_var"),
            self.running_var.view_mut().into_dyn(),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::{assert_gradients, ix1, ix2, uniform};
    use ndarray::{array, Array2, ArrayD};

    #[test]
    fn training_forward_and_running_update_by_hand() {
        // One channel, rows (1, 2, 3, 6): mean 3, biased var 14/4, unbiased var 14/3.
        let mut bn = BatchNorm::<f64>::new(1);
        let x = array![[1.0], [2.0], [3.0], [6.0]];
        let (mut y, mut cache) = (Array2::zeros((4, 1)), BatchNormCache::default());
        bn.forward(y.view_mut(), x.view(), true, &mut cache)
            .unwrap();
        let s = (3.5f64 + 1e-5).sqrt();
        for (got, want) in y.iter().zip([-2.0 / s, -1.0 / s, 0.0, 3.0 / s]) {
            assert!((got - want).abs() < 1e-14, "{y}");
        }
        assert!((bn.running_mean[0] - 0.3).abs() < 1e-15);
        assert!((bn.running_var[0] - (0.9 + 0.1 * 14.0 / 3.0)).abs() < 1e-15);
        // Evaluation uses the running statistics: (x − 0.3) / √(running_var + eps).
        bn.forward(y.view_mut(), x.view(), false, &mut cache)
            .unwrap();
        let s = (bn.running_var[0] + 1e-5).sqrt();
        assert!((y[[0, 0]] - 0.7 / s).abs() < 1e-14);
    }

    fn layer(i: &[ArrayD<f64>]) -> BatchNorm<f64> {
        let mut bn = BatchNorm::new(3);
        bn.weight.value = ix1(&i[1]);
        bn.bias.value = ix1(&i[2]);
        bn.running_mean = array![0.1, -0.2, 0.3];
        bn.running_var = array![0.5, 1.5, 2.0];
        bn
    }

    #[test]
    fn backward_matches_finite_differences_in_both_modes() {
        for training in [true, false] {
            let inputs = [uniform(&[6, 3], 71), uniform(&[3], 72), uniform(&[3], 73)];
            let run = |i: &[ArrayD<f64>]| {
                let (mut bn, mut y, mut cache) =
                    (layer(i), Array2::zeros((6, 3)), BatchNormCache::default());
                bn.forward(y.view_mut(), ix2(&i[0]).view(), training, &mut cache)
                    .unwrap();
                (bn, y, cache)
            };
            assert_gradients(
                "batch_norm",
                1e-6,
                &inputs,
                &mut |i| run(i).1.into_dyn(),
                &mut |i, dout| {
                    let (mut bn, _, cache) = run(i);
                    let mut dx = Array2::zeros((6, 3));
                    bn.backward(dx.view_mut(), ix2(dout).view(), ix2(&i[0]).view(), &cache)
                        .unwrap();
                    vec![
                        dx.into_dyn(),
                        bn.weight.grad.into_dyn(),
                        bn.bias.grad.into_dyn(),
                    ]
                },
            );
        }
    }
}
