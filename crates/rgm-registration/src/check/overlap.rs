//! The measures a composite judges its candidates by, which need no ground truth: the two-way
//! overlap of a pair under a transform ([`overlap_score`]), how well the pose turned about one of
//! the source's axes fits as well ([`turned_share`], [`turned_poses`]), and whether two
//! transforms agree ([`agree`]).

use rgm_geom::cloud::evenly;
use rgm_geom::{KnnIndex, Point3, PointCloud, RigidTransform};

use crate::check::symmetry::{principal_axes, turn_about};

use crate::fit::share_within;

/// At most this many points of each cloud are counted by [`overlap_score`], at an even stride:
/// a share measured on 10,000 points is within ±0.01 of the whole cloud's (two standard errors),
/// far finer than the gaps a composite's judgement rests on, and a dense scan's 40,000 or a
/// room's 300,000 points then cost no more than 10,000 (`docs/baselines.md`, issue 57). Clouds
/// of fewer points (ModelNet40's 1,024) are counted whole.
pub const OVERLAP_SAMPLE: usize = 10_000;

/// Share of the points of each cloud that the transform brings within `distance` of the other
/// cloud, source → target plus target → source (0 to 2). Counting both ways rewards an overlap
/// that both clouds agree on, where a one-way fitness is fooled by a small cloud lying anywhere
/// on a large one. Each share is counted on at most [`OVERLAP_SAMPLE`] of a cloud's points,
/// against the other cloud whole.
pub fn overlap_score(
    source: (&PointCloud, &KnnIndex),
    target: (&PointCloud, &KnnIndex),
    transform: &RigidTransform,
    distance: f64,
) -> f64 {
    let share = |points: &[Point3<f64>], onto: &KnnIndex, moved: &RigidTransform| {
        if points.len() <= OVERLAP_SAMPLE {
            return share_within(points, onto, moved, distance);
        }
        let sample: Vec<Point3<f64>> = evenly(points, OVERLAP_SAMPLE).copied().collect(); // (S,)
        share_within(&sample, onto, moved, distance)
    };
    share(&source.0.points, target.1, transform)
        + share(&target.0.points, source.1, &transform.inverse())
}

/// How little `transform`'s overlap tells the shape's pose: the best [`overlap_score`] of its
/// [`turned_poses`], as a share of `transform`'s own. Near 1 or above, a pose turned about one of
/// the source's axes fits as well, as for a symmetric shape. Overlaps counted within `distance`.
pub fn turned_share(
    source: (&PointCloud, &KnnIndex),
    target: (&PointCloud, &KnnIndex),
    transform: &RigidTransform,
    distance: f64,
) -> f64 {
    let score = overlap_score(source, target, transform, distance);
    if source.0.len() < 3 || score <= 0.0 {
        return f64::INFINITY;
    }
    let best = turned_poses(source.0, transform)
        .iter()
        .map(|turned| overlap_score(source, target, turned, distance))
        .fold(0.0, f64::max);
    best / score
}

/// `transform` with the source first turned by a quarter, a half or three quarters about each
/// of its principal axes (through its centroid): the nine poses a symmetric shape fits as well.
pub fn turned_poses(source: &PointCloud, transform: &RigidTransform) -> Vec<RigidTransform> {
    let (centre, _, axes) = principal_axes(source);
    let mut poses = Vec::with_capacity(9);
    for axis in axes.column_iter() {
        for quarters in 1..4 {
            let about = turn_about(
                &centre,
                &axis.into_owned(),
                quarters as f64 * std::f64::consts::FRAC_PI_2,
            );
            poses.push(transform.compose(&about));
        }
    }
    poses
}

/// Two transforms `within` (degrees, distance) of each other: rotations less than its degrees
/// apart, and moving the frame's origin to points less than its distance apart.
pub fn agree(a: &RigidTransform, b: &RigidTransform, within: (f64, f64)) -> bool {
    let (degrees, distance) = within;
    a.inverse().compose(b).rotation_angle_deg() < degrees
        && (a.translation - b.translation).norm() < distance
}
