//! Rotation helpers: ZYX Euler angles (roll, pitch, yaw) and skew matrices.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// The skew-symmetric matrix `[v]×` with `[v]× w = v × w` (paper eq. 2).
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Roll, pitch, yaw (rad) of `nav_from_body` in the aerospace ZYX convention:
/// `nav_from_body = Rz(yaw) · Ry(pitch) · Rx(roll)`.
pub fn euler_zyx(nav_from_body: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (roll, pitch, yaw) = nav_from_body.euler_angles();
    Vector3::new(roll, pitch, yaw)
}

/// `nav_from_body` from ZYX Euler angles (rad), the inverse of [`euler_zyx`].
pub fn from_euler_zyx(roll: f64, pitch: f64, yaw: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(roll, pitch, yaw)
}

/// Wraps an angle to (-π, π].
pub fn wrap_pi(a: f64) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    let mut x = (a + std::f64::consts::PI).rem_euclid(two_pi) - std::f64::consts::PI;
    if x <= -std::f64::consts::PI {
        x += two_pi;
    }
    x
}

/// Roll, pitch, yaw error (estimate − truth), wrapped, rad.
pub fn euler_error(est: &UnitQuaternion<f64>, truth: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (r1, p1, y1) = est.euler_angles();
    let (r0, p0, y0) = truth.euler_angles();
    Vector3::new(wrap_pi(r1 - r0), wrap_pi(p1 - p0), wrap_pi(y1 - y0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_round_trip() {
        let q = from_euler_zyx(0.1, -0.2, 2.5);
        let e = euler_zyx(&q);
        assert!((e - Vector3::new(0.1, -0.2, 2.5)).norm() < 1e-12);
        // ZYX order: yaw applied last.
        let r = Matrix3::from(nalgebra::Rotation3::from_axis_angle(
            &Vector3::z_axis(),
            2.5,
        )) * Matrix3::from(nalgebra::Rotation3::from_axis_angle(
            &Vector3::y_axis(),
            -0.2,
        )) * Matrix3::from(nalgebra::Rotation3::from_axis_angle(
            &Vector3::x_axis(),
            0.1,
        ));
        assert!((q.to_rotation_matrix().matrix() - r).norm() < 1e-12);
    }

    #[test]
    fn skew_is_cross_product() {
        let a = Vector3::new(1.0, -2.0, 0.5);
        let b = Vector3::new(0.3, 0.7, -1.1);
        assert!((skew(&a) * b - a.cross(&b)).norm() < 1e-15);
    }

    #[test]
    fn wrap() {
        assert!((wrap_pi(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
        assert!((wrap_pi(-0.5) + 0.5).abs() < 1e-15);
    }
}
