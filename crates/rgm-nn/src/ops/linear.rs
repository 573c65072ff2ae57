//! Linear layer / 1×1 convolution on `(rows, C)` matrices, with or without bias.

use crate::error::check_shape;
use crate::gemm::{mat_mul, mat_mul_then};
use crate::init::{self, Init};
use crate::param::{join_name, ParamView, ParamViewMut};
use crate::scalar::Then;
use crate::{Compute, Param, Parameters, Result, Scalar};
use ndarray::{Array1, Array2, ArrayView2, ArrayViewMut2, Ix1, Ix2};

/// `out = inp · weightᵀ + bias`, PyTorch's `nn.Linear` (and `nn.Conv{1,2}d` with a 1×1 kernel,
/// whose `(C_out, C_in, 1, 1)` weight is this `(C_out, C_in)` one).
#[derive(Clone, Debug)]
pub struct Linear<T: Scalar> {
    pub weight: Param<T, Ix2>,       // (C_out, C_in)
    pub bias: Option<Param<T, Ix1>>, // (C_out)
}

impl<T: Scalar> Linear<T> {
    /// PyTorch's default initialisation: weight and bias uniform in `±1/√C_in`.
    pub fn new(c_in: usize, c_out: usize, bias: bool, init: &mut impl Init) -> Self {
        let bound = init::default_bound(c_in);
        let weight = Param::new(init.uniform((c_out, c_in), bound));
        let bias = bias.then(|| Param::new(init.uniform(c_out, bound)));
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
    pub fn forward(
        &self,
        out: ArrayViewMut2<'_, T>,
        inp: ArrayView2<'_, T>,
        compute: Compute,
    ) -> Result<()> {
        self.forward_then(out, inp, false, compute)
    }

    /// `out = ReLU(inp · weightᵀ + bias)`, the ReLU in the product's write-back: the value of
    /// [`Linear::forward`] and [`crate::relu_in_place`], bit for bit, one pass over `out`
    /// fewer. Shapes as [`Linear::forward`].
    pub fn forward_relu(
        &self,
        out: ArrayViewMut2<'_, T>,
        inp: ArrayView2<'_, T>,
        compute: Compute,
    ) -> Result<()> {
        self.forward_then(out, inp, true, compute)
    }

    fn forward_then(
        &self,
        mut out: ArrayViewMut2<'_, T>,
        inp: ArrayView2<'_, T>,
        relu: bool,
        compute: Compute,
    ) -> Result<()> {
        let rows = inp.nrows();
        check_shape("linear forward", "inp", inp.shape(), &[rows, self.c_in()])?;
        check_shape("linear forward", "out", out.shape(), &[rows, self.c_out()])?;
        let bias = self.bias.as_ref().map(|b| b.value.view());
        let then = Then::Layer { bias, relu };
        mat_mul_then(&inp, &self.weight.value.t(), then, &mut out, compute);
        Ok(())
    }

    /// Differentiates `out = inp · weightᵀ + bias`:
    /// `dinp += dout · weight`, `dweight += doutᵀ · inp`, `dbias += Σ_rows dout`.
    /// `dinp`: (R, C_in), `dout`: (R, C_out), `inp`: (R, C_in) as given to forward.
    pub fn backward(
        &mut self,
        dinp: ArrayViewMut2<'_, T>,
        dout: ArrayView2<'_, T>,
        inp: ArrayView2<'_, T>,
        compute: Compute,
    ) -> Result<()> {
        self.backward_then(dinp, dout, inp, false, compute)
    }

    /// Differentiates `out = ReLU(pre) · weightᵀ + bias` given `inp = ReLU(pre)`, this layer's
    /// input: `dpre = (dout · weight) ⊙ [inp > 0]` (zero gradient at 0, as PyTorch), ReLU's
    /// backward in the product's write-back; the weight and bias gradients added as
    /// [`Linear::backward`]. `dpre` is written, not added to (what it held is ignored): the
    /// value of [`Linear::backward`] into a zeroed scratch, then [`crate::relu_backward`] into
    /// a zeroed `dpre`, without the scratch and the passes. Shapes as [`Linear::backward`].
    pub fn backward_through_relu(
        &mut self,
        dpre: ArrayViewMut2<'_, T>,
        dout: ArrayView2<'_, T>,
        inp: ArrayView2<'_, T>,
        compute: Compute,
    ) -> Result<()> {
        self.backward_then(dpre, dout, inp, true, compute)
    }

    fn backward_then(
        &mut self,
        mut dinp: ArrayViewMut2<'_, T>,
        dout: ArrayView2<'_, T>,
        inp: ArrayView2<'_, T>,
        through_relu: bool,
        compute: Compute,
    ) -> Result<()> {
        let rows = self.check_backward(dout, inp)?;
        check_shape(
            "linear backward",
            "dinp",
            dinp.shape(),
            &[rows, self.c_in()],
        )?;
        let weight = &self.weight.value;
        if through_relu {
            mat_mul_then(&dout, weight, Then::ReluGrad(inp), &mut dinp, compute);
        } else {
            mat_mul(T::one(), &dout, weight, T::one(), &mut dinp, compute);
        }
        self.backward_params(dout, inp, compute)
    }

    /// Checks a backward's `inp` (R, C_in) and `dout` (R, C_out); returns R.
    fn check_backward(&self, dout: ArrayView2<'_, T>, inp: ArrayView2<'_, T>) -> Result<usize> {
        let rows = inp.nrows();
        check_shape("linear backward", "inp", inp.shape(), &[rows, self.c_in()])?;
        check_shape(
            "linear backward",
            "dout",
            dout.shape(),
            &[rows, self.c_out()],
        )?;
        Ok(rows)
    }

    /// Adds the weight and bias gradients of [`Linear::backward`] only, for a layer whose
    /// input needs no gradient (the network's input). Shapes as [`Linear::backward`].
    pub fn backward_params(
        &mut self,
        dout: ArrayView2<'_, T>,
        inp: ArrayView2<'_, T>,
        compute: Compute,
    ) -> Result<()> {
        self.check_backward(dout, inp)?;
        mat_mul(
            T::one(),
            &dout.t(),
            &inp,
            T::one(),
            &mut self.weight.grad,
            compute,
        );
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
        lin.forward(
            out.view_mut(),
            array![[1.0, 2.0]].view(),
            Compute::default(),
        )
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
                    layer(i)
                        .forward(out.view_mut(), ix2(&i[0]).view(), Compute::default())
                        .unwrap();
                    out.into_dyn()
                },
                &mut |i, dout| {
                    let mut lin = layer(i);
                    let mut dinp = Array2::zeros((9, 5));
                    lin.backward(
                        dinp.view_mut(),
                        ix2(dout).view(),
                        ix2(&i[0]).view(),
                        Compute::default(),
                    )
                    .unwrap();
                    let mut grads = vec![dinp.into_dyn(), lin.weight.grad.into_dyn()];
                    grads.extend(lin.bias.map(|b| b.grad.into_dyn()));
                    grads
                },
            );
        }
    }

    #[test]
    fn backward_through_relu_matches_finite_differences() {
        // out = ReLU(pre) · Wᵀ + b; no entry of pre within the step of the kink at 0.
        let pre = uniform(&[9, 5], 4).mapv(|v: f64| if v.abs() < 0.01 { 0.5 } else { v });
        let inputs = vec![pre, uniform(&[3, 5], 5), uniform(&[3], 6)];
        let layer = |i: &[ArrayD<f64>]| {
            let b = i[2].clone().into_dimensionality::<Ix1>().unwrap();
            Linear::from_values(ix2(&i[1]), Some(b)).unwrap()
        };
        let relu = |i: &[ArrayD<f64>]| ix2(&i[0]).mapv(|x| x.max(0.0));
        assert_gradients(
            "linear through relu",
            1e-6,
            &inputs,
            &mut |i| {
                let mut out = Array2::zeros((9, 3));
                layer(i)
                    .forward(out.view_mut(), relu(i).view(), Compute::default())
                    .unwrap();
                out.into_dyn()
            },
            &mut |i, dout| {
                let mut lin = layer(i);
                let mut dpre = Array2::zeros((9, 5));
                lin.backward_through_relu(
                    dpre.view_mut(),
                    ix2(dout).view(),
                    relu(i).view(),
                    Compute::default(),
                )
                .unwrap();
                vec![
                    dpre.into_dyn(),
                    lin.weight.grad.into_dyn(),
                    lin.bias.unwrap().grad.into_dyn(),
                ]
            },
        );
    }

    #[test]
    fn the_fused_relus_give_the_unfused_bits() {
        // f32, sizes past the AVX-512 product's panels (K = 300 > 256); a third of the inputs
        // and of the hidden units at or below zero.
        let mut rng = StdRng::seed_from_u64(7);
        let lin = Linear::<f32>::new(300, 40, true, &mut rng);
        let inp = Array2::from_shape_fn((37, 300), |(i, j)| ((i * 7 + j * 3) % 11) as f32 - 3.0);
        let mut fused = Array2::from_elem((37, 40), f32::NAN);
        lin.forward_relu(fused.view_mut(), inp.view(), Compute::default())
            .unwrap();
        let mut unfused = Array2::zeros((37, 40));
        lin.forward(unfused.view_mut(), inp.view(), Compute::default())
            .unwrap();
        crate::relu_in_place(unfused.view_mut());
        assert_eq!(fused.mapv(f32::to_bits), unfused.mapv(f32::to_bits));
        assert!(unfused.iter().any(|&x| x == 0.0) && unfused.iter().any(|&x| x > 0.0));
        // Backward through the ReLU of `inp`, which has zeros and negatives (as no ReLU output
        // has, but the mask reads only the sign).
        let dout = Array2::from_shape_fn((37, 40), |(i, j)| ((i * 5 + j) % 9) as f32 * 0.25 - 1.0);
        let mut a = lin.clone();
        let mut dpre = Array2::from_elem((37, 300), f32::NAN); // written, not added to
        a.backward_through_relu(dpre.view_mut(), dout.view(), inp.view(), Compute::default())
            .unwrap();
        let mut b = lin.clone();
        let mut dinp = Array2::zeros((37, 300));
        b.backward(dinp.view_mut(), dout.view(), inp.view(), Compute::default())
            .unwrap();
        let mut want = Array2::zeros((37, 300));
        crate::relu_backward(want.view_mut(), dinp.view(), inp.view()).unwrap();
        assert_eq!(dpre.mapv(f32::to_bits), want.mapv(f32::to_bits));
        assert_eq!(a.weight.grad, b.weight.grad);
        assert_eq!(a.bias.unwrap().grad, b.bias.as_ref().unwrap().grad);
        let mut c = lin.clone();
        c.backward_params(dout.view(), inp.view(), Compute::default())
            .unwrap();
        assert_eq!(c.weight.grad, b.weight.grad);
        assert_eq!(c.bias.unwrap().grad, b.bias.unwrap().grad);
        assert!(c.weight.grad.iter().any(|&g| g != 0.0));
    }

    #[test]
    fn backward_accumulates_and_zero_grad_clears() {
        let mut lin = Linear::<f64>::new(2, 2, true, &mut StdRng::seed_from_u64(0));
        assert_eq!(lin.num_params(), 6, "2×2 weight and 2 biases");
        let (inp, dout) = (array![[1.0, 2.0]], array![[1.0, -1.0]]);
        let mut dinp = Array2::zeros((1, 2));
        lin.backward(dinp.view_mut(), dout.view(), inp.view(), Compute::default())
            .unwrap();
        let once = (dinp.clone(), lin.weight.grad.clone());
        lin.backward(dinp.view_mut(), dout.view(), inp.view(), Compute::default())
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
            .forward(
                out.view_mut(),
                Array2::zeros((2, 5)).view(),
                Compute::default(),
            )
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "linear forward: inp has shape [2, 5], expected [2, 4]"
        );
    }
}
