//! Point-to-point ICP as Open3D's `registration_icp` with
//! `TransformationEstimationPointToPoint` (no scaling) and `ICPConvergenceCriteria`.
//!
//! Open3D's loop, followed step for step: score the initial transform (pair each moved source
//! point with its nearest target point strictly closer than the maximum correspondence
//! distance); then up to `max_iteration` times: solve the rigid fit of the pairs (Kabsch, unit
//! weights), left-compose it onto the transform, re-score, and stop when both fitness and inlier
//! RMSE changed by less than their relative thresholds. The reported fitness and RMSE are those
//! of the final transform.

use std::time::Instant;

use nalgebra::Point3;
use rgm_geom::{kabsch, GeomError, KnnIndex, PointCloud, Result, RigidTransform};

use crate::fit::{score, Fit};
use crate::registrar::{MethodId, Progress, Registrar, Registration};
use crate::Prepared;

/// The method's name ([`crate::registrar::MethodId`]).
pub const NAME: &str = "icp";

/// Settings of [`register`]; `Default` gives Open3D's defaults and our correspondence distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IcpConfig {
    /// Pairs farther apart are ignored. Default 0.1: about two point spacings of a 1,024-point
    /// ModelNet shape in the unit sphere (Open3D has no default; users pass 0.05–0.2 here).
    pub max_correspondence_distance: f64,
    /// Stop when fitness changes by less than this (Open3D default 1e-6).
    pub relative_fitness: f64,
    /// …and inlier RMSE by less than this (Open3D default 1e-6).
    pub relative_rmse: f64,
    /// Most iterations (Open3D default 30).
    pub max_iteration: usize,
    /// The starting `t_target_source` (default: identity, as the paper's ICP baseline).
    pub initial: RigidTransform,
}

impl Default for IcpConfig {
    fn default() -> Self {
        Self {
            max_correspondence_distance: 0.1,
            relative_fitness: 1e-6,
            relative_rmse: 1e-6,
            max_iteration: 30,
            initial: RigidTransform::identity(),
        }
    }
}

/// Registers `source` onto `target`. Errors on empty clouds, non-finite points or a
/// non-positive correspondence distance. When fewer than 3 pairs remain (or they are collinear)
/// the loop stops early with the transform so far and `converged: false`.
pub fn register(source: &PointCloud, target: &PointCloud, config: &IcpConfig) -> Result<Fit> {
    register_prepared(source, &Prepared::new(target), config)
}

/// [`register`] onto a prepared target, its tree shared with the stages before and after.
pub fn register_prepared(
    source: &PointCloud,
    target: &Prepared,
    config: &IcpConfig,
) -> Result<Fit> {
    const OP: &str = "icp::register";
    check_clouds(OP, source, target)?;
    if !(config.max_correspondence_distance > 0.0) {
        return Err(GeomError::Degenerate {
            op: OP,
            why: format!(
                "max_correspondence_distance must be > 0, got {}",
                config.max_correspondence_distance
            ),
        });
    }
    Ok(register_with_index(source, target, target.index(), config))
}

/// [`register`] with the target's index built already (`index` over `target.points`), for
/// callers that run several ICP stages on one target. The clouds and distance are not checked.
pub(crate) fn register_with_index(
    source: &PointCloud,
    target: &PointCloud,
    index: &KnnIndex,
    config: &IcpConfig,
) -> Fit {
    let max_d = config.max_correspondence_distance;
    let identity = RigidTransform::identity();
    let mut transform = config.initial;
    let mut moved: Vec<Point3<f64>> = source.points.iter().map(|p| transform.apply(p)).collect(); // (N,)
    let mut pairs = Vec::with_capacity(source.len());
    let mut current = score(&moved, index, &identity, max_d, Some(&mut pairs));
    let (mut xs, mut ys) = (
        Vec::with_capacity(source.len()),
        Vec::with_capacity(source.len()),
    ); // (P,) pairs
    let ones = vec![1.0; source.len()]; // (N,) Kabsch weights
    let mut iterations = 0;
    let mut converged = false;
    while iterations < config.max_iteration {
        xs.clear();
        ys.clear();
        xs.extend(pairs.iter().map(|&(i, _)| moved[i]));
        ys.extend(pairs.iter().map(|&(_, j)| target.points[j]));
        let Ok(update) = kabsch(&xs, &ys, &ones[..xs.len()]) else {
            break;
        };
        transform = update.compose(&transform);
        iterations += 1;
        for (m, p) in moved.iter_mut().zip(&source.points) {
            *m = transform.apply(p);
        }
        let previous = current;
        current = score(&moved, index, &identity, max_d, Some(&mut pairs));
        if (previous.fitness - current.fitness).abs() < config.relative_fitness
            && (previous.inlier_rmse - current.inlier_rmse).abs() < config.relative_rmse
        {
            converged = true;
            break;
        }
    }
    Fit::scored(transform, iterations, converged, current)
}

/// Both clouds non-empty with finite coordinates.
pub(crate) fn check_clouds(
    op: &'static str,
    source: &PointCloud,
    target: &PointCloud,
) -> Result<()> {
    if source.is_empty() || target.is_empty() {
        return Err(GeomError::TooFewPoints {
            op,
            needed: 1,
            got: source.len().min(target.len()),
        });
    }
    if !source
        .points
        .iter()
        .chain(&target.points)
        .all(|p| p.coords.iter().all(|v| v.is_finite()))
    {
        return Err(GeomError::NonFinite { op });
    }
    Ok(())
}

/// Point-to-point ICP ([`crate::methods::icp`]) from its configured initial transform.
impl<E: From<GeomError>> Registrar<E> for IcpConfig {
    fn id(&self) -> MethodId {
        MethodId::plain(NAME)
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        _: &mut dyn FnMut(Progress),
    ) -> std::result::Result<Registration, E> {
        let start = Instant::now();
        let result = register_prepared(source, target, self)?;
        let distance = self.max_correspondence_distance;
        Ok(Registration::scored_within(
            result, source, target, distance, start,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use rgm_geom::euler::rotation_xyz_intrinsic;
    use rgm_geom::testing::box_surface;

    #[test]
    fn recovers_a_small_offset_exactly_on_identical_points() {
        let target = box_surface(500, 1);
        let gt = RigidTransform::new(
            rotation_xyz_intrinsic(0.05, -0.03, 0.04),
            Vector3::new(0.02, -0.01, 0.03),
        );
        let source = target.transformed(&gt.inverse());
        let result = register(&source, &target, &IcpConfig::default()).unwrap();
        let err = (result.t_target_source.to_matrix4() - gt.to_matrix4())
            .abs()
            .max();
        assert!(
            err < 1e-6,
            "error {err:.3e} after {} iterations",
            result.iterations
        );
        assert!(result.converged);
        assert_eq!(result.inlier_count, 500);
        assert_eq!(result.fitness, 1.0);
        assert!(result.inlier_rmse < 1e-6);
    }

    #[test]
    fn one_iteration_is_one_kabsch_step() {
        // With max_iteration 1 the result is exactly the Kabsch fit of the initial pairs.
        let target = box_surface(300, 2);
        let gt = RigidTransform::new(
            rotation_xyz_intrinsic(0.1, 0.0, 0.05),
            Vector3::new(0.03, 0.0, 0.0),
        );
        let source = target.transformed(&gt.inverse());
        let config = IcpConfig {
            max_iteration: 1,
            ..IcpConfig::default()
        };
        let result = register(&source, &target, &config).unwrap();
        let index = KnnIndex::new(&target.points);
        let mut pairs = Vec::new();
        score(
            &source.points,
            &index,
            &RigidTransform::identity(),
            0.1,
            Some(&mut pairs),
        );
        let xs: Vec<_> = pairs.iter().map(|&(i, _)| source.points[i]).collect();
        let ys: Vec<_> = pairs.iter().map(|&(_, j)| target.points[j]).collect();
        let expected = kabsch(&xs, &ys, &vec![1.0; xs.len()]).unwrap();
        assert_eq!(result.iterations, 1);
        assert!(!result.converged);
        assert!(
            (result.t_target_source.to_matrix4() - expected.to_matrix4())
                .abs()
                .max()
                < 1e-12
        );
        let s = score(&source.points, &index, &expected, 0.1, None);
        assert_eq!(
            (result.inlier_count, result.fitness, result.inlier_rmse),
            (s.inlier_count, s.fitness, s.inlier_rmse)
        );
    }

    /// Pinned from Open3D 0.20 on ModelNet40 `airplane_0627`:
    ///
    /// ```python
    /// R = Rotation.from_euler('xyz', [4, -3, 5], degrees=True).as_matrix(); t = np.array([0.02, -0.03, 0.01])
    /// src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts @ R.T + t))  # pcd: the airplane
    /// r = o3d.pipelines.registration.registration_icp(src, pcd, 0.1, np.eye(4),
    ///     TransformationEstimationPointToPoint(), ICPConvergenceCriteria(max_iteration=k))
    /// r.transformation, r.fitness, r.inlier_rmse
    /// ```
    #[test]
    fn matches_open3d_registration_icp() {
        let target = rgm_geom::testing::airplane();
        let r = rgm_geom::euler::rotation_xyz_extrinsic(
            4f64.to_radians(),
            -3f64.to_radians(),
            5f64.to_radians(),
        );
        let source = target.transformed(&RigidTransform::new(r, Vector3::new(0.02, -0.03, 0.01)));
        let cases = [
            (
                1,
                [
                    [
                        0.9992752796246036,
                        0.027158345576948774,
                        0.026670954176648293,
                        -0.003154561696485786,
                    ],
                    [
                        -0.027915140288138997,
                        0.999206062518233,
                        0.028425157334694973,
                        0.005744710348460372,
                    ],
                    [
                        -0.02587779886047819,
                        -0.029149080471460365,
                        0.9992400465522813,
                        -0.0063819910591766055,
                    ],
                ],
                0.03236624198165532,
            ),
            (
                30,
                [
                    [
                        0.9948294478803328,
                        0.0870362988312832,
                        0.052335956242943876,
                        -0.017808859555097603,
                    ],
                    [
                        -0.09058031520755636,
                        0.9934498321516351,
                        0.0696608749212158,
                        0.030918492519488045,
                    ],
                    [
                        -0.04593012221855635,
                        -0.0740412971499086,
                        0.9961969233988578,
                        -0.0112646057041147,
                    ],
                ],
                4.4360767796854955e-16,
            ),
        ];
        for (k, rows, rmse) in cases {
            let config = IcpConfig {
                max_iteration: k,
                ..IcpConfig::default()
            };
            let result = register(&source, &target, &config).unwrap();
            let m = result.t_target_source.to_matrix4();
            for (r, row) in rows.iter().enumerate() {
                for (c, want) in row.iter().enumerate() {
                    assert!(
                        (m[(r, c)] - want).abs() < 1e-9,
                        "k={k} ({r},{c}): {} vs {want}",
                        m[(r, c)]
                    );
                }
            }
            assert_eq!(result.fitness, 1.0);
            assert!(
                (result.inlier_rmse - rmse).abs() < 1e-9,
                "k={k}: rmse {} vs {rmse}",
                result.inlier_rmse
            );
        }
    }

    #[test]
    fn far_apart_clouds_stop_without_pairs() {
        let target = box_surface(100, 3);
        let source = target.transformed(&RigidTransform::new(
            nalgebra::Matrix3::identity(),
            Vector3::new(10.0, 0.0, 0.0),
        ));
        let result = register(&source, &target, &IcpConfig::default()).unwrap();
        assert_eq!(result.iterations, 0);
        assert!(!result.converged);
        assert_eq!(result.t_target_source, RigidTransform::identity());
        assert_eq!(
            (result.inlier_count, result.fitness, result.inlier_rmse),
            (0, 0.0, 0.0)
        );
    }

    #[test]
    fn bad_inputs_are_errors() {
        let c = box_surface(10, 4);
        let empty = PointCloud::default();
        assert!(matches!(
            register(&empty, &c, &IcpConfig::default()),
            Err(GeomError::TooFewPoints { .. })
        ));
        let zero = IcpConfig {
            max_correspondence_distance: 0.0,
            ..IcpConfig::default()
        };
        assert!(matches!(
            register(&c, &c, &zero),
            Err(GeomError::Degenerate { .. })
        ));
        let mut nan = c.clone();
        nan.points[3].z = f64::NAN;
        assert_eq!(
            register(&nan, &c, &IcpConfig::default()),
            Err(GeomError::NonFinite {
                op: "icp::register"
            })
        );
    }
}
