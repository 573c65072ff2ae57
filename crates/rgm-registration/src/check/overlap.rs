//! The measures a composite judges its candidates by, which need no ground truth: the two-way
//! overlap of a pair under a transform ([`overlap_score`]), how well the pose turned about one of
//! the source's axes fits as well ([`turned_share`], [`turned_poses`]), and whether two
//! transforms agree ([`agree`]).

use rgm_geom::{KnnIndex, PointCloud, RigidTransform};

use crate::check::symmetry::{principal_axes, turn_about};

use crate::fit::score;

/// Share of the points of each cloud that the transform brings within `distance` of the other
/// cloud, source → target plus target → source (0 to 2). Counting both ways rewards an overlap
/// that both clouds agree on, where a one-way fitness is fooled by a small cloud lying anywhere
/// on a large one.
pub fn overlap_score(
    source: (&PointCloud, &KnnIndex),
    target: (&PointCloud, &KnnIndex),
    transform: &RigidTransform,
    distance: f64,
) -> f64 {
    let there = score(&source.0.points, target.1, transform, distance, None);
    let back = score(
        &target.0.points,
        source.1,
        &transform.inverse(),
        distance,
        None,
    );
    there.fitness + back.fitness
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
