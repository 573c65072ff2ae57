//! Binary cross-entropy between C̃ and the 0/1 ground-truth matching (spec §3).

use crate::correspondences::Correspondences;
use crate::error::{check_shape, Result};
use ndarray::{ArrayView2, ArrayViewMut2};
use rgm_nn::Scalar;

/// PyTorch's BCELoss clamps each log at −100, so C̃ = 0 or 1 gives a finite loss.
const LOG_CLAMP: f64 = -100.0;
/// PyTorch's BCELoss backward divides by max(c·(1 − c), 1e-12).
const GRAD_EPS: f64 = 1e-12;

/// loss = −(1/N)·Σ_ij [y_ij·log c_ij + (1 − y_ij)·log(1 − c_ij)], each log clamped at −100.
///
/// Over a batch the caller averages these per-pair losses (equal to the reference's sum over the
/// batch divided by the total N when all N are equal).
///
/// Derivative (PyTorch's form): dc_ij = dloss·(c_ij − y_ij) / max(c_ij·(1 − c_ij), 1e-12) / N,
/// the exact derivative wherever c·(1 − c) ≥ 1e-12 (where no log is clamped either).
pub fn bce_forward<T: Scalar>(
    c: ArrayView2<'_, T>, // (N, M)
    gt: &Correspondences,
) -> Result<T> {
    check_shape("bce forward", "c", c.shape(), &[gt.n(), gt.m()])?;
    let clamp = T::from_f64(LOG_CLAMP);
    let log = |x: T| x.ln().max(clamp);
    // Every entry as a 0, then the ones corrected: log c − log(1 − c).
    let zeros_term = c.fold(T::zero(), |acc, &c| acc + log(T::one() - c));
    let ones_term = gt.pairs().iter().fold(T::zero(), |acc, &(i, j)| {
        let c = c[[i, j]];
        acc + log(c) - log(T::one() - c)
    });
    Ok(-(zeros_term + ones_term) / T::from_f64(gt.n() as f64))
}

/// Adds the gradient of [`bce_forward`] into `dc`.
pub fn bce_backward<T: Scalar>(
    mut dc: ArrayViewMut2<'_, T>, // (N, M)
    dloss: T,
    c: ArrayView2<'_, T>, // (N, M)
    gt: &Correspondences,
) -> Result<()> {
    const OP: &str = "bce backward";
    check_shape(OP, "c", c.shape(), &[gt.n(), gt.m()])?;
    check_shape(OP, "dc", dc.shape(), &[gt.n(), gt.m()])?;
    let scale = dloss / T::from_f64(gt.n() as f64);
    let eps = T::from_f64(GRAD_EPS);
    // Every entry as a 0: (c − 0)/max(c·(1 − c), eps)
    dc.zip_mut_with(&c, |dc, &c| {
        *dc += scale * c / (c * (T::one() - c)).max(eps)
    });
    // A one's entry: (c − 1) − (c − 0) = −1 in the numerator.
    for &(i, j) in gt.pairs() {
        let c = c[[i, j]];
        dc[[i, j]] -= scale / (c * (T::one() - c)).max(eps);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference;
    use ndarray::{array, Array2, ArrayD};
    use rgm_nn::gradcheck::{assert_gradients, ix2, uniform};

    #[test]
    fn forward_matches_reference() {
        let gt = Correspondences::new(3, 4, vec![(0, 2), (1, 0), (2, 1)]).unwrap();
        let loss = bce_forward(reference::sinkhorn_slack().view(), &gt).unwrap();
        assert!((loss - reference::BCE).abs() < 1e-14, "{loss}");
    }

    #[test]
    fn zero_and_one_entries_stay_finite() {
        // Right answers cost 0; a confident wrong 1 and a missed 0 cost the clamp, 100 each.
        let c = array![[1.0, 0.0], [0.0, 1.0]];
        let right = Correspondences::new(2, 2, vec![(0, 0), (1, 1)]).unwrap();
        let wrong = Correspondences::new(2, 2, vec![(0, 1), (1, 1)]).unwrap();
        assert_eq!(bce_forward(c.view(), &right).unwrap(), 0.0);
        assert_eq!(bce_forward(c.view(), &wrong).unwrap(), 200.0 / 2.0);
        let mut dc = Array2::zeros((2, 2));
        bce_backward(dc.view_mut(), 1.0, c.view(), &wrong).unwrap();
        // (c − y)/max(c(1 − c), 1e-12)/N: ±1e12/2 on the wrong entries, 0 on the right ones.
        assert_eq!(dc, array![[0.5e12, -0.5e12], [0.0, 0.0]]);
    }

    #[test]
    fn backward_matches_finite_differences() {
        let gt = Correspondences::new(4, 5, vec![(0, 3), (1, 1), (3, 0)]).unwrap();
        let inputs = [uniform(&[4, 5], 5) * 0.45 + 0.5]; // entries in (0.05, 0.95)
        let loss = |i: &[ArrayD<f64>]| {
            ArrayD::from_elem(vec![1], bce_forward(ix2(&i[0]).view(), &gt).unwrap())
        };
        assert_gradients("bce", 1e-7, &inputs, &mut |i| loss(i), &mut |i, dloss| {
            let mut dc = Array2::zeros((4, 5));
            bce_backward(dc.view_mut(), dloss[[0]], ix2(&i[0]).view(), &gt).unwrap();
            vec![dc.into_dyn()]
        });
    }
}
