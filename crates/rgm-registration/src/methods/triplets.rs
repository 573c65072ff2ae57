//! Registration of tiny clouds (a few markers, a handful of landmarks) by trying every
//! correspondence of one source triangle: features and networks need neighbourhoods that a
//! cloud of 3 to a few dozen points does not have, but so few points can be searched whole.
//!
//! The source's triangle of largest area is matched to every ordered target triplet of the same
//! side lengths (within [`TripletConfig::tolerance`]); each match gives a transform (Kabsch on
//! the three pairs), the one that brings the most source points within the tolerance of a
//! target point wins (ties to the smaller RMSE), and it is fitted again on all those pairs.

use std::time::Instant;

use rgm_geom::{kabsch, GeomError, PointCloud, Result, RigidTransform};

use crate::fit::{score, Fit};
use crate::registrar::{MethodId, Registrar, Registration};
use crate::Prepared;

/// The method's name ([`crate::registrar::MethodId`]).
pub const NAME: &str = "triplets";

/// Settings of [`register`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TripletConfig {
    /// Most points per cloud (default 32): the search grows with the cube of the target's
    /// points.
    pub max_points: usize,
    /// How far side lengths and matched points may differ, as a share of the source's largest
    /// side (default 0.05): noise of a few per cent of the markers' spread is taken.
    pub tolerance: f64,
}

impl Default for TripletConfig {
    fn default() -> Self {
        Self {
            max_points: 32,
            tolerance: 0.05,
        }
    }
}

/// The three indices of `cloud`'s triangle of largest area.
fn widest_triangle(cloud: &PointCloud) -> [usize; 3] {
    let p = &cloud.points;
    let mut best = ([0, 1, 2], -1.0);
    for i in 0..p.len() {
        for j in i + 1..p.len() {
            for k in j + 1..p.len() {
                let area = (p[j] - p[i]).cross(&(p[k] - p[i])).norm();
                if area > best.1 {
                    best = ([i, j, k], area);
                }
            }
        }
    }
    best.0
}

/// Registers `source` onto `target` by [`TripletConfig`]'s search. Errors when a cloud has fewer
/// than 3 points or more than `max_points`, or its points all lie on a line.
pub fn register(
    source: &PointCloud,
    target: &PointCloud,
    config: &TripletConfig,
) -> Result<(Fit, f64)> {
    register_prepared(source, &Prepared::new(target), config)
}

/// [`register`] onto a prepared target, its tree shared with the stages after.
pub fn register_prepared(
    source: &PointCloud,
    target: &Prepared,
    config: &TripletConfig,
) -> Result<(Fit, f64)> {
    const OP: &str = "triplets::register";
    let bad = |why: String| Err(GeomError::Degenerate { op: OP, why });
    for (name, cloud) in [("source", source), ("target", target)] {
        if cloud.len() < 3 || cloud.len() > config.max_points {
            return bad(format!(
                "the {name} has {} points; the search takes 3 to {}",
                cloud.len(),
                config.max_points
            ));
        }
    }
    let [i, j, k] = widest_triangle(source);
    let s = &source.points;
    let sides = [
        (s[j] - s[i]).norm(),
        (s[k] - s[j]).norm(),
        (s[i] - s[k]).norm(),
    ];
    let longest = sides.iter().copied().fold(0.0, f64::max);
    let area = (s[j] - s[i]).cross(&(s[k] - s[i])).norm();
    if !(area > 1e-12 * longest * longest) {
        return bad("the source's points lie on a line: no rotation about it is told".into());
    }
    let tolerance = config.tolerance * longest;
    let index = target.index();
    let t = &target.points;
    let close = |a: usize, b: usize, side: f64| ((t[a] - t[b]).norm() - side).abs() <= tolerance;
    // (inliers, RMSE, transform) of the best match so far.
    let mut best: Option<(usize, f64, RigidTransform)> = None;
    let weights = [1.0; 3];
    for a in 0..t.len() {
        for b in (0..t.len()).filter(|&b| b != a && close(a, b, sides[0])) {
            for c in (0..t.len()).filter(|&c| c != a && c != b && close(b, c, sides[1])) {
                if !close(c, a, sides[2]) {
                    continue;
                }
                let Ok(transform) = kabsch(&[s[i], s[j], s[k]], &[t[a], t[b], t[c]], &weights)
                else {
                    continue;
                };
                let fit = score(&source.points, index, &transform, tolerance, None);
                let better = best.as_ref().is_none_or(|&(count, rmse, _)| {
                    fit.inlier_count > count || fit.inlier_count == count && fit.inlier_rmse < rmse
                });
                if better {
                    best = Some((fit.inlier_count, fit.inlier_rmse, transform));
                }
            }
        }
    }
    let Some((_, _, found)) = best else {
        return Ok((
            Fit::scored(
                RigidTransform::identity(),
                0,
                false,
                score(
                    &source.points,
                    index,
                    &RigidTransform::identity(),
                    tolerance,
                    None,
                ),
            ),
            tolerance,
        ));
    };
    // Fitted again on every pair the match brings within the tolerance.
    let mut pairs = Vec::new();
    score(&source.points, index, &found, tolerance, Some(&mut pairs));
    let (from, to): (Vec<_>, Vec<_>) = pairs.iter().map(|&(i, j)| (s[i], t[j])).unzip();
    let transform = kabsch(&from, &to, &vec![1.0; from.len()]).unwrap_or(found);
    let fit = score(&source.points, index, &transform, tolerance, None);
    Ok((Fit::scored(transform, 1, true, fit), tolerance))
}

impl<E: From<GeomError>> Registrar<E> for TripletConfig {
    fn id(&self) -> MethodId {
        MethodId::plain(NAME)
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        _: &mut dyn FnMut(crate::registrar::Progress),
    ) -> std::result::Result<Registration, E> {
        let start = Instant::now();
        let (result, tolerance) = register_prepared(source, target, self)?;
        Ok(Registration::scored_within(
            result, source, target, tolerance, start,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::StdRng, Rng, SeedableRng};
    use rgm_geom::{Point3, Vector3};

    /// Issue 44, D12: exact copies of 3 to 10 points at another pose are registered, in both
    /// directions, also when the target holds the points in another order.
    #[test]
    fn copies_of_a_few_points_are_registered_at_any_pose() {
        let mut rng = StdRng::seed_from_u64(7);
        for n in 3..=10 {
            let source = PointCloud::new(
                (0..n)
                    .map(|_| {
                        Point3::new(
                            rng.gen_range(-1.0..1.0),
                            rng.gen_range(-1.0..1.0),
                            rng.gen_range(-1.0..1.0),
                        )
                    })
                    .collect(),
            );
            let pose = RigidTransform::new(
                rgm_geom::euler::rotation_xyz_intrinsic(
                    rng.gen_range(-3.0..3.0),
                    rng.gen_range(-1.5..1.5),
                    rng.gen_range(-3.0..3.0),
                ),
                Vector3::new(0.5, -2.0, 1.0),
            );
            let mut target = source.transformed(&pose);
            target.points.reverse();
            for (a, b, truth) in [(&source, &target, pose), (&target, &source, pose.inverse())] {
                let found =
                    Registrar::<GeomError>::register(&mut TripletConfig::default(), a, b).unwrap();
                let t = found.result.t_target_source;
                let angle = t.inverse().compose(&truth).rotation_angle_deg();
                assert!(angle < 1e-6, "{n} points: {angle}°");
                assert!((t.translation - truth.translation).norm() < 1e-9, "{n}");
                assert_eq!(found.result.inlier_count, n, "{n}");
                assert!(found.doubt.is_none(), "{n}");
            }
        }
    }

    #[test]
    fn too_many_points_or_a_line_is_a_clear_error() {
        let line = PointCloud::new((0..5).map(|i| Point3::new(i as f64, 0.0, 0.0)).collect());
        let err = register(&line, &line, &TripletConfig::default()).unwrap_err();
        assert!(err.to_string().contains("lie on a line"), "{err}");
        let many = PointCloud::new(
            (0..40)
                .map(|i| Point3::new(i as f64, (i * i) as f64, 0.0))
                .collect(),
        );
        let err = register(&many, &line, &TripletConfig::default()).unwrap_err();
        assert!(
            err.to_string()
                .contains("the source has 40 points; the search takes 3 to 32"),
            "{err}"
        );
    }
}
