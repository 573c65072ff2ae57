//! Registration metrics of spec §5, per pair and averaged over pairs.
//!
//! - MAE(R), MAE(t) — anisotropic, from DCP: Euler angles of `R_pred` and `R_gt` as scipy's
//!   `as_euler('xyz')` (extrinsic x-y-z, degrees), mean absolute difference over the 3 angles,
//!   with **no wrap-around** (DCP's and RGM's code subtract the angle arrays directly, so 179° vs
//!   −179° counts as 358°); mean absolute difference of t over the 3 axes.
//! - MIE(R), MIE(t) — isotropic, from RPM-Net: the angle of `R_gtᵀ R_pred` in degrees, and the
//!   norm of the translation of `T_gt⁻¹ ∘ T_pred`, which is `‖R_gtᵀ (t_pred − t_gt)‖ = ‖t_pred − t_gt‖`.
//! - CCD — clipped Chamfer distance as RGM's code computes it (not the paper's formula): the
//!   source is moved by the *predicted* transform; each point's Euclidean distance to the nearest
//!   point of the other cloud is clipped at 0.1; the mean source→target plus the mean
//!   target→source.
//! - Chamfer — the same without clipping and with squared distances (RPM-Net's form, but against
//!   the given target cloud rather than a clean copy of it).
//! - Recall — a pair counts when MAE(R) < 1° and MAE(t) < 0.1.

use nalgebra::Point3;

use crate::euler::euler_xyz_extrinsic;
use crate::knn::KnnIndex;
use crate::{GeomError, PointCloud, Result, RigidTransform};

/// Distances above this count as this in the CCD (spec §5).
pub const CCD_CLIP: f64 = 0.1;
/// A pair is a success for recall when MAE(R) is below this many degrees…
pub const RECALL_MAE_R_DEG: f64 = 1.0;
/// …and MAE(t) below this.
pub const RECALL_MAE_T: f64 = 0.1;

/// The metrics of one registered pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairMetrics {
    /// Mean absolute Euler-angle error, degrees (anisotropic).
    pub mae_r_deg: f64,
    /// Mean absolute translation error over the 3 axes (anisotropic).
    pub mae_t: f64,
    /// Angle of `R_gtᵀ R_pred`, degrees (isotropic).
    pub mie_r_deg: f64,
    /// `‖t of T_gt⁻¹ ∘ T_pred‖` (isotropic).
    pub mie_t: f64,
    /// Clipped Chamfer distance (RGM's code).
    pub ccd: f64,
    /// Chamfer distance: mean squared nearest distances, both ways, unclipped.
    pub chamfer: f64,
    /// MAE(R) < 1° and MAE(t) < 0.1.
    pub recall: bool,
}

impl PairMetrics {
    /// Metrics of the predicted `t_target_source` against the ground truth, for the source
    /// cloud (before any transform) and the target cloud. Errors when a cloud is empty.
    pub fn compute(
        pred: &RigidTransform,
        gt: &RigidTransform,
        source: &PointCloud,
        target: &PointCloud,
    ) -> Result<Self> {
        if source.is_empty() || target.is_empty() {
            let got = source.len().min(target.len());
            return Err(GeomError::TooFewPoints {
                op: "PairMetrics::compute",
                needed: 1,
                got,
            });
        }
        let e_pred = euler_xyz_extrinsic(&pred.rotation);
        let e_gt = euler_xyz_extrinsic(&gt.rotation);
        let mae_r_deg = (0..3)
            .map(|i| (e_pred[i] - e_gt[i]).to_degrees().abs())
            .sum::<f64>()
            / 3.0;
        let mae_t = (pred.translation - gt.translation).abs().sum() / 3.0;
        let residual = gt.inverse().compose(pred);
        let mie_r_deg = residual.rotation_angle_deg();
        let mie_t = residual.translation.norm();

        let moved = source.transformed(pred);
        let (ccd_st, chamfer_st) = nearest_distance_means(&moved.points, &target.points);
        let (ccd_ts, chamfer_ts) = nearest_distance_means(&target.points, &moved.points);
        Ok(Self {
            mae_r_deg,
            mae_t,
            mie_r_deg,
            mie_t,
            ccd: ccd_st + ccd_ts,
            chamfer: chamfer_st + chamfer_ts,
            recall: mae_r_deg < RECALL_MAE_R_DEG && mae_t < RECALL_MAE_T,
        })
    }
}

/// For each point of `from`, its Euclidean distance d to the nearest point of `to`:
/// (mean of min(d, 0.1), mean of d²). Both clouds non-empty.
fn nearest_distance_means(from: &[Point3<f64>], to: &[Point3<f64>]) -> (f64, f64) {
    let index = KnnIndex::new(to);
    let (mut clipped, mut squared) = (0.0, 0.0);
    for p in from {
        let d = index.nearest(p).1;
        clipped += d.min(CCD_CLIP);
        squared += d * d;
    }
    let n = from.len() as f64;
    (clipped / n, squared / n)
}

/// Metrics averaged over a test set; recall as the fraction of pairs that succeed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MetricsSummary {
    /// Number of pairs averaged.
    pub pairs: usize,
    pub mae_r_deg: f64,
    pub mae_t: f64,
    pub mie_r_deg: f64,
    pub mie_t: f64,
    pub ccd: f64,
    pub chamfer: f64,
    /// Fraction of pairs with `recall` true, in [0, 1].
    pub recall: f64,
}

impl MetricsSummary {
    /// The means over `pairs`; an error when there is none.
    pub fn from_pairs(pairs: &[PairMetrics]) -> Result<Self> {
        if pairs.is_empty() {
            return Err(GeomError::TooFewPoints {
                op: "MetricsSummary::from_pairs (pairs)",
                needed: 1,
                got: 0,
            });
        }
        let n = pairs.len() as f64;
        let mean = |f: fn(&PairMetrics) -> f64| pairs.iter().map(f).sum::<f64>() / n;
        Ok(Self {
            pairs: pairs.len(),
            mae_r_deg: mean(|p| p.mae_r_deg),
            mae_t: mean(|p| p.mae_t),
            mie_r_deg: mean(|p| p.mie_r_deg),
            mie_t: mean(|p| p.mie_t),
            ccd: mean(|p| p.ccd),
            chamfer: mean(|p| p.chamfer),
            recall: mean(|p| if p.recall { 1.0 } else { 0.0 }),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::euler::{rotation_xyz_extrinsic, rz};
    use nalgebra::Vector3;

    fn close(a: f64, b: f64) {
        assert!((a - b).abs() < 1e-9, "{a} vs {b}");
    }

    fn deg(a: f64, b: f64, c: f64) -> nalgebra::Matrix3<f64> {
        rotation_xyz_extrinsic(a.to_radians(), b.to_radians(), c.to_radians())
    }

    fn one_point() -> PointCloud {
        PointCloud::new(vec![Point3::origin()])
    }

    #[test]
    fn anisotropic_errors_by_hand() {
        // Euler (10, 20, 30)° vs (12, 17, 30)°: |−2| + |3| + 0 = 5 → 5/3°.
        // t (0.1, 0.2, 0.3) vs (0, 0.5, 0.3): 0.1 + 0.3 + 0 = 0.4 → 0.4/3.
        let pred = RigidTransform::new(deg(10.0, 20.0, 30.0), Vector3::new(0.1, 0.2, 0.3));
        let gt = RigidTransform::new(deg(12.0, 17.0, 30.0), Vector3::new(0.0, 0.5, 0.3));
        let m = PairMetrics::compute(&pred, &gt, &one_point(), &one_point()).unwrap();
        close(m.mae_r_deg, 5.0 / 3.0);
        close(m.mae_t, 0.4 / 3.0);
        assert!(!m.recall, "MAE(R) 1.67° is above 1°");
    }

    #[test]
    fn euler_difference_does_not_wrap_around() {
        // γ = 179° vs −179°: 358° apart as DCP/RGM compute it (2° on the circle) → 358/3.
        let pred = RigidTransform::new(deg(0.0, 0.0, 179.0), Vector3::zeros());
        let gt = RigidTransform::new(deg(0.0, 0.0, -179.0), Vector3::zeros());
        let m = PairMetrics::compute(&pred, &gt, &one_point(), &one_point()).unwrap();
        close(m.mae_r_deg, 358.0 / 3.0);
        close(m.mie_r_deg, 2.0);
    }

    #[test]
    fn isotropic_errors_by_hand() {
        // R_gt = Rz(10°), R_pred = Rz(30°): R_gtᵀ R_pred = Rz(20°) → 20°.
        // t_gt = (1, 0, 0), t_pred = (1, 0, 2): T_gt⁻¹∘T_pred has t = R_gtᵀ (0, 0, 2) → norm 2.
        let gt = RigidTransform::new(rz(10f64.to_radians()), Vector3::new(1.0, 0.0, 0.0));
        let pred = RigidTransform::new(rz(30f64.to_radians()), Vector3::new(1.0, 0.0, 2.0));
        let m = PairMetrics::compute(&pred, &gt, &one_point(), &one_point()).unwrap();
        close(m.mie_r_deg, 20.0);
        close(m.mie_t, 2.0);
        // Anisotropic: γ differs by 20° → 20/3; t differs by 2 on z → 2/3.
        close(m.mae_r_deg, 20.0 / 3.0);
        close(m.mae_t, 2.0 / 3.0);
    }

    #[test]
    fn ccd_and_chamfer_by_hand() {
        // Source {(0,0,0), (1,0,0)} moved by the identity, target {(0,0,0.05), (1,0.5,0)}.
        // source→target nearest: 0.05 and 0.5; target→source: 0.05 and 0.5.
        // CCD: clipped (0.05 + 0.1)/2 twice = 0.15. Chamfer: (0.0025 + 0.25)/2 twice = 0.2525.
        let source = PointCloud::new(vec![Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 0.0)]);
        let target = PointCloud::new(vec![
            Point3::new(0.0, 0.0, 0.05),
            Point3::new(1.0, 0.5, 0.0),
        ]);
        let id = RigidTransform::identity();
        let m = PairMetrics::compute(&id, &id, &source, &target).unwrap();
        close(m.ccd, 0.15);
        close(m.chamfer, 0.2525);
        assert!(m.recall);
        // The prediction moves the source: shifting it by (0, 0, 0.05) makes point 0 exact and
        // point 1 at √(0.25 + 0.0025) from (1, 0.5, 0): CCD (0 + 0.1)/2 twice = 0.1.
        let shift =
            RigidTransform::new(nalgebra::Matrix3::identity(), Vector3::new(0.0, 0.0, 0.05));
        let m = PairMetrics::compute(&shift, &id, &source, &target).unwrap();
        close(m.ccd, 0.1);
        close(m.chamfer, 2.0 * (0.0 + 0.2525) / 2.0);
    }

    #[test]
    fn recall_thresholds_and_summary() {
        let id = RigidTransform::identity();
        let small = RigidTransform::new(deg(0.0, 0.0, 2.9), Vector3::new(0.0, 0.0, 0.29));
        let big = RigidTransform::new(deg(0.0, 0.0, 3.1), Vector3::zeros());
        let a = PairMetrics::compute(&small, &id, &one_point(), &one_point()).unwrap();
        let b = PairMetrics::compute(&big, &id, &one_point(), &one_point()).unwrap();
        assert!(a.recall, "2.9/3° and 0.29/3 are below 1° and 0.1");
        assert!(!b.recall, "3.1/3° is above 1°");
        let s = MetricsSummary::from_pairs(&[a, b]).unwrap();
        assert_eq!(s.pairs, 2);
        close(s.recall, 0.5);
        close(s.mae_r_deg, (2.9 + 3.1) / 6.0);
        close(s.mie_t, 0.29 / 2.0);
        assert!(MetricsSummary::from_pairs(&[]).is_err());
    }

    #[test]
    fn empty_clouds_are_errors() {
        let id = RigidTransform::identity();
        let err = PairMetrics::compute(&id, &id, &PointCloud::default(), &one_point());
        assert!(matches!(err, Err(GeomError::TooFewPoints { got: 0, .. })));
    }
}
