//! Rigid transforms `y = R x + t`, and random poses as the data protocol draws them.

use nalgebra::{Matrix3, Matrix4, Point3, Vector3};
use rand::Rng;

use crate::euler::rotation_xyz_intrinsic;
use crate::{GeomError, Result};

/// A rigid transform `y = R x + t` (rotation matrix with det +1, translation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidTransform {
    /// R. // (3, 3)
    pub rotation: Matrix3<f64>,
    /// t. // (3,)
    pub translation: Vector3<f64>,
}

impl Default for RigidTransform {
    fn default() -> Self {
        Self::identity()
    }
}

impl RigidTransform {
    /// A transform from its parts; `rotation` is trusted to be a rotation.
    pub fn new(rotation: Matrix3<f64>, translation: Vector3<f64>) -> Self {
        Self {
            rotation,
            translation,
        }
    }

    /// The identity.
    pub fn identity() -> Self {
        Self::new(Matrix3::identity(), Vector3::zeros())
    }

    /// `R p + t`.
    pub fn apply(&self, p: &Point3<f64>) -> Point3<f64> {
        Point3::from(self.rotation * p.coords + self.translation)
    }

    /// `R v` (directions and normals ignore the translation).
    pub fn apply_vector(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * v
    }

    /// `self ∘ first`: apply `first`, then `self`.
    pub fn compose(&self, first: &RigidTransform) -> Self {
        Self::new(
            self.rotation * first.rotation,
            self.rotation * first.translation + self.translation,
        )
    }

    /// The inverse `x = Rᵀ (y − t)`.
    pub fn inverse(&self) -> Self {
        let rt = self.rotation.transpose();
        Self::new(rt, -(rt * self.translation))
    }

    /// The homogeneous 4×4 matrix `[[R, t], [0, 1]]`.
    pub fn to_matrix4(&self) -> Matrix4<f64> {
        let mut m = Matrix4::identity();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.rotation);
        m.fixed_view_mut::<3, 1>(0, 3).copy_from(&self.translation);
        m
    }

    /// Rows of the 4×4 matrix, for printing and JSON.
    pub fn to_rows(&self) -> [[f64; 4]; 4] {
        let m = self.to_matrix4();
        std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
    }

    /// A transform from a homogeneous 4×4 matrix, checked to be rigid within `tol`
    /// (RᵀR = I, det R = +1, last row 0 0 0 1).
    pub fn from_matrix4(m: &Matrix4<f64>, tol: f64) -> Result<Self> {
        if m.iter().any(|v| !v.is_finite()) {
            return Err(GeomError::NonFinite {
                op: "RigidTransform::from_matrix4",
            });
        }
        let last = m.fixed_view::<1, 4>(3, 0);
        if (last[0].abs() + last[1].abs() + last[2].abs() + (last[3] - 1.0).abs()) > tol {
            return Err(GeomError::NotRigid {
                why: format!("last row is {last}, expected 0 0 0 1"),
            });
        }
        let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into();
        let orth = (r.transpose() * r - Matrix3::identity()).abs().max();
        if orth > tol {
            return Err(GeomError::NotRigid {
                why: format!("rotation block is not orthonormal (|RᵀR − I| = {orth:.2e})"),
            });
        }
        let det = r.determinant();
        if (det - 1.0).abs() > tol {
            return Err(GeomError::NotRigid {
                why: format!("rotation block has determinant {det:.6}, expected +1"),
            });
        }
        Ok(Self::new(r, m.fixed_view::<3, 1>(0, 3).into()))
    }

    /// The rotation angle of `R` in degrees, `acos((trace − 1) / 2)`.
    pub fn rotation_angle_deg(&self) -> f64 {
        ((self.rotation.trace() - 1.0) / 2.0)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    }

    /// A random pose as spec §1 draws G: angles a, b, c uniform in [0°, `max_angle_deg`],
    /// `R = Rx(a)·Ry(b)·Rz(c)`, translation uniform in [−`max_translation`, `max_translation`]
    /// per axis. Draw order: a, b, c, then t_x, t_y, t_z.
    pub fn random<R: Rng + ?Sized>(rng: &mut R, max_angle_deg: f64, max_translation: f64) -> Self {
        let mut angle = || rng.gen_range(0.0..=max_angle_deg).to_radians();
        let (a, b, c) = (angle(), angle(), angle());
        let rotation = rotation_xyz_intrinsic(a, b, c);
        let mut shift = || rng.gen_range(-max_translation..=max_translation);
        let translation = Vector3::new(shift(), shift(), shift());
        Self::new(rotation, translation)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::StdRng, SeedableRng};

    fn pose(seed: u64) -> RigidTransform {
        RigidTransform::random(&mut StdRng::seed_from_u64(seed), 45.0, 0.5)
    }

    #[test]
    fn inverse_undoes_the_transform() {
        let t = pose(1);
        let p = Point3::new(0.3, -0.7, 1.1);
        let back = t.inverse().apply(&t.apply(&p));
        assert!((back - p).norm() < 1e-12);
        let id = t.compose(&t.inverse());
        assert!((id.to_matrix4() - Matrix4::identity()).abs().max() < 1e-12);
    }

    #[test]
    fn compose_applies_the_right_one_first() {
        let (a, b) = (pose(2), pose(3));
        let p = Point3::new(1.0, 2.0, 3.0);
        let composed = a.compose(&b).apply(&p);
        assert!((composed - a.apply(&b.apply(&p))).norm() < 1e-12);
        assert!(
            (a.compose(&b).to_matrix4() - a.to_matrix4() * b.to_matrix4())
                .abs()
                .max()
                < 1e-12
        );
    }

    #[test]
    fn matrix4_round_trip_and_rejection() {
        let t = pose(4);
        assert_eq!(
            RigidTransform::from_matrix4(&t.to_matrix4(), 1e-9).unwrap(),
            t
        );
        let mut m = t.to_matrix4();
        m[(0, 0)] *= -1.0;
        assert!(matches!(
            RigidTransform::from_matrix4(&m, 1e-6),
            Err(GeomError::NotRigid { .. })
        ));
        let mut scaled = Matrix4::identity() * 2.0;
        scaled[(3, 3)] = 1.0;
        assert!(RigidTransform::from_matrix4(&scaled, 1e-6).is_err());
    }

    #[test]
    fn random_poses_stay_in_range() {
        for seed in 0..200 {
            let t = pose(seed);
            assert!((t.rotation.determinant() - 1.0).abs() < 1e-12);
            assert!(t.translation.iter().all(|v| v.abs() <= 0.5));
            // Three rotations of at most 45° compose to at most 135°.
            assert!(t.rotation_angle_deg() <= 135.0 + 1e-9);
        }
    }

    #[test]
    fn rotation_angle_of_a_quarter_turn() {
        let t = RigidTransform::new(
            rotation_xyz_intrinsic(0.0, 0.0, std::f64::consts::FRAC_PI_2),
            Vector3::zeros(),
        );
        assert!((t.rotation_angle_deg() - 90.0).abs() < 1e-12);
    }
}
