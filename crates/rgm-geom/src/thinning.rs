//! Dense clouds thinned to the density of the training clouds (1,024-point ModelNet40 shapes
//! in the unit sphere), for methods whose settings were chosen at that density.

use std::borrow::Cow;

use crate::PointCloud;

/// Points of a training cloud (1,024 per ModelNet40 shape; 717 after the partial crop): a cloud
/// with more points is denser than the methods were tuned for.
pub const DENSITY_POINTS: usize = 1024;

/// Voxel of the first thinning step of a cloud denser than [`DENSITY_POINTS`], in unit-sphere
/// units (the training clouds' median nearest-neighbour distance is 0.011–0.042).
pub const DENSITY_VOXEL: f64 = 0.035;

/// How a cloud denser than [`DENSITY_POINTS`] (in the unit-sphere frame) is thinned to
/// [`DENSITY_POINTS`] points; a cloud of no more points is used as it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Thinning {
    /// Averaged over voxels of [`DENSITY_VOXEL`] (merging duplicates and averaging their
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

/// `cloud` thinned `how` if it has more than [`DENSITY_POINTS`].
pub fn thinned(cloud: &PointCloud, how: Thinning) -> Cow<'_, PointCloud> {
    if cloud.len() <= DENSITY_POINTS {
        return Cow::Borrowed(cloud);
    }
    Cow::Owned(match how {
        Thinning::Voxels => {
            let averaged = cloud.voxel_downsampled(DENSITY_VOXEL);
            averaged.select(&averaged.farthest_point_indices(DENSITY_POINTS))
        }
        Thinning::Cells => {
            let seeds = cloud.select(&cloud.farthest_point_indices(DENSITY_POINTS));
            cloud.cell_means(&seeds.points)
        }
    })
}
