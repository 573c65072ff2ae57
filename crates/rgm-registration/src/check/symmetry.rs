//! Whether a cloud fits itself turned: a shape with a rotational symmetry (a box, a cube, a
//! cylinder, a sphere) has several poses on any other cloud that fit exactly as well, so no
//! registration of it (or onto it) tells one pose, however well it overlaps.
//!
//! A rotation that maps a cloud onto itself keeps its covariance, so it permutes the
//! covariance's eigenspaces: where the three spreads differ, it can only be a half turn about an
//! axis; where two are equal, a turn about the third axis (an n-fold prism, a cylinder) or a half
//! turn across it; where all three are (a cube, a regular solid, a sphere), the axes say nothing,
//! and the turns are looked for about the direction of the cloud's farthest point (a vertex of
//! a regular solid is on an axis of 3-, 4- or 5-fold symmetry). [`SelfFit`] tries those turns.

use nalgebra::{Rotation3, Unit, Vector3};
use rayon::prelude::*;
use rgm_geom::cloud::{evenly, median};
use rgm_geom::{KnnIndex, Matrix3, Point3, PointCloud, RigidTransform};

/// The centroid, the spreads (ascending) and the principal axes (one a column, in the spreads'
/// order) of `cloud`'s covariance.
pub(crate) fn principal_axes(cloud: &PointCloud) -> (Point3<f64>, Vector3<f64>, Matrix3<f64>) {
    let (centre, covariance) = scatter(cloud.points.iter());
    let eigen = covariance.symmetric_eigen();
    let mut order = [0, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
    let spreads = Vector3::from_fn(|i, _| eigen.eigenvalues[order[i]]);
    let axes = Matrix3::from_fn(|r, c| eigen.eigenvectors[(r, order[c])]);
    (centre, spreads, axes)
}

/// The mean of `points` and the sum of their outer products about it (the covariance, unscaled);
/// the origin and zero for none.
fn scatter<'a>(
    points: impl Iterator<Item = &'a Point3<f64>> + Clone,
) -> (Point3<f64>, Matrix3<f64>) {
    let n = points.clone().count().max(1) as f64;
    let centre = Point3::from(points.clone().map(|p| p.coords).sum::<Vector3<f64>>() / n);
    let mut covariance = Matrix3::zeros();
    for p in points {
        let d = p - centre;
        covariance += d * d.transpose();
    }
    (centre, covariance)
}

/// The turn by `angle` (radians) about `axis` through `centre`: p ↦ c + R (p − c).
pub(crate) fn turn_about(centre: &Point3<f64>, axis: &Vector3<f64>, angle: f64) -> RigidTransform {
    let turn = Rotation3::from_axis_angle(&Unit::new_normalize(*axis), angle).into_inner();
    RigidTransform::new(turn, centre.coords - turn * centre.coords)
}

/// At most this many points of a cloud are tried under each turn.
const SAMPLE: usize = 1024;

/// A point's local spacing is its distance to this many-th nearest other point (about twice the
/// distance to its nearest, and far steadier).
const NEIGHBOURS: usize = 4;

/// A cloud's surface is measured at each point through it and this many nearest.
const PLANE_NEIGHBOURS: usize = 8;

/// A cloud fits itself under a turn when at least `share` of its points, turned, lie within
/// `within` times their local spacing (the distance to their 4th nearest other point) of the
/// cloud: a resampled surface, not the same points, is what a symmetry gives. Only a surface
/// can: a cloud whose points fill a volume (a lattice, foliage) has some point near wherever a
/// turn takes its points, so a cloud fits itself only where the median flatness of its points'
/// neighbourhoods (of each point and its 8 nearest) is below `flat`. Turns are looked for
/// beyond the principal axes' half turns where two spreads are within `near_equal` of each
/// other (the smaller over the larger).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SelfFit {
    pub within: f64,
    pub share: f64,
    pub near_equal: f64,
    pub flat: f64,
}

impl SelfFit {
    /// The turns that may map `cloud` onto itself (module doc), about its centroid.
    fn candidate_turns(&self, cloud: &PointCloud) -> Vec<RigidTransform> {
        use std::f64::consts::{PI, TAU};
        let (centre, spreads, axes) = principal_axes(cloud);
        let equal = |a: usize, b: usize| spreads[a] >= self.near_equal * spreads[b];
        let mut turns: Vec<RigidTransform> = (0..3)
            .map(|i| turn_about(&centre, &axes.column(i).into_owned(), PI))
            .collect();
        let (low, high) = (equal(0, 1), equal(1, 2));
        if low && high {
            // Every axis is a principal one: try the regular solids' turns about a vertex.
            let far = cloud
                .points
                .iter()
                .max_by(|a, b| (*a - centre).norm().total_cmp(&(*b - centre).norm()));
            if let Some(far) = far.filter(|far| (*far - centre).norm() > 0.0) {
                for n in [2, 3, 4, 5] {
                    turns.push(turn_about(&centre, &(far - centre), TAU / n as f64));
                }
            }
        } else if low || high {
            // The odd axis out is the axis of an n-fold prism or a cylinder.
            let odd = if low { axes.column(2) } else { axes.column(0) }.into_owned();
            for n in 3..=8 {
                turns.push(turn_about(&centre, &odd, TAU / n as f64));
            }
        }
        turns
    }

    /// A turn (not the identity) that maps `cloud` onto itself, if there is one: a result on
    /// such a cloud is as good turned by it. `index` is over `cloud.points`.
    pub fn symmetry(&self, cloud: &PointCloud, index: &KnnIndex) -> Option<RigidTransform> {
        if cloud.len() <= PLANE_NEIGHBOURS {
            return None;
        }
        // Each tried point with how near its turned copy must come: its own neighbours'
        // distance, so that a cloud denser in some parts is measured in each part's spacing.
        let sample: Vec<&Point3<f64>> = evenly(&cloud.points, SAMPLE).collect(); // (S,)
        let tried: Vec<(Point3<f64>, f64)> = sample
            .par_iter()
            .map(|&p| {
                (
                    *p,
                    self.within * index.k_nearest(p, NEIGHBOURS + 1)[NEIGHBOURS].1,
                )
            })
            .filter(|&(_, reach)| reach > 0.0)
            .collect(); // (S,)
        if tried.is_empty() {
            return None;
        }
        // A turn is given up at the first miss beyond the share allowed: most turns of a shape
        // without a symmetry miss at once, so trying them costs a few queries each.
        let misses_allowed = ((1.0 - self.share) * tried.len() as f64).floor() as usize;
        let turn = self.candidate_turns(cloud).into_iter().find(|turn| {
            let mut misses = 0;
            tried.iter().all(|(p, reach)| {
                misses += usize::from(index.nearest_within(&turn.apply(p), *reach).is_none());
                misses <= misses_allowed
            })
        })?;
        // Measured only for a cloud that fits itself, which few do.
        let flatness = median(
            evenly(&cloud.points, SAMPLE)
                .map(|p| flatness(cloud, &index.k_nearest(p, PLANE_NEIGHBOURS + 1)))
                .collect(),
        );
        (flatness < self.flat).then_some(turn)
    }
}

/// How far the points `around` (indices into `cloud`) spread off their plane: the least of
/// their covariance's eigenvalues over the sum (0 on a plane, 1/3 for a ball; 1 when they are
/// all one point, which says nothing of a surface).
fn flatness(cloud: &PointCloud, around: &[(usize, f64)]) -> f64 {
    let (_, covariance) = scatter(around.iter().map(|&(i, _)| &cloud.points[i]));
    let spreads = covariance.symmetric_eigen().eigenvalues;
    let total = spreads.sum();
    if total > 0.0 {
        spreads.min() / total
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rgm_geom::testing::box_surface_of;

    const FIT: SelfFit = SelfFit {
        within: 1.0,
        share: 0.9,
        near_equal: 0.8,
        flat: 0.1,
    };

    /// `cloud` turned by a rotation that is no symmetry of a box, so that its axes are no
    /// longer the frame's.
    fn askew(cloud: &PointCloud) -> PointCloud {
        let turn = RigidTransform::new(
            Rotation3::from_euler_angles(0.4, -0.7, 1.1).into_inner(),
            Vector3::new(0.3, -0.2, 0.1),
        );
        PointCloud::new(cloud.points.iter().map(|p| turn.apply(p)).collect())
    }

    fn symmetry_of(cloud: &PointCloud) -> Option<RigidTransform> {
        FIT.symmetry(cloud, &KnnIndex::new(&cloud.points))
    }

    #[test]
    fn a_cube_a_box_and_a_sphere_fit_themselves_turned() {
        let cube = askew(&box_surface_of([0.5, 0.5, 0.5], 2048, 1));
        let turn = symmetry_of(&cube).expect("a cube fits itself turned");
        assert!(
            turn.rotation_angle_deg() > 60.0,
            "{}",
            turn.rotation_angle_deg()
        );
        let flat_box = askew(&box_surface_of([0.5, 0.3, 0.15], 2048, 2));
        let half = symmetry_of(&flat_box).expect("a box fits itself half turned");
        assert!((half.rotation_angle_deg() - 180.0).abs() < 2.0);
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let sphere = PointCloud::new(
            (0..2048)
                .map(|_| {
                    let v = Vector3::new(rng.gen(), rng.gen(), rng.gen()).map(|x: f64| x - 0.5);
                    Point3::from(v.normalize())
                })
                .collect(),
        );
        assert!(symmetry_of(&sphere).is_some());
    }

    #[test]
    fn a_shape_without_a_symmetry_fits_itself_under_no_turn() {
        // A box with a post on one corner: no turn maps it onto itself.
        let mut shape = box_surface_of([0.5, 0.35, 0.2], 2048, 4);
        shape.points.extend(
            box_surface_of([0.075, 0.075, 0.3], 512, 5)
                .points
                .iter()
                .map(|p| p + Vector3::new(0.45, 0.3, 0.5)),
        );
        assert_eq!(symmetry_of(&askew(&shape)), None);
    }

    #[test]
    fn a_cloud_that_fills_a_volume_fits_itself_under_no_turn() {
        // A lattice spaced alike along x and y: a half turn about the diagonal maps it onto
        // itself, and every other turn lands its points near some point; it has no surface
        // to fit, and no turn is taken for a symmetry.
        let spaced = |k: usize| 0.3 * (k * k) as f64;
        let lattice = PointCloud::new(
            (0..125)
                .map(|i| Point3::new(spaced(i % 5), spaced(i / 5 % 5), (i / 25) as f64 * 1.3))
                .collect(),
        );
        let index = KnnIndex::new(&lattice.points);
        assert!(SelfFit { flat: 1.0, ..FIT }
            .symmetry(&lattice, &index)
            .is_some());
        assert_eq!(FIT.symmetry(&lattice, &index), None);
    }
}
