//! Dense clouds thinned to the density a method was tuned at ([`Density`]), for methods whose
//! settings were chosen at that density ([`crate::compose::Thinned`] runs a composite on several
//! thinnings of a dense pair). The density is configuration: the caller that composes the methods
//! knows what they were tuned on.

use std::borrow::Cow;

use rgm_geom::{PointCloud, Strays};

/// The density methods were tuned at: a cloud of more than `points` points is denser, and is
/// thinned to `points`, averaged over voxels of `voxel` first ([`Thinning::Voxels`]; in the
/// clouds' units, unit-sphere units inside [`crate::compose::Normalised`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Density {
    pub points: usize,
    pub voxel: f64,
}

impl Density {
    /// Whether a pair of clouds of `source` and `target` points is denser.
    pub fn is_exceeded_by(&self, source: usize, target: usize) -> bool {
        source.max(target) > self.points
    }
}

/// How a cloud denser than a [`Density`] is thinned to its points; a cloud of no more points is
/// used as it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Thinning {
    /// Averaged over voxels of [`Density::voxel`] (merging duplicates and averaging their
    /// noise), then thinned by farthest-point sampling (`docs/training/README.md`, the
    /// robustness study of `default_study`).
    Voxels,
    /// Farthest-point seeds, each replaced by the mean of its Voronoi cell in the dense cloud
    /// ([`PointCloud::cell_means`]): as good as [`Thinning::Voxels`] alone on validation pairs,
    /// but wrong on different pairs (`docs/training/default-study/thinning-200-validation.md`).
    Cells,
}

impl Thinning {
    /// What a candidate's name carries after it when it ran on this thinning (`rgm/cells`);
    /// empty for the first, [`Thinning::Voxels`].
    pub fn suffix(self) -> &'static str {
        match self {
            Self::Voxels => "",
            Self::Cells => "/cells",
        }
    }
}

/// The strays both thinnings leave out at the scale of cubes of [`Density::voxel`]
/// ([`PointCloud::non_stray_indices`]): a dense scan's edges stay, and 20 % of its points
/// scattered through its box go, their second nearest other point at least 0.6 of a side away
/// in 95 % of them; the LiDAR pair's far rings, sparse beside its near ones, stay, their points'
/// second nearest within 0.19–0.26 of a side in 95 % of them, within 0.03–0.04 in half
/// (docs/baselines.md, "Data unlike the dev set").
pub const STRAYS: Strays = Strays {
    share: 0.2,
    alone: 0.25,
};

/// `cloud` thinned `how` to `density` without its stray points; `None` when it has no more
/// points (it is used as it is).
pub fn thinned(cloud: &PointCloud, how: Thinning, density: Density) -> Option<PointCloud> {
    if cloud.len() <= density.points {
        return None;
    }
    Some(match how {
        Thinning::Voxels => {
            let averaged = cloud.voxel_downsampled_without_strays(density.voxel, &STRAYS);
            averaged.select(&averaged.farthest_point_indices(density.points))
        }
        Thinning::Cells => {
            let kept = cloud.non_stray_indices(density.voxel, &STRAYS);
            let cloud = if kept.len() < cloud.len() {
                Cow::Owned(cloud.select(&kept))
            } else {
                Cow::Borrowed(cloud)
            };
            let seeds = cloud.select(&cloud.farthest_point_indices(density.points));
            cloud.cell_means(&seeds.points)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::square_with_strays;

    #[test]
    fn both_thinnings_leave_out_the_strays_scattered_through_a_dense_scan_s_box() {
        // A square of 200 × 200 points in z = 0 (about 25 in a cube of the thinning's voxel)
        // and 20 % as many strays through its box.
        let cloud = square_with_strays(1.4, 200, 8000, 3);
        let density = Density {
            points: 1024,
            voxel: 0.035,
        };
        let off_the_square = |c: &PointCloud| {
            c.points
                .iter()
                .filter(|p| p.z.abs() > 2.0 * density.voxel)
                .count()
        };
        // Without the strays left out, most of the farthest points are strays.
        let unfiltered = cloud.voxel_downsampled(density.voxel);
        assert!(off_the_square(&unfiltered.select(&unfiltered.farthest_point_indices(1024))) > 500);
        for how in [Thinning::Voxels, Thinning::Cells] {
            let thin = thinned(&cloud, how, density).expect("a dense cloud");
            assert!(thin.len() > 900, "{how:?}: {}", thin.len());
            assert_eq!(off_the_square(&thin), 0, "{how:?}");
        }
    }
}
