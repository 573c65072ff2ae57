//! Weighted Kabsch (Umeyama without scale): the rigid transform minimising
//! `Σ w_i ‖R x_i + t − y_i‖²` (spec §4.5).
//!
//! With weighted centroids `c_X`, `c_Y` and covariance `H = Σ w_i (x_i − c_X)(y_i − c_Y)ᵀ = U Σ Vᵀ`,
//! `R = V diag(1, 1, d) Uᵀ` with `d = sign det(V Uᵀ)` (the reflection fix: det R = +1 always),
//! and `t = c_Y − R c_X`.
//!
//! Degenerate inputs are errors, never NaN: when the covariance has rank < 2 (all points with
//! positive weight coincident or collinear) a rotation about the line is left free, so no
//! unique answer exists and [`GeomError::Degenerate`] is returned. Rank 2 (planar points) is
//! fine: the third axis follows from the other two and det R = +1.

use nalgebra::{Matrix3, Point3, Vector3, SVD};

use crate::{GeomError, Result, RigidTransform};

/// The smallest ratio σ₂/σ₁ of the covariance's singular values accepted as rank 2. Below it
/// the points are taken as collinear.
const RANK_TOLERANCE: f64 = 1e-10;

/// The fewest pairs of positive weight that fix a pose: two leave a rotation about their line
/// free.
pub const MIN_POINTS: usize = 3;

/// The transform `t_target_source` that best maps `source[i]` onto `target[i]` in the weighted
/// least-squares sense. Weights must be finite and ≥ 0; points with zero weight are ignored.
pub fn kabsch(
    source: &[Point3<f64>],
    target: &[Point3<f64>],
    weights: &[f64],
) -> Result<RigidTransform> {
    const OP: &str = "kabsch";
    if source.len() != target.len() {
        return Err(GeomError::LengthMismatch {
            op: OP,
            left: source.len(),
            right: target.len(),
        });
    }
    if weights.len() != source.len() {
        return Err(GeomError::LengthMismatch {
            op: OP,
            left: source.len(),
            right: weights.len(),
        });
    }
    let finite = |p: &Point3<f64>| p.coords.iter().all(|v| v.is_finite());
    if !source.iter().chain(target).all(finite) || !weights.iter().all(|w| w.is_finite()) {
        return Err(GeomError::NonFinite { op: OP });
    }
    if let Some(w) = weights.iter().find(|&&w| w < 0.0) {
        return Err(GeomError::Degenerate {
            op: OP,
            why: format!("negative weight {w}"),
        });
    }
    let positive = weights.iter().filter(|&&w| w > 0.0).count();
    if positive == 0 {
        return Err(GeomError::Degenerate {
            op: OP,
            why: "all weights are zero".into(),
        });
    }
    if positive < MIN_POINTS {
        return Err(GeomError::TooFewPoints {
            op: OP,
            needed: MIN_POINTS,
            got: positive,
        });
    }

    let total: f64 = weights.iter().sum();
    let mut cx = Vector3::zeros();
    let mut cy = Vector3::zeros();
    for ((x, y), &w) in source.iter().zip(target).zip(weights) {
        cx += w * x.coords;
        cy += w * y.coords;
    }
    cx /= total;
    cy /= total;
    let mut h = Matrix3::zeros(); // (3, 3)
    for ((x, y), &w) in source.iter().zip(target).zip(weights) {
        h += w * (x.coords - cx) * (y.coords - cy).transpose();
    }

    let svd =
        SVD::try_new(h, true, true, f64::EPSILON, 0).ok_or_else(|| GeomError::Degenerate {
            op: OP,
            why: "SVD of the covariance did not converge".into(),
        })?;
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(GeomError::Degenerate {
            op: OP,
            why: "SVD returned no singular vectors".into(),
        });
    };
    // nalgebra does not sort singular values: order them to find σ₁ ≥ σ₂ ≥ σ₃.
    let mut sigma = [
        svd.singular_values[0],
        svd.singular_values[1],
        svd.singular_values[2],
    ];
    sigma.sort_by(|a, b| b.total_cmp(a));
    if !(sigma[1] > RANK_TOLERANCE * sigma[0]) {
        return Err(GeomError::Degenerate {
            op: OP,
            why: format!(
                "covariance has rank < 2 (singular values {:.3e}, {:.3e}, {:.3e}): points are coincident or collinear",
                sigma[0], sigma[1], sigma[2]
            ),
        });
    }
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    // Flip the singular vector of the smallest singular value when V Uᵀ is a reflection.
    let smallest = (0..3)
        .min_by(|&a, &b| svd.singular_values[a].total_cmp(&svd.singular_values[b]))
        .unwrap_or(2);
    let mut fix = Matrix3::identity();
    fix[(smallest, smallest)] = d;
    let rotation = v * fix * u.transpose();
    let translation = cy - rotation * cx;
    Ok(RigidTransform::new(rotation, translation))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::euler::rotation_xyz_intrinsic;
    use crate::testing::uniform_cube;
    use rand::{rngs::StdRng, Rng, SeedableRng};

    fn assert_rotation(r: &Matrix3<f64>) {
        assert!(
            (r.transpose() * r - Matrix3::identity()).abs().max() < 1e-12,
            "not orthonormal: {r}"
        );
        assert!(
            (r.determinant() - 1.0).abs() < 1e-12,
            "det {}",
            r.determinant()
        );
    }

    fn assert_same(a: &RigidTransform, b: &RigidTransform, tol: f64) {
        let diff = (a.to_matrix4() - b.to_matrix4()).abs().max();
        assert!(
            diff < tol,
            "transforms differ by {diff:.3e}:\n{:?}\n{:?}",
            a,
            b
        );
    }

    #[test]
    fn recovers_a_known_pose_exactly() {
        let mut rng = StdRng::seed_from_u64(7);
        for _ in 0..20 {
            let pose = RigidTransform::random(&mut rng, 180.0, 2.0);
            let x = uniform_cube(50, &mut rng);
            let y: Vec<_> = x.iter().map(|p| pose.apply(p)).collect();
            let w: Vec<f64> = (0..50).map(|_| rng.gen_range(0.1..2.0)).collect();
            let got = kabsch(&x, &y, &w).unwrap();
            assert_rotation(&got.rotation);
            assert_same(&got, &pose, 1e-10);
        }
    }

    #[test]
    fn zero_weights_are_ignored() {
        let mut rng = StdRng::seed_from_u64(8);
        let pose = RigidTransform::random(&mut rng, 45.0, 0.5);
        let x = uniform_cube(30, &mut rng);
        let mut y: Vec<_> = x.iter().map(|p| pose.apply(p)).collect();
        let mut w = vec![1.0; 30];
        // Ten wild outliers with weight zero change nothing.
        for i in 0..10 {
            y[i] = Point3::new(100.0, -50.0, 7.0 * i as f64);
            w[i] = 0.0;
        }
        assert_same(&kabsch(&x, &y, &w).unwrap(), &pose, 1e-10);
    }

    #[test]
    fn planar_data_gets_a_proper_rotation() {
        // Points in the plane z = 0: H has rank 2 and plain V Uᵀ may be a reflection.
        let mut rng = StdRng::seed_from_u64(9);
        let mut hit_reflection = false;
        for _ in 0..20 {
            let pose = RigidTransform::random(&mut rng, 90.0, 1.0);
            let x: Vec<_> = (0..20)
                .map(|_| Point3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), 0.0))
                .collect();
            let y: Vec<_> = x.iter().map(|p| pose.apply(p)).collect();
            let w = vec![1.0; 20];
            let svd = weighted_covariance(&x, &y).svd(true, true);
            hit_reflection |=
                (svd.v_t.unwrap().transpose() * svd.u.unwrap().transpose()).determinant() < 0.0;
            let got = kabsch(&x, &y, &w).unwrap();
            assert_rotation(&got.rotation);
            assert_same(&got, &pose, 1e-9);
        }
        assert!(hit_reflection, "no sample exercised the reflection fix");
    }

    #[test]
    fn mirrored_data_gets_the_best_proper_rotation() {
        // y = mirror(x) has no exact rigid fit; the answer must still be a rotation and a
        // stationary point of Σ‖R x̃ − ỹ‖²: H R symmetric (skew part zero), and no nearby rotation
        // does better.
        let mut rng = StdRng::seed_from_u64(10);
        let x = uniform_cube(40, &mut rng);
        let mirror = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
        let y: Vec<_> = x.iter().map(|p| Point3::from(mirror * p.coords)).collect();
        let got = kabsch(&x, &y, &vec![1.0; 40]).unwrap();
        assert_rotation(&got.rotation);
        let h = weighted_covariance(&x, &y);
        let svd = h.svd(true, true);
        assert!(
            (svd.v_t.unwrap().transpose() * svd.u.unwrap().transpose()).determinant() < 0.0,
            "plain SVD is not a reflection here"
        );
        let hr = h * got.rotation;
        assert!(
            (hr - hr.transpose()).abs().max() < 1e-10,
            "not stationary: {hr}"
        );
        // With the optimal translation for each R the cost is that of the centred clouds.
        let n = x.len() as f64;
        let cx: Vector3<f64> = x.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n;
        let cy: Vector3<f64> = y.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n;
        let cost = |r: &Matrix3<f64>| -> f64 {
            x.iter()
                .zip(&y)
                .map(|(a, b)| (r * (a.coords - cx) - (b.coords - cy)).norm_squared())
                .sum()
        };
        let best = cost(&got.rotation);
        for i in 0..30 {
            let (a, b, c) = (
                0.01 * (i % 3) as f64 - 0.01,
                0.01 * (i / 3 % 3) as f64 - 0.01,
                0.02 * (i as f64 / 9.0 - 1.5),
            );
            let r = got.rotation * rotation_xyz_intrinsic(a, b, c);
            assert!(cost(&r) >= best - 1e-12, "perturbation {i} is better");
        }
    }

    fn weighted_covariance(x: &[Point3<f64>], y: &[Point3<f64>]) -> Matrix3<f64> {
        let n = x.len() as f64;
        let cx: Vector3<f64> = x.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n;
        let cy: Vector3<f64> = y.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n;
        x.iter()
            .zip(y)
            .map(|(a, b)| (a.coords - cx) * (b.coords - cy).transpose())
            .sum()
    }

    #[test]
    fn degenerate_inputs_are_errors() {
        let p = |x: f64, y: f64, z: f64| Point3::new(x, y, z);
        let tri = vec![
            p(0.0, 0.0, 0.0),
            p(1.0, 0.0, 0.0),
            p(0.0, 1.0, 0.0),
            p(0.0, 0.0, 1.0),
        ];
        let ones = vec![1.0; 4];
        assert_eq!(
            kabsch(&tri, &tri[..3], &ones),
            Err(GeomError::LengthMismatch {
                op: "kabsch",
                left: 4,
                right: 3
            })
        );
        assert_eq!(
            kabsch(&tri, &tri, &ones[..2]),
            Err(GeomError::LengthMismatch {
                op: "kabsch",
                left: 4,
                right: 2
            })
        );
        assert_eq!(
            kabsch(&tri, &tri, &[1.0, 1.0, 0.0, 0.0]),
            Err(GeomError::TooFewPoints {
                op: "kabsch",
                needed: 3,
                got: 2
            })
        );
        assert!(
            matches!(kabsch(&tri, &tri, &[0.0; 4]), Err(GeomError::Degenerate { why, .. }) if why.contains("all weights"))
        );
        assert!(
            matches!(kabsch(&tri, &tri, &[1.0, 1.0, -1.0, 1.0]), Err(GeomError::Degenerate { why, .. }) if why.contains("negative"))
        );
        assert_eq!(
            kabsch(&tri, &tri, &[1.0, f64::NAN, 1.0, 1.0]),
            Err(GeomError::NonFinite { op: "kabsch" })
        );
        let mut bad = tri.clone();
        bad[1].x = f64::INFINITY;
        assert_eq!(
            kabsch(&bad, &tri, &ones),
            Err(GeomError::NonFinite { op: "kabsch" })
        );
        let line: Vec<_> = (0..5)
            .map(|i| p(i as f64, 2.0 * i as f64, -(i as f64)))
            .collect();
        assert!(
            matches!(kabsch(&line, &line, &[1.0; 5]), Err(GeomError::Degenerate { why, .. }) if why.contains("collinear"))
        );
        let same = vec![p(1.0, 2.0, 3.0); 5];
        assert!(
            matches!(kabsch(&same, &same, &[1.0; 5]), Err(GeomError::Degenerate { why, .. }) if why.contains("coincident"))
        );
        // Rank 2 is fine: the identity is recovered from planar points.
        let got = kabsch(&tri[..3], &tri[..3], &[1.0; 3]).unwrap();
        assert_same(&got, &RigidTransform::identity(), 1e-12);
    }
}
