//! Dense clouds thinned to the density a method was tuned at ([`Density`]), for methods whose
//! settings were chosen at that density ([`crate::compose::Thinned`] runs a composite on several
//! thinnings of a dense pair). The density is configuration: the caller that composes the methods
//! knows what they were tuned on.

use rgm_geom::PointCloud;

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

/// `cloud` thinned `how` to `density`; `None` when it has no more points (it is used as it is).
pub fn thinned(cloud: &PointCloud, how: Thinning, density: Density) -> Option<PointCloud> {
    if cloud.len() <= density.points {
        return None;
    }
    Some(match how {
        Thinning::Voxels => {
            let averaged = cloud.voxel_downsampled(density.voxel);
            averaged.select(&averaged.farthest_point_indices(density.points))
        }
        Thinning::Cells => {
            let seeds = cloud.select(&cloud.farthest_point_indices(density.points));
            cloud.cell_means(&seeds.points)
        }
    })
}
