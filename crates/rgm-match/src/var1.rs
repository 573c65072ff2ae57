//! The "Var1" ablation affinity: S_ij = exp(−(‖F_Xi − F_Yj‖₂ − 0.5)).

use crate::error::{check_shape, Result};
use ndarray::linalg::general_mat_mul;
use ndarray::{Array2, ArrayView2, ArrayViewMut2, Axis, Zip};
use rgm_nn::Scalar;

/// Settings of the Var1 affinity.
#[derive(Clone, Debug, PartialEq)]
pub struct Var1Config {
    /// The distance subtracted before the exponential (spec: 0.5).
    pub offset: f64,
}

impl Default for Var1Config {
    fn default() -> Self {
        Self { offset: 0.5 }
    }
}

/// What [`var1_backward`] needs from the forward pass.
#[derive(Clone, Debug)]
pub struct Var1Cache<T> {
    dist: Array2<T>, // (N, M) D
}

impl<T: Scalar> Var1Cache<T> {
    /// Buffers for an N×M affinity.
    pub fn new(n: usize, m: usize) -> Self {
        Self {
            dist: Array2::zeros((n, m)),
        }
    }
}

/// D_ij = ‖F_Xi − F_Yj‖₂ and S_ij = exp(offset − D_ij).
///
/// D² is formed as ‖x‖² + ‖y‖² − 2·x·y (one matrix product), clamped at 0: for nearly equal
/// features D carries an absolute error of about √ε·‖x‖.
///
/// Derivative: dD_ij = −S_ij·dS_ij, and ∂D_ij/∂F_Xi = (F_Xi − F_Yj)/D_ij = −∂D_ij/∂F_Yj, taken as 0
/// where D_ij = 0 (the subgradient of the norm at its minimum).
pub fn var1_forward<T: Scalar>(
    mut s: ArrayViewMut2<'_, T>, // (N, M) out
    fx: ArrayView2<'_, T>,       // (N, Q)
    fy: ArrayView2<'_, T>,       // (M, Q)
    cfg: &Var1Config,
    cache: &mut Var1Cache<T>,
) -> Result<()> {
    const OP: &str = "var1 forward";
    let (n, q) = fx.dim();
    let m = fy.nrows();
    check_shape(OP, "fy", fy.shape(), &[m, q])?;
    check_shape(OP, "s", s.shape(), &[n, m])?;
    check_shape(OP, "cache", cache.dist.shape(), &[n, m])?;
    let x_sq = fx.map_axis(Axis(1), |r| r.dot(&r)); // (N)
    let y_sq = fy.map_axis(Axis(1), |r| r.dot(&r)); // (M)
    let dist = &mut cache.dist; // (N, M) first −2·x·y, then D
    general_mat_mul(-T::from_f64(2.0), &fx, &fy.t(), T::zero(), dist);
    Zip::indexed(&mut *dist)
        .for_each(|(i, j), d| *d = (*d + x_sq[i] + y_sq[j]).max(T::zero()).sqrt());
    let offset = T::from_f64(cfg.offset);
    Zip::from(&mut s)
        .and(&*dist)
        .for_each(|s, &d| *s = (offset - d).exp());
    Ok(())
}

/// Adds the gradients of [`var1_forward`] into `dfx` and `dfy`.
pub fn var1_backward<T: Scalar>(
    mut dfx: ArrayViewMut2<'_, T>, // (N, Q)
    mut dfy: ArrayViewMut2<'_, T>, // (M, Q)
    ds: ArrayView2<'_, T>,         // (N, M)
    fx: ArrayView2<'_, T>,         // (N, Q)
    fy: ArrayView2<'_, T>,         // (M, Q)
    s: ArrayView2<'_, T>,          // (N, M) the forward output
    cache: &Var1Cache<T>,
) -> Result<()> {
    const OP: &str = "var1 backward";
    let (n, m) = cache.dist.dim();
    let q = fx.ncols();
    check_shape(OP, "fx", fx.shape(), &[n, q])?;
    check_shape(OP, "fy", fy.shape(), &[m, q])?;
    check_shape(OP, "ds", ds.shape(), &[n, m])?;
    check_shape(OP, "s", s.shape(), &[n, m])?;
    check_shape(OP, "dfx", dfx.shape(), &[n, q])?;
    check_shape(OP, "dfy", dfy.shape(), &[m, q])?;
    // S = exp(offset − D)  →  dD = −S·dS; D = ‖x − y‖  →  w = dD/D (0 where D = 0)
    let mut w = Array2::<T>::zeros((n, m)); // (N, M)
    Zip::from(&mut w)
        .and(&ds)
        .and(&s)
        .and(&cache.dist)
        .for_each(|w, &ds, &s, &d| {
            *w = if d > T::zero() {
                -(s * ds) / d
            } else {
                T::zero()
            };
        });
    // dF_Xi += Σ_j w_ij·(F_Xi − F_Yj) = (Σ_j w_ij)·F_Xi − (w·F_Y)_i
    let w_rows = w.sum_axis(Axis(1)); // (N)
    Zip::from(dfx.rows_mut())
        .and(fx.rows())
        .and(&w_rows)
        .for_each(|mut d, x, &c| d.scaled_add(c, &x));
    general_mat_mul(-T::one(), &w, &fy, T::one(), &mut dfx);
    // dF_Yj += Σ_i w_ij·(F_Yj − F_Xi) = (Σ_i w_ij)·F_Yj − (wᵀ·F_X)_j
    let w_cols = w.sum_axis(Axis(0)); // (M)
    Zip::from(dfy.rows_mut())
        .and(fy.rows())
        .and(&w_cols)
        .for_each(|mut d, y, &c| d.scaled_add(c, &y));
    general_mat_mul(-T::one(), &w.t(), &fx, T::one(), &mut dfy);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;
    use rgm_nn::gradcheck::{assert_gradients, ix2, uniform};

    fn run(fx: &Array2<f64>, fy: &Array2<f64>) -> (Array2<f64>, Var1Cache<f64>) {
        let (n, m) = (fx.nrows(), fy.nrows());
        let mut cache = Var1Cache::new(n, m);
        let mut s = Array2::zeros((n, m));
        var1_forward(
            s.view_mut(),
            fx.view(),
            fy.view(),
            &Var1Config::default(),
            &mut cache,
        )
        .unwrap();
        (s, cache)
    }

    #[test]
    fn forward_by_hand() {
        // D = [[0, 5], [5, 0]] (a 3-4-5 triangle) → S = [[e^0.5, e^-4.5], [e^-4.5, e^0.5]]
        let (fx, fy) = (
            array![[0.0, 0.0], [3.0, 4.0]],
            array![[0.0, 0.0], [3.0, 4.0]],
        );
        let (s, _) = run(&fx, &fy);
        let (near, far) = (0.5f64.exp(), (-4.5f64).exp());
        assert!(
            s.abs_diff_eq(&array![[near, far], [far, near]], 1e-12),
            "{s}"
        );
    }

    #[test]
    fn backward_matches_finite_differences() {
        let (n, m, q) = (5, 3, 4);
        let inputs = [uniform(&[n, q], 1), uniform(&[m, q], 2)];
        assert_gradients(
            "var1",
            1e-6,
            &inputs,
            &mut |i| run(&ix2(&i[0]), &ix2(&i[1])).0.into_dyn(),
            &mut |i, ds| {
                let (fx, fy) = (ix2(&i[0]), ix2(&i[1]));
                let (s, cache) = run(&fx, &fy);
                let (mut dfx, mut dfy) = (Array2::zeros((n, q)), Array2::zeros((m, q)));
                var1_backward(
                    dfx.view_mut(),
                    dfy.view_mut(),
                    ix2(ds).view(),
                    fx.view(),
                    fy.view(),
                    s.view(),
                    &cache,
                )
                .unwrap();
                vec![dfx.into_dyn(), dfy.into_dyn()]
            },
        );
    }

    #[test]
    fn backward_is_zero_and_finite_at_zero_distance() {
        // Identical features: D = 0 exactly, the norm's subgradient 0 is used instead of 0/0.
        let f = array![[0.3, -1.2, 2.0]];
        let (s, cache) = run(&f, &f);
        let (mut dfx, mut dfy) = (Array2::zeros((1, 3)), Array2::zeros((1, 3)));
        var1_backward(
            dfx.view_mut(),
            dfy.view_mut(),
            array![[1.0]].view(),
            f.view(),
            f.view(),
            s.view(),
            &cache,
        )
        .unwrap();
        assert!(
            dfx.iter().chain(dfy.iter()).all(|&g| g == 0.0),
            "{dfx} {dfy}"
        );
    }
}
