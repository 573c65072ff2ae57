//! Euler angles in the two conventions of the spec.
//!
//! - Data protocol (spec §1): `R = Rx(a)·Ry(b)·Rz(c)` — [`rotation_xyz_intrinsic`].
//! - Metrics (spec §5): scipy's `as_euler('xyz')`, extrinsic x-y-z, `R = Rz(γ)·Ry(β)·Rx(α)` —
//!   [`rotation_xyz_extrinsic`] and its inverse [`euler_xyz_extrinsic`].
//!
//! Angles are in radians.

use nalgebra::Matrix3;

/// Rotation about x by `a`.
pub fn rx(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

/// Rotation about y by `b`.
pub fn ry(b: f64) -> Matrix3<f64> {
    let (s, c) = b.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

/// Rotation about z by `c`.
pub fn rz(c: f64) -> Matrix3<f64> {
    let (s, co) = c.sin_cos();
    Matrix3::new(co, -s, 0.0, s, co, 0.0, 0.0, 0.0, 1.0)
}

/// `Rx(a)·Ry(b)·Rz(c)`: how the data protocol builds its random rotation.
pub fn rotation_xyz_intrinsic(a: f64, b: f64, c: f64) -> Matrix3<f64> {
    rx(a) * ry(b) * rz(c)
}

/// `Rz(γ)·Ry(β)·Rx(α)`: scipy's `from_euler('xyz', [α, β, γ])` (extrinsic).
pub fn rotation_xyz_extrinsic(alpha: f64, beta: f64, gamma: f64) -> Matrix3<f64> {
    rz(gamma) * ry(beta) * rx(alpha)
}

/// `[α, β, γ]` with `R = Rz(γ)·Ry(β)·Rx(α)`, as scipy's `as_euler('xyz')`: β in [−π/2, π/2],
/// α and γ in (−π, π]. At gimbal lock (|β| = π/2) γ is set to 0, as scipy does.
pub fn euler_xyz_extrinsic(r: &Matrix3<f64>) -> [f64; 3] {
    // R = Rz(γ)Ry(β)Rx(α): R[2,0] = −sin β, R[2,1] = cos β sin α, R[2,2] = cos β cos α,
    // R[1,0] = sin γ cos β, R[0,0] = cos γ cos β.
    let sb = (-r[(2, 0)]).clamp(-1.0, 1.0);
    let beta = sb.asin();
    if (1.0 - sb.abs()) < 1e-12 {
        // cos β = 0: only α ∓ γ is defined; with γ = 0, R[0,1] = sin β sin α − …, R[1,1] = cos α.
        let alpha = if sb > 0.0 {
            r[(0, 1)].atan2(r[(1, 1)])
        } else {
            (-r[(0, 1)]).atan2(r[(1, 1)])
        };
        return [alpha, beta, 0.0];
    }
    let alpha = r[(2, 1)].atan2(r[(2, 2)]);
    let gamma = r[(1, 0)].atan2(r[(0, 0)]);
    [alpha, beta, gamma]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extrinsic_round_trip() {
        for &(a, b, g) in &[
            (0.1, 0.2, 0.3),
            (-2.5, 1.2, 3.0),
            (1.0, -0.7, -2.0),
            (0.0, 0.0, 0.0),
        ] {
            let r = rotation_xyz_extrinsic(a, b, g);
            let [a2, b2, g2] = euler_xyz_extrinsic(&r);
            assert!((a - a2).abs() < 1e-12 && (b - b2).abs() < 1e-12 && (g - g2).abs() < 1e-12);
        }
    }

    #[test]
    fn gimbal_lock_recovers_the_rotation() {
        for &b in &[std::f64::consts::FRAC_PI_2, -std::f64::consts::FRAC_PI_2] {
            let r = rotation_xyz_extrinsic(0.4, b, 0.0);
            let [a2, b2, g2] = euler_xyz_extrinsic(&r);
            assert!((rotation_xyz_extrinsic(a2, b2, g2) - r).abs().max() < 1e-9);
        }
    }

    #[test]
    fn scipy_pinned_value() {
        // scipy: Rotation.from_euler('xyz', [10, 20, 30], degrees=True).as_matrix()[0]
        //   = [0.81379768, -0.44096961, 0.37852231]
        let r = rotation_xyz_extrinsic(10f64.to_radians(), 20f64.to_radians(), 30f64.to_radians());
        let row = [r[(0, 0)], r[(0, 1)], r[(0, 2)]];
        let expected = [0.81379768, -0.44096961, 0.37852231];
        for (x, e) in row.iter().zip(expected) {
            assert!((x - e).abs() < 1e-8, "{row:?}");
        }
    }

    #[test]
    fn intrinsic_differs_from_extrinsic_order() {
        // Rx(a)Ry(b)Rz(c) is scipy's from_euler('XYZ') (intrinsic), not from_euler('xyz').
        // scipy: Rotation.from_euler('XYZ', [10, 20, 30], degrees=True).as_matrix()[0]
        //   = [0.81379768, -0.46984631, 0.34202014]
        let r = rotation_xyz_intrinsic(10f64.to_radians(), 20f64.to_radians(), 30f64.to_radians());
        let expected = [0.81379768, -0.46984631, 0.34202014];
        for (c, e) in expected.iter().enumerate() {
            assert!((r[(0, c)] - e).abs() < 1e-8, "{r}");
        }
    }
}
