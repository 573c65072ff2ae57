//! The frame a registration runs in: the pair centred and scaled so that lengths set for
//! unit-sphere shapes (the refinement's and FGR's defaults, and what a method above this crate
//! was tuned on) fit
//! inputs of any size, and far outliers left out.

use nalgebra::{Point3, Vector3};

use crate::{PointCloud, RigidTransform};

/// How a pair is moved into the unit-sphere frame: `p' = (p − centre) / scale`,
/// each cloud about its own centre, both by one scale.
///
/// The benchmark's pairs (unit-sphere shapes, one moved by at most 0.5 per axis, jitter ≤ 0.05:
/// every point within 1.95 of the origin) are already in that frame and are left as they are:
/// the identity whenever both clouds lie within [`Normalisation::FRAME_RADIUS`] of the origin
/// and the larger cloud's extent (its largest distance from its centroid) is within
/// [`Normalisation::FRAME_EXTENT`]. Any other pair is centred (each cloud on its centroid) and
/// scaled by one common factor so that the farthest point of either cloud lies on the unit
/// sphere ([`Normalisation::centred`]): the same pair at half or twice the size reaches the
/// methods as the same clouds, centred.
///
/// All of it is measured on each cloud's [`near`] points: a far outlier (a stray return of a
/// scanner) neither decides the frame nor shrinks the pair to a dot in it, and the methods
/// leave it out. Lengths are taken at any scale ([`crate::length`]): a pair at 1e200 or
/// 1e-200 reaches the methods as it does at 1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Normalisation {
    pub source_centre: Vector3<f64>,
    pub target_centre: Vector3<f64>,
    pub scale: f64,
}

/// A point farther from its cloud's coordinate-wise median than this many times the median
/// distance from it is a far outlier ([`PointCloud::near_indices`]); no ModelNet40 shape has one
/// (`docs/geom.md`, "Far outliers").
pub const FAR_OUTLIER: f64 = 12.0;

/// The indices of `cloud`'s points that are not far outliers ([`FAR_OUTLIER`]), in order.
pub fn near(cloud: &PointCloud) -> Vec<usize> {
    cloud.near_indices(FAR_OUTLIER)
}

/// The largest distance of `cloud`'s points from `centre`; 0 for an empty cloud.
fn radius(cloud: &PointCloud, centre: &Point3<f64>) -> f64 {
    cloud
        .points
        .iter()
        .map(|p| crate::length(&(p - centre)))
        .fold(0.0, f64::max)
}

impl Normalisation {
    /// Pairs within this radius of the origin are in the unit-sphere frame…
    pub const FRAME_RADIUS: f64 = 2.0;
    /// …when the larger extent is in this range: a ModelNet40 shape reaches 1 from its centre,
    /// a 70 % crop of it 0.80–1.11 (10th and 90th percentiles over 400 training shapes; the
    /// larger of a test pair's two crops at most 1.38).
    pub const FRAME_EXTENT: std::ops::RangeInclusive<f64> = 0.7..=1.7;

    /// No change.
    pub fn identity() -> Self {
        Self {
            source_centre: Vector3::zeros(),
            target_centre: Vector3::zeros(),
            scale: 1.0,
        }
    }

    /// The normalisation of the pair (`source`, `target`), as described on the type.
    pub fn of_pair(source: &PointCloud, target: &PointCloud) -> Self {
        let (source, target) = rayon::join(
            || source.select(&near(source)),
            || target.select(&near(target)),
        );
        Self::of_near_pair(&source, &target)
    }

    /// [`Normalisation::of_pair`] of clouds whose far outliers ([`near`]) are left out already.
    pub(crate) fn of_near_pair(source: &PointCloud, target: &PointCloud) -> Self {
        // (centroid, extent from it, reach from the origin) of one cloud; the two side by side.
        let measure = |cloud: &PointCloud| {
            let centre = cloud.centroid();
            let extent = radius(cloud, &centre);
            (centre, extent, radius(cloud, &Point3::origin()))
        };
        let ((cx, source_extent, source_reach), (cy, target_extent, target_reach)) =
            rayon::join(|| measure(source), || measure(target));
        let extent = source_extent.max(target_extent);
        let reach = source_reach.max(target_reach);
        if reach <= Self::FRAME_RADIUS && Self::FRAME_EXTENT.contains(&extent) || extent == 0.0 {
            return Self::identity();
        }
        Self::centred_on(cx, cy, extent)
    }

    /// Each cloud centred on its centroid, both scaled by one factor so that the farthest point
    /// of either lies on the unit sphere (no scaling for clouds of coincident points).
    pub fn centred(source: &PointCloud, target: &PointCloud) -> Self {
        let (cx, cy) = (source.centroid(), target.centroid());
        let extent = radius(source, &cx).max(radius(target, &cy));
        Self::centred_on(cx, cy, extent)
    }

    /// Centred on `cx` and `cy`, scaled by `extent` (none when it is 0).
    fn centred_on(cx: Point3<f64>, cy: Point3<f64>, extent: f64) -> Self {
        Self {
            source_centre: cx.coords,
            target_centre: cy.coords,
            scale: if extent > 0.0 { extent } else { 1.0 },
        }
    }

    /// Whether the pair is used as it is.
    pub fn is_identity(&self) -> bool {
        *self == Self::identity()
    }

    fn apply(cloud: &PointCloud, centre: &Vector3<f64>, scale: f64) -> PointCloud {
        PointCloud::new(cloud.points.iter().map(|p| (p - centre) / scale).collect())
    }

    /// The source in the unit-sphere frame.
    pub fn source(&self, cloud: &PointCloud) -> PointCloud {
        Self::apply(cloud, &self.source_centre, self.scale)
    }

    /// The target in the unit-sphere frame.
    pub fn target(&self, cloud: &PointCloud) -> PointCloud {
        Self::apply(cloud, &self.target_centre, self.scale)
    }

    /// The transform in the caller's frame of `t` (y' = R x' + t' in the unit-sphere frame):
    /// y = s y' + c_Y = R x + (s t' + c_Y − R c_X).
    pub fn undo(&self, t: &RigidTransform) -> RigidTransform {
        let translation =
            self.scale * t.translation + self.target_centre - t.rotation * self.source_centre;
        RigidTransform::new(t.rotation, translation)
    }

    /// The transform in the unit-sphere frame of `t` (in the caller's frame): the inverse of
    /// [`Normalisation::undo`], t' = (t − c_Y + R c_X) / s.
    pub fn redo(&self, t: &RigidTransform) -> RigidTransform {
        let translation =
            (t.translation - self.target_centre + t.rotation * self.source_centre) / self.scale;
        RigidTransform::new(t.rotation, translation)
    }
}
