//! The AIS affinity with a symmetric learnable matrix: S = F_X · ((W + Wᵀ)/2) · F_Yᵀ.

use crate::error::{check_shape, MatchError, Result};
use ndarray::{Array2, ArrayView2, ArrayViewMut2, Ix2};
use rgm_nn::gemm::mat_mul;
use rgm_nn::init::Init;
use rgm_nn::param::{join_name, ParamView, ParamViewMut};
use rgm_nn::{Compute, Param, Parameters, Scalar};

/// Settings of the affinity layer.
#[derive(Clone, Debug, PartialEq)]
pub struct AffinityConfig {
    /// Q, the width of the graph features on both sides (spec: 512).
    pub width: usize,
}

impl Default for AffinityConfig {
    fn default() -> Self {
        Self { width: 512 }
    }
}

/// The affinity layer: S = F_X · A · F_Yᵀ with A = (W + Wᵀ)/2 (the reference's `affinity_b.A`).
#[derive(Clone, Debug)]
pub struct Affinity<T: Scalar> {
    pub w: Param<T, Ix2>, // (Q, Q)
}

/// What [`Affinity::backward`] needs from the forward pass.
#[derive(Clone, Debug)]
pub struct AffinityCache<T> {
    a: Array2<T>,    // (Q, Q) the symmetric part A = (W + Wᵀ)/2
    fx_a: Array2<T>, // (N, Q) F_X · A
}

impl<T: Scalar> AffinityCache<T> {
    /// Buffers for N source points of width Q.
    pub fn new(n: usize, q: usize) -> Self {
        Self {
            a: Array2::zeros((q, q)),
            fx_a: Array2::zeros((n, q)),
        }
    }
}

impl<T: Scalar> Affinity<T> {
    /// The reference initialisation: W = I + U(−1/√Q, 1/√Q), drawn in row-major order (I for
    /// [`rgm_nn::init::Unset`]).
    pub fn new(cfg: &AffinityConfig, init: &mut impl Init) -> Self {
        let bound = 1.0 / (cfg.width as f64).sqrt();
        let noise: Array2<f64> = init.uniform((cfg.width, cfg.width), bound); // (Q, Q)
        let w = Array2::from_shape_fn(noise.dim(), |(r, c)| {
            let eye = if r == c { 1.0 } else { 0.0 };
            T::from_f64(eye + noise[[r, c]])
        });
        Self { w: Param::new(w) }
    }

    /// A layer with the given square W (Q, Q).
    pub fn from_values(w: Array2<T>) -> Result<Self> {
        if !w.is_square() {
            return Err(MatchError::Shape {
                op: "Affinity::from_values",
                what: "w",
                got: w.shape().to_vec(),
                expected: vec![w.nrows(), w.nrows()],
            });
        }
        Ok(Self { w: Param::new(w) })
    }

    /// Q, the feature width.
    pub fn width(&self) -> usize {
        self.w.value.nrows()
    }

    /// S = F_X · A · F_Yᵀ with A = (W + Wᵀ)/2.
    pub fn forward(
        &self,
        mut s: ArrayViewMut2<'_, T>, // (N, M) out
        fx: ArrayView2<'_, T>,       // (N, Q)
        fy: ArrayView2<'_, T>,       // (M, Q)
        cache: &mut AffinityCache<T>,
        compute: Compute,
    ) -> Result<()> {
        const OP: &str = "affinity forward";
        let (n, m, q) = (fx.nrows(), fy.nrows(), self.width());
        check_shape(OP, "fx", fx.shape(), &[n, q])?;
        check_shape(OP, "fy", fy.shape(), &[m, q])?;
        check_shape(OP, "s", s.shape(), &[n, m])?;
        check_shape(OP, "cache", cache.fx_a.shape(), &[n, q])?;
        let (w, half) = (&self.w.value, T::from_f64(0.5));
        cache.a.assign(w);
        cache.a += &w.t();
        cache.a *= half;
        mat_mul(T::one(), &fx, &cache.a, T::zero(), &mut cache.fx_a, compute);
        mat_mul(T::one(), &cache.fx_a, &fy.t(), T::zero(), &mut s, compute);
        Ok(())
    }

    /// Differentiates S = F_X · A · F_Yᵀ: with G = dS · F_Y, dF_X += G · A, dF_Y += dSᵀ · (F_X · A),
    /// and dA = F_Xᵀ · G, so dW += (dA + dAᵀ)/2.
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &mut self,
        mut dfx: ArrayViewMut2<'_, T>, // (N, Q)
        mut dfy: ArrayViewMut2<'_, T>, // (M, Q)
        ds: ArrayView2<'_, T>,         // (N, M)
        fx: ArrayView2<'_, T>,         // (N, Q)
        fy: ArrayView2<'_, T>,         // (M, Q)
        cache: &AffinityCache<T>,
        compute: Compute,
    ) -> Result<()> {
        const OP: &str = "affinity backward";
        let (n, m, q) = (fx.nrows(), fy.nrows(), self.width());
        check_shape(OP, "fx", fx.shape(), &[n, q])?;
        check_shape(OP, "fy", fy.shape(), &[m, q])?;
        check_shape(OP, "ds", ds.shape(), &[n, m])?;
        check_shape(OP, "dfx", dfx.shape(), &[n, q])?;
        check_shape(OP, "dfy", dfy.shape(), &[m, q])?;
        check_shape(OP, "cache", cache.fx_a.shape(), &[n, q])?;
        // S = (F_X · A) · F_Yᵀ  →  dF_Y += dSᵀ · (F_X · A)
        mat_mul(T::one(), &ds.t(), &cache.fx_a, T::one(), &mut dfy, compute);
        // (Every product through `mat_mul`, the f32 one on AVX-512 where the processor has it.)
        let mut g = Array2::zeros((n, q)); // (N, Q) dS · F_Y
        mat_mul(T::one(), &ds, &fy, T::zero(), &mut g, compute);
        // S = F_X · (A · F_Yᵀ)  →  dF_X += (dS · F_Y) · A
        mat_mul(T::one(), &g, &cache.a, T::one(), &mut dfx, compute);
        // dA = F_Xᵀ · dS · F_Y, and A = (W + Wᵀ)/2  →  dW += (dA + dAᵀ)/2
        let half = T::from_f64(0.5);
        let mut da = Array2::zeros((q, q)); // (Q, Q)
        mat_mul(T::one(), &fx.t(), &g, T::zero(), &mut da, compute);
        self.w.grad.scaled_add(half, &da);
        self.w.grad.scaled_add(half, &da.t());
        Ok(())
    }
}

impl<T: Scalar> Parameters<T> for Affinity<T> {
    fn visit_params_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ParamView<'a, T>)) {
        f(&join_name(prefix, "A"), self.w.view());
    }

    fn visit_params(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ParamViewMut<'_, T>)) {
        f(&join_name(prefix, "A"), self.w.view_mut());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, ArrayD};
    use rand::{rngs::StdRng, SeedableRng};
    use rgm_nn::gradcheck::{assert_gradients, ix2, uniform};

    #[test]
    fn forward_by_hand() {
        // W = [[1 2],[0 1]] → A = [[1 1],[1 1]]; F_X·A = [3 3]; S = [3 3]·F_Yᵀ = [3 3 6]
        let aff = Affinity::from_values(array![[1.0, 2.0], [0.0, 1.0]]).unwrap();
        let (fx, fy) = (
            array![[1.0, 2.0]],
            array![[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]],
        );
        let mut s = Array2::zeros((1, 3));
        aff.forward(
            s.view_mut(),
            fx.view(),
            fy.view(),
            &mut AffinityCache::new(1, 2),
            Compute::default(),
        )
        .unwrap();
        assert_eq!(s, array![[3.0, 3.0, 6.0]]);
    }

    #[test]
    fn backward_matches_finite_differences() {
        // Rectangular N ≠ M ≠ Q and a non-symmetric W: dW must be the symmetric part's gradient.
        let (n, m, q) = (5, 4, 3);
        let inputs = [
            uniform(&[n, q], 1),
            uniform(&[m, q], 2),
            uniform(&[q, q], 3),
        ];
        let run = |i: &[ArrayD<f64>]| {
            let aff = Affinity::from_values(ix2(&i[2])).unwrap();
            let mut cache = AffinityCache::new(n, q);
            let mut s = Array2::zeros((n, m));
            aff.forward(
                s.view_mut(),
                ix2(&i[0]).view(),
                ix2(&i[1]).view(),
                &mut cache,
                Compute::default(),
            )
            .unwrap();
            (aff, cache, s)
        };
        assert_gradients(
            "affinity",
            1e-7,
            &inputs,
            &mut |i| run(i).2.into_dyn(),
            &mut |i, ds| {
                let (mut aff, cache, _) = run(i);
                let (mut dfx, mut dfy) = (Array2::zeros((n, q)), Array2::zeros((m, q)));
                aff.backward(
                    dfx.view_mut(),
                    dfy.view_mut(),
                    ix2(ds).view(),
                    ix2(&i[0]).view(),
                    ix2(&i[1]).view(),
                    &cache,
                    Compute::default(),
                )
                .unwrap();
                vec![dfx.into_dyn(), dfy.into_dyn(), aff.w.grad.into_dyn()]
            },
        );
    }

    #[test]
    fn init_is_identity_plus_uniform_and_seeded() {
        let cfg = AffinityConfig { width: 64 };
        let aff = Affinity::<f64>::new(&cfg, &mut StdRng::seed_from_u64(4));
        let bound = 1.0 / 8.0;
        let noise = &aff.w.value - &Array2::<f64>::eye(64);
        assert!(noise.iter().all(|v| v.abs() < bound));
        assert!(
            noise.iter().any(|v| v.abs() > 0.99 * bound),
            "draws reach the bound"
        );
        assert!(noise.mean().unwrap().abs() < 0.01);
        assert_eq!(
            aff.w.value,
            Affinity::<f64>::new(&cfg, &mut StdRng::seed_from_u64(4))
                .w
                .value
        );
        assert_eq!(AffinityConfig::default().width, 512);
    }

    #[test]
    fn parameter_names_match_the_reference_state_dict() {
        let mut aff = Affinity::<f32>::from_values(Array2::eye(2)).unwrap();
        let mut names = vec![];
        aff.visit_params("affinity_0", &mut |name, p| {
            names.push((name.to_string(), p.value.shape().to_vec()))
        });
        assert_eq!(names, [("affinity_0.A".to_string(), vec![2, 2])]);
    }

    #[test]
    fn width_mismatch_is_an_error() {
        let aff = Affinity::<f64>::from_values(Array2::eye(3)).unwrap();
        let mut s = Array2::zeros((2, 2));
        let err = aff.forward(
            s.view_mut(),
            Array2::zeros((2, 4)).view(),
            Array2::zeros((2, 3)).view(),
            &mut AffinityCache::new(2, 3),
            Compute::default(),
        );
        assert!(
            matches!(err, Err(MatchError::Shape { what: "fx", .. })),
            "{err:?}"
        );
    }
}
