//! The "Var1" ablation score (spec §2.7, `models/Net_noais.py` of the reference code): the
//! Sinkhorn's log-domain input is −(D²_ij − 0.5) with D²_ij = ‖F_Xi − F_Yj‖² the squared
//! Euclidean distance (so in the linear domain S_ij = exp(−(D²_ij − 0.5))); no affinity matrix,
//! no instance norm.

use crate::error::{check_shape, Result};
use ndarray::linalg::general_mat_mul;
use ndarray::{ArrayView2, ArrayViewMut2, Axis, Zip};
use rgm_nn::gemm::count_multiply_adds;
use rgm_nn::Scalar;

/// Settings of the Var1 score.
#[derive(Clone, Debug, PartialEq)]
pub struct Var1Config {
    /// The squared distance subtracted from (spec: 0.5).
    pub offset: f64,
}

impl Default for Var1Config {
    fn default() -> Self {
        Self { offset: 0.5 }
    }
}

/// `s_ij = offset − D²_ij`, the log-domain score, with D² = ‖x‖² + ‖y‖² − 2·x·y (one matrix
/// product).
///
/// Derivative: ∂s_ij/∂F_Xi = −2(F_Xi − F_Yj) = −∂s_ij/∂F_Yj.
pub fn var1_forward<T: Scalar>(
    mut s: ArrayViewMut2<'_, T>, // (N, M) out
    fx: ArrayView2<'_, T>,       // (N, Q)
    fy: ArrayView2<'_, T>,       // (M, Q)
    cfg: &Var1Config,
) -> Result<()> {
    const OP: &str = "var1 forward";
    let (n, q) = fx.dim();
    let m = fy.nrows();
    check_shape(OP, "fy", fy.shape(), &[m, q])?;
    check_shape(OP, "s", s.shape(), &[n, m])?;
    let x_sq = fx.map_axis(Axis(1), |r| r.dot(&r)); // (N)
    let y_sq = fy.map_axis(Axis(1), |r| r.dot(&r)); // (M)
                                                    // s = offset − ‖x‖² − ‖y‖² + 2·x·y
    general_mat_mul(T::from_f64(2.0), &fx, &fy.t(), T::zero(), &mut s);
    count_multiply_adds(n, q, m);
    let offset = T::from_f64(cfg.offset);
    Zip::indexed(&mut s).for_each(|(i, j), s| *s += offset - x_sq[i] - y_sq[j]);
    Ok(())
}

/// Adds the gradients of [`var1_forward`] into `dfx` and `dfy`.
pub fn var1_backward<T: Scalar>(
    mut dfx: ArrayViewMut2<'_, T>, // (N, Q)
    mut dfy: ArrayViewMut2<'_, T>, // (M, Q)
    ds: ArrayView2<'_, T>,         // (N, M)
    fx: ArrayView2<'_, T>,         // (N, Q)
    fy: ArrayView2<'_, T>,         // (M, Q)
) -> Result<()> {
    const OP: &str = "var1 backward";
    let (n, m) = ds.dim();
    let q = fx.ncols();
    check_shape(OP, "fx", fx.shape(), &[n, q])?;
    check_shape(OP, "fy", fy.shape(), &[m, q])?;
    check_shape(OP, "dfx", dfx.shape(), &[n, q])?;
    check_shape(OP, "dfy", dfy.shape(), &[m, q])?;
    // s_ij = offset − ‖F_Xi − F_Yj‖²  →  dF_Xi += Σ_j w_ij (F_Xi − F_Yj) with w = −2·ds
    let two = T::from_f64(2.0);
    let w_rows = ds.sum_axis(Axis(1)); // (N)
    Zip::from(dfx.rows_mut())
        .and(fx.rows())
        .and(&w_rows)
        .for_each(|mut d, x, &c| d.scaled_add(-two * c, &x));
    general_mat_mul(two, &ds, &fy, T::one(), &mut dfx);
    count_multiply_adds(n, m, q);
    // dF_Yj += Σ_i w_ij (F_Yj − F_Xi)
    let w_cols = ds.sum_axis(Axis(0)); // (M)
    Zip::from(dfy.rows_mut())
        .and(fy.rows())
        .and(&w_cols)
        .for_each(|mut d, y, &c| d.scaled_add(-two * c, &y));
    general_mat_mul(two, &ds.t(), &fx, T::one(), &mut dfy);
    count_multiply_adds(m, n, q);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array2};
    use rgm_nn::gradcheck::{assert_gradients, ix2, uniform};

    fn run(fx: &Array2<f64>, fy: &Array2<f64>) -> Array2<f64> {
        let mut s = Array2::zeros((fx.nrows(), fy.nrows()));
        var1_forward(s.view_mut(), fx.view(), fy.view(), &Var1Config::default()).unwrap();
        s
    }

    #[test]
    fn forward_by_hand() {
        // D = [[0, 5], [5, 0]] (a 3-4-5 triangle) → s = 0.5 − D² = [[0.5, −24.5], [−24.5, 0.5]]
        let (fx, fy) = (
            array![[0.0, 0.0], [3.0, 4.0]],
            array![[0.0, 0.0], [3.0, 4.0]],
        );
        let s = run(&fx, &fy);
        assert!(
            s.abs_diff_eq(&array![[0.5, -24.5], [-24.5, 0.5]], 1e-12),
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
            &mut |i| run(&ix2(&i[0]), &ix2(&i[1])).into_dyn(),
            &mut |i, ds| {
                let (fx, fy) = (ix2(&i[0]), ix2(&i[1]));
                let (mut dfx, mut dfy) = (Array2::zeros((n, q)), Array2::zeros((m, q)));
                var1_backward(
                    dfx.view_mut(),
                    dfy.view_mut(),
                    ix2(ds).view(),
                    fx.view(),
                    fy.view(),
                )
                .unwrap();
                vec![dfx.into_dyn(), dfy.into_dyn()]
            },
        );
    }
}
