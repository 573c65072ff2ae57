//! Linear layer / 1×1 convolution on `(rows, C)` matrices, with or without bias.

use crate::error::check_shape;
use crate::gemm::{mat_mul, mat_mul_bias};
use crate::init;
use crate::param::{join_name, ParamView, ParamViewMut};
use crate::{Param, Parameters, Result, Scalar};
use ndarray::{Array1, Array2, ArrayView2, ArrayViewMut2, Ix1, Ix2};
use rand::Rng;

/// `out = inp · weightᵀ + bias`, PyTorch's `nn.Linear` (and `nn.Conv{1,2}d` with a 1×1 kernel,
/// whose `(C_out, C_in, 1, 1)` weight is this `(C_out, C_in)` one).
#[derive(Clone, Debug)]
pub struct Linear<T: Scalar> {
    pub weight: Param<T, Ix2>,       // (C_out, C_in)
    pub bias: Option<Param<T, Ix1>>, // (C_out)
}

impl<T: Scalar> Linear<T> {
    /// PyTorch's default initialisation: weight and bias uniform in `±1/√C_in`.
    pub fn new(c_in: usize, c_out: usize, bias: bool, rng: &mut impl Rng) -> Self {
        let bound = init::default_bound(c_in);
        let weight = Param::new(init::uniform((c_out, c_in), bound, rng));
        let bias = bias.then(|| Param::new(init::uniform(c_out, bound, rng)));
        Self { weight, bias }
    }

    /// A layer with the given weight `(C_out, C_in)` and optional bias `(C_out)`.
    pub fn from_values(weight: Array2<T>, bias: Option<Array1<T>>) -> Result<Self> {
        if let Some(b) = &bias {
            check_shape("linear", "bias", b.shape(), &[weight.nrows()])?;
        }
        Ok(Self {
            weight: Param::new(weight),
            bias: bias.map(Param::new),
        })
    }

    pub fn c_in(&self) -> usize {
        self.weight.value.ncols()
    }

    pub fn c_out(&self) -> usize {
        self.weight.value.nrows()
    }

    /// `out = inp · weightᵀ + bias`. `out`: (R, C_out), `inp`: (R, C_in).
    pub fn forward(&self, mut out: ArrayViewMut2<'_, T>, inp: ArrayView2<'_, T>) -> Result<()> {
        let rows = inp.nrows();
        check_shape("linear forward", "inp", inp.shape(), &[rows, self.c_in()])?;
        check_shape("linear forward", "out", out.shape(), &[rows, self.c_out()])?;
        match &self.bias {
            Some(b) => mat_mul_bias(&inp, &self.weight.value.t(), &b.value, &mut out),
            None => mat_mul(T::one(), &inp, &self.weight.value.t(), T::zero(), &mut out),
        }
        Ok(())
    }

    /// Differentiates `out = inp · weightᵀ + bias`:
    /// `dinp += dout · weight`, `dweight += doutᵀ · inp`, `dbias += Σ_rows dout`.
    /// `dinp`: (R, C_in), `dout`: (R, C_out), `inp`: (R, C_in) as given to forward.
    pub fn backward(
        &mut self,
        mut dinp: ArrayViewMut2<'_, T>,
        dout: ArrayView2<'_, T>,
        inp: ArrayView2<'_, T>,
    ) -> Result<()> {
        let rows = inp.nrows();
        check_shape("linear backward", "inp", inp.shape(), &[rows, self.c_in()])?;
        check_shape(
            "linear backward",
            "dinp",
            dinp.shape(),
            &[rows, self.c_in()],
        )?;
        check_shape(
            "linear backward",
            "dout",
            dout.shape(),
            &[rows, self.c_out()],
        )?;
        mat_mul(T::one(), &dout, &self.weight.value, T::one(), &mut dinp);
        mat_mul(T::one(), &dout.t(), &inp, T::one(), &mut self.weight.grad);
        if let Some(b) = &mut self.bias {
            for row in dout.rows() {
                b.grad += &row;
            }
        }
        Ok(())
    }
}

impl<T: Scalar> Parameters<T> for Linear<T> {
    fn visit_params_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ParamView<'a, T>)) {
        f(&join_name(prefix, "weight"), self.weight.view());
        if let Some(b) = &self.bias {
            f(&join_name(prefix, "bias"), b.view());
        }
    }

    fn visit_params(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ParamViewMut<'_, T>)) {
        f(&join_name(prefix, "weight"), self.weight.view_mut());
        if let Some(b) = &mut self.bias {
            f(&join_name(prefix, "bias"), b.view_mut());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::{assert_gradients, ix2, uniform};
    use ndarray::{array, ArrayD};
    use rand::{rngs::StdRng, SeedableRng};

    #[test]
    fn forward_by_hand() {
        // out = [1 2] · [[1 0],[0 1],[1 1]]ᵀ + [0.5 0 -1] = [1.5 2 2]
        let lin = Linear::from_values(
            array![[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]],
            Some(array![0.5, 0.0, -1.0]),
        )
        .unwrap();
        let mut out = Array2::zeros((1, 3));
        lin.forward(out.view_mut(), array![[1.0, 2.0]].view())
            .unwrap();
        assert_eq!(out, array![[1.5, 2.0, 2.0]]);
    }

    #[test]
    fn backward_matches_finite_differences() {
        // 9 rows: above ndarray's BLAS cut-off (7), so all three products run through dgemm.
        for bias in [true, false] {
            let mut inputs = vec![uniform(&[9, 5], 1), uniform(&[3, 5], 2)];
            if bias {
                inputs.push(uniform(&[3], 3));
            }
            let layer = |i: &[ArrayD<f64>]| {
                let b = i
                    .get(2)
                    .map(|b| b.clone().into_dimensionality::<Ix1>().unwrap());
                Linear::from_values(ix2(&i[1]), b).unwrap()
            };
            assert_gradients(
                "linear",
                1e-6,
                &inputs,
                &mut |i| {
                    let mut out = Array2::zeros((9, 3));
                    layer(i).forward(out.view_mut(), ix2(&i[0]).view()).unwrap();
                    out.into_dyn()
                },
                &mut |i, dout| {
                    let mut lin = layer(i);
                    let mut dinp = Array2::zeros((9, 5));
                    lin.backward(dinp.view_mut(), ix2(dout).view(), ix2(&i[0]).view())
                        .unwrap();
                    let mut grads = vec![dinp.into_dyn(), lin.weight.grad.into_dyn()];
                    grads.extend(lin.bias.map(|b| b.grad.into_dyn()));
                    grads
                },
            );
        }
    }

    #[test]
    fn backward_accumulates_and_zero_grad_clears() {
        let mut lin = Linear::<f64>::new(2, 2, true, &mut StdRng::seed_from_u64(0));
        assert_eq!(lin.num_params(), 6, "2×2 weight and 2 biases");
        let (inp, dout) = (array![[1.0, 2.0]], array![[1.0, -1.0]]);
        let mut dinp = Array2::zeros((1, 2));
        lin.backward(dinp.view_mut(), dout.view(), inp.view())
            .unwrap();
        let once = (dinp.clone(), lin.weight.grad.clone());
        lin.backward(dinp.view_mut(), dout.view(), inp.view())
            .unwrap();
        assert_eq!(dinp, &once.0 * 2.0);
        assert_eq!(lin.weight.grad, &once.1 * 2.0);
        lin.zero_grad();
        assert!(lin
            .weight
            .grad
            .iter()
            .chain(lin.bias.as_ref().unwrap().grad.iter())
            .all(|&g| g == 0.0));
    }

    #[test]
    fn wrong_shape_is_an_error() {
        let lin = Linear::<f32>::new(4, 3, false, &mut StdRng::seed_from_u64(0));
        let mut out = Array2::zeros((2, 3));
        let err = lin
            .forward(out.view_mut(), Array2::zeros((2, 5)).view())
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "linear forward: inp has shape [2, 5], expected [2, 4]"
        );
    }
}
