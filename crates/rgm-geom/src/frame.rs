//! The frame a registration runs in: the pair centred and scaled so that lengths set for
//! unit-sphere shapes (the refinement's and FGR's defaults, and what a method above this crate
//! was tuned on) fit
//! inputs of any size, and far outliers left out.

use nalgebra::{Point3, Vector3};

use crate::{PointCloud, RigidTransform};

/// How a pair is moved into the unit-sphere frame: `p' = (p − centre) / scale`,
/// each cloud about its own centre, both by one scale.
///
/// A pair already in that frame by its [`FrameRule`] is left as it is (the identity): both clouds
/// within [`FrameRule::within`] of the origin, the larger cloud's extent (its largest distance
/// from its centroid) in [`FrameRule::extent`]. Any other pair is centred (each cloud on its
/// centroid) and scaled by one common factor so that the farthest point of either cloud lies on
/// the unit sphere ([`Normalisation::centred`]): the same pair at any two sizes outside the
/// frame's window reaches the methods as the same clouds, centred.
///
/// All of it is measured on each cloud's [`FrameRule::near`] points: a far outlier (a stray
/// return of a scanner) neither decides the frame nor shrinks the pair to a dot in it, and the
/// methods leave it out. Lengths are taken at any scale ([`crate::length`]): a pair at 1e200 or
/// 1e-200 reaches the methods as it does at 1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Normalisation {
    pub source_centre: Vector3<f64>,
    pub target_centre: Vector3<f64>,
    pub scale: f64,
}

/// Which pairs a [`Normalisation`] leaves as they are and which points it leaves out:
/// configuration, its values chosen where methods are composed (the pairs the methods were
/// tuned on are left as they are, bit for bit).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameRule {
    /// A point farther from its cloud's coordinate-wise median than this many times the median
    /// distance from it is a far outlier ([`PointCloud::near_indices`]).
    pub far_outlier: f64,
    /// A pair whose clouds lie within this radius of the origin…
    pub within: f64,
    /// …and whose larger extent lies in this range (inclusive) is in the frame already.
    pub extent: (f64, f64),
}

impl FrameRule {
    /// The indices of `cloud`'s points that are not far outliers, in order.
    pub fn near(&self, cloud: &PointCloud) -> Vec<usize> {
        cloud.near_indices(self.far_outlier)
    }
}

/// The largest distance of `cloud`'s points from `centre`; 0 for an empty cloud.
fn radius(cloud: &PointCloud, centre: &Point3<f64>) -> f64 {
    cloud
        .points
        .iter()
        .map(|p| crate::length(&(p - centre)))
        .fold(0.0, f64::max)
}

/// A pair's points that are not far outliers, and the frame `rule` gives the pair by them: what
/// every user of the frame starts from.
pub struct NearPair {
    pub frame: Normalisation,
    /// Each cloud's near points ([`FrameRule::near`]): their indices in the cloud, and the
    /// points (as given, not yet moved). // (N',) and (N', 3)
    pub source: (Vec<usize>, PointCloud),
    pub target: (Vec<usize>, PointCloud), // (M',) and (M', 3)
}

impl NearPair {
    /// The near points of `source` and `target` (each cloud's side by side) and their frame.
    pub fn of(source: &PointCloud, target: &PointCloud, rule: &FrameRule) -> Self {
        let near_of = |cloud: &PointCloud| {
            let kept = rule.near(cloud);
            let selected = cloud.select(&kept);
            (kept, selected)
        };
        let (source, target) = rayon::join(|| near_of(source), || near_of(target));
        Self {
            frame: Normalisation::of_near_pair(&source.1, &target.1, rule),
            source,
            target,
        }
    }

    /// Both clouds' near points moved into the frame (side by side).
    pub fn moved(&self) -> (PointCloud, PointCloud) {
        rayon::join(
            || self.frame.source(&self.source.1),
            || self.frame.target(&self.target.1),
        )
    }
}

impl Normalisation {
    /// No change.
    pub fn identity() -> Self {
        Self {
            source_centre: Vector3::zeros(),
            target_centre: Vector3::zeros(),
            scale: 1.0,
        }
    }

    /// The normalisation of the pair (`source`, `target`) by `rule`, as described on the type.
    pub fn of_pair(source: &PointCloud, target: &PointCloud, rule: &FrameRule) -> Self {
        NearPair::of(source, target, rule).frame
    }

    /// [`Normalisation::of_pair`] of clouds whose far outliers ([`FrameRule::near`]) are left
    /// out already.
    fn of_near_pair(source: &PointCloud, target: &PointCloud, rule: &FrameRule) -> Self {
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
        let (least, most) = rule.extent;
        if reach <= rule.within && (least..=most).contains(&extent) || extent == 0.0 {
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
