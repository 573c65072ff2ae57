//! The "annotated transformer" LayerNorm over the channels of each row:
//! `y = a ⊙ (x − mean) / (std + eps) + b` with the *unbiased* standard deviation and eps added to
//! the std (not `torch.nn.LayerNorm`, which uses the biased variance inside the square root).

use crate::error::{check_shape, check_shapes};
use crate::param::{join_name, ParamView, ParamViewMut};
use crate::{NnError, Param, Parameters, Result, Scalar};
use ndarray::{Array1, ArrayView1, ArrayView2, ArrayViewMut2, Ix1, Zip};

/// The annotated transformer's LayerNorm; parameters named `a_2` (scale) and `b_2` (shift) as
/// in its state dict.
#[derive(Clone, Debug)]
pub struct LayerNorm<T: Scalar> {
    pub scale: Param<T, Ix1>, // (C), "a_2", initialised to 1
    pub shift: Param<T, Ix1>, // (C), "b_2", initialised to 0
    pub eps: T,               // 1e-6
}

/// What [`LayerNorm::backward`] needs besides the input.
#[derive(Clone, Debug, Default)]
pub struct LayerNormCache<T> {
    pub mean: Array1<T>, // (R)
    pub std: Array1<T>,  // (R), unbiased
}

impl<T: Scalar> LayerNorm<T> {
    /// Scale 1, shift 0, eps 1e-6 over `c` channels.
    pub fn new(c: usize) -> Self {
        Self {
            scale: Param::new(Array1::ones(c)),
            shift: Param::new(Array1::zeros(c)),
            eps: T::from_f64(1e-6),
        }
    }

    pub fn channels(&self) -> usize {
        self.scale.value.len()
    }

    /// `out = a ⊙ (inp − mean) / (std + eps) + b`, row by row. `out`, `inp`: (R, C), C ≥ 2.
    pub fn forward(
        &self,
        mut out: ArrayViewMut2<'_, T>,
        inp: ArrayView2<'_, T>,
        cache: &mut LayerNormCache<T>,
    ) -> Result<()> {
        let (rows, c) = inp.dim();
        check_shape(
            "layer_norm forward",
            "inp",
            inp.shape(),
            &[rows, self.channels()],
        )?;
        check_shape("layer_norm forward", "out", out.shape(), &[rows, c])?;
        if c < 2 {
            return Err(NnError::InvalidArgument {
                op: "layer_norm forward",
                why: format!("unbiased std needs C >= 2, got {c}"),
            });
        }
        if cache.mean.len() != rows {
            cache.mean = Array1::zeros(rows);
            cache.std = Array1::zeros(rows);
        }
        let (cf, cm1) = (T::from_f64(c as f64), T::from_f64((c - 1) as f64));
        for r in 0..rows {
            let x = inp.row(r);
            let mean = x.sum() / cf;
            let std = (x
                .iter()
                .fold(T::zero(), |s, &v| s + (v - mean) * (v - mean))
                / cm1)
                .sqrt();
            let inv = T::one() / (std + self.eps);
            Zip::from(out.row_mut(r))
                .and(&x)
                .and(&self.scale.value)
                .and(&self.shift.value)
                .for_each(|y, &x, &a, &b| {
                    *y = a * (x - mean) * inv + b;
                });
            cache.mean[r] = mean;
            cache.std[r] = std;
        }
        Ok(())
    }

    /// Differentiates `y = a ⊙ d / (s + eps) + b`, `d = x − mean`, `s = √(Σ d² / (C − 1))`.
    /// With `g = dout ⊙ a` and `r = 1 / (s + eps)`:
    /// `dx = r (g − mean(g)) − r² (Σ_j g_j d_j) d / ((C − 1) s)` (the last term vanishes when
    /// `s = 0`), `da += Σ_rows dout ⊙ d r`, `db += Σ_rows dout`.
    pub fn backward(
        &mut self,
        mut dinp: ArrayViewMut2<'_, T>,
        dout: ArrayView2<'_, T>,
        inp: ArrayView2<'_, T>,
        cache: &LayerNormCache<T>,
    ) -> Result<()> {
        let (rows, c) = inp.dim();
        check_shapes(
            "layer_norm backward",
            &[cache.mean.len(), self.channels()],
            &[
                ("inp", inp.shape()),
                ("dinp", dinp.shape()),
                ("dout", dout.shape()),
            ],
        )?;
        let (cf, cm1) = (T::from_f64(c as f64), T::from_f64((c - 1) as f64));
        for r in 0..rows {
            let (mean, std) = (cache.mean[r], cache.std[r]);
            let inv = T::one() / (std + self.eps);
            let (x, g_out) = (inp.row(r), dout.row(r));
            let (g_sum, g_dot_d) = grad_sums(x, g_out, self.scale.value.view(), mean);
            let g_mean = g_sum / cf;
            let coef = if std > T::zero() {
                inv * inv * g_dot_d / (cm1 * std)
            } else {
                T::zero()
            };
            Zip::from(dinp.row_mut(r))
                .and(&x)
                .and(&g_out)
                .and(&self.scale.value)
                .for_each(|dx, &x, &go, &a| {
                    *dx = *dx + inv * (go * a - g_mean) - coef * (x - mean);
                });
            Zip::from(&mut self.scale.grad)
                .and(&mut self.shift.grad)
                .and(&x)
                .and(&g_out)
                .for_each(|da, db, &x, &go| {
                    *da += go * (x - mean) * inv;
                    *db += go;
                });
        }
        Ok(())
    }
}

/// `(Σ_j g_j, Σ_j g_j (x_j − mean))` over one row, `g = dout ⊙ a`: eight running sums of each,
/// so that the additions vectorise (a single running sum is one serial chain of additions).
fn grad_sums<T: Scalar>(
    x: ArrayView1<'_, T>,
    g_out: ArrayView1<'_, T>,
    a: ArrayView1<'_, T>,
    mean: T,
) -> (T, T) {
    let (Some(x), Some(g_out), Some(a)) = (x.as_slice(), g_out.as_slice(), a.as_slice()) else {
        // Strided rows: the same sums on contiguous copies.
        let copy = |v: ArrayView1<'_, T>| Array1::from_iter(v.iter().copied());
        let (x, g_out, a) = (copy(x), copy(g_out), copy(a));
        return grad_sums(x.view(), g_out.view(), a.view(), mean);
    };
    const LANES: usize = 8;
    let (mut sums, mut dots) = ([T::zero(); LANES], [T::zero(); LANES]);
    let whole = x.len() - x.len() % LANES;
    for ((x, go), a) in x[..whole]
        .chunks_exact(LANES)
        .zip(g_out[..whole].chunks_exact(LANES))
        .zip(a[..whole].chunks_exact(LANES))
    {
        for l in 0..LANES {
            let g = go[l] * a[l];
            sums[l] += g;
            dots[l] += g * (x[l] - mean);
        }
    }
    let (mut sum, mut dot) = (T::zero(), T::zero());
    for j in whole..x.len() {
        let g = g_out[j] * a[j];
        sum += g;
        dot += g * (x[j] - mean);
    }
    for l in 0..LANES {
        sum += sums[l];
        dot += dots[l];
    }
    (sum, dot)
}

impl<T: Scalar> Parameters<T> for LayerNorm<T> {
    fn visit_params_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ParamView<'a, T>)) {
        f(&join_name(prefix, "a_2"), self.scale.view());
        f(&join_name(prefix, "b_2"), self.shift.view());
    }

    fn visit_params(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ParamViewMut<'_, T>)) {
        f(&join_name(prefix, "a_2"), self.scale.view_mut());
        f(&join_name(prefix, "b_2"), self.shift.view_mut());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::{assert_gradients, ix1, ix2, uniform};
    use ndarray::{array, Array2, ArrayD};

    #[test]
    fn forward_by_hand_uses_unbiased_std_plus_eps() {
        // x = (1, 2, 3, 6): mean 3, unbiased var (4 + 1 + 0 + 9) / 3 = 14/3.
        let ln = LayerNorm::<f64>::new(4);
        let (mut y, mut cache) = (Array2::zeros((1, 4)), LayerNormCache::default());
        ln.forward(
            y.view_mut(),
            array![[1.0, 2.0, 3.0, 6.0]].view(),
            &mut cache,
        )
        .unwrap();
        let s = (14.0f64 / 3.0).sqrt() + 1e-6;
        for (got, want) in y.iter().zip([-2.0 / s, -1.0 / s, 0.0, 3.0 / s]) {
            assert!((got - want).abs() < 1e-15, "{y}");
        }
    }

    fn layer(i: &[ArrayD<f64>]) -> LayerNorm<f64> {
        let mut ln = LayerNorm::new(i[1].len());
        ln.scale.value = ix1(&i[1]);
        ln.shift.value = ix1(&i[2]);
        ln
    }

    #[test]
    fn backward_matches_finite_differences() {
        // C = 5 (fewer channels than the backward's eight running sums) and C = 19 (two rounds
        // of them and a remainder of three).
        for c in [5, 19] {
            let inputs = [uniform(&[4, c], 61), uniform(&[c], 62), uniform(&[c], 63)];
            let run = |i: &[ArrayD<f64>]| {
                let (mut y, mut cache) = (Array2::zeros((4, c)), LayerNormCache::default());
                layer(i)
                    .forward(y.view_mut(), ix2(&i[0]).view(), &mut cache)
                    .unwrap();
                (y, cache)
            };
            assert_gradients(
                "layer_norm",
                1e-6,
                &inputs,
                &mut |i| run(i).0.into_dyn(),
                &mut |i, dout| {
                    let (_, cache) = run(i);
                    let mut ln = layer(i);
                    let mut dx = Array2::zeros((4, c));
                    ln.backward(dx.view_mut(), ix2(dout).view(), ix2(&i[0]).view(), &cache)
                        .unwrap();
                    vec![
                        dx.into_dyn(),
                        ln.scale.grad.into_dyn(),
                        ln.shift.grad.into_dyn(),
                    ]
                },
            );
        }
    }

    #[test]
    fn strided_rows_give_the_contiguous_gradients() {
        // Every other column of a (3, 38) array: rows of 19 values two apart.
        let (wide, dout) = (ix2(&uniform(&[3, 38], 64)), ix2(&uniform(&[3, 19], 65)));
        let strided = wide.slice(ndarray::s![.., ..;2]);
        let grads = |x: ArrayView2<'_, f64>| {
            let (mut ln, mut cache) = (LayerNorm::<f64>::new(19), LayerNormCache::default());
            ln.scale.value = ix1(&uniform(&[19], 66));
            ln.forward(Array2::zeros((3, 19)).view_mut(), x, &mut cache)
                .unwrap();
            let mut dx = Array2::zeros((3, 19));
            ln.backward(dx.view_mut(), dout.view(), x, &cache).unwrap();
            (dx, ln.scale.grad, ln.shift.grad)
        };
        assert_eq!(grads(strided), grads(strided.to_owned().view()));
    }

    // A constant row has std = 0, where std is not differentiable (PyTorch returns NaN there).
    // Here the std term is dropped: y = b and dx = (g − mean(g)) / eps, finite.
    #[test]
    fn constant_row_gives_shift_and_finite_gradient() {
        let mut ln = LayerNorm::<f64>::new(2);
        ln.shift.value = array![0.5, -0.5];
        let x = array![[0.3, 0.3]];
        let (mut y, mut cache) = (Array2::zeros((1, 2)), LayerNormCache::default());
        ln.forward(y.view_mut(), x.view(), &mut cache).unwrap();
        assert_eq!(y, array![[0.5, -0.5]]);
        let mut dx = Array2::zeros((1, 2));
        ln.backward(dx.view_mut(), array![[1.0, 3.0]].view(), x.view(), &cache)
            .unwrap();
        // g = (1, 3), mean(g) = 2: dx = (−1, 1) / 1e-6.
        assert!(
            (dx[[0, 0]] + 1e6).abs() < 1e-6 && (dx[[0, 1]] - 1e6).abs() < 1e-6,
            "{dx}"
        );
    }
}
