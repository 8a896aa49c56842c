//! The estimator's per-IMU-sample output: the vocabulary ([`PoseOutput`], [`AidingFlags`]) is
//! `uavnav_core::output`'s; here are the helpers that fill it (Euler σ, eq. (31)'s `J`, the cheap
//! geodetic conversion).

use nalgebra::{UnitQuaternion, Vector3};
use uavnav_core::Lla;
pub use uavnav_core::output::{AidingFlags, PoseOutput};

/// The paper's eq. (31) matrix `J(φ, θ)`: ZYX Euler-angle rates from body angular rates,
/// `[φ̇ θ̇ ψ̇]ᵀ = J ω_nb^b`. Singular at θ = ±90°.
pub fn euler_rate_matrix(roll: f64, pitch: f64) -> nalgebra::Matrix3<f64> {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let tp = sp / cp;
    nalgebra::Matrix3::new(1.0, sr * tp, cr * tp, 0.0, cr, -sr, 0.0, sr / cp, cr / cp)
}

/// The canonical ZYX angles of the same attitude: pitch in [−90°, 90°], roll and yaw in
/// (−180°, 180°]. A filter whose state is Euler angles (the `paper` profile's attitude EKF)
/// carries pitch through ±90° when the vehicle flips, and `(φ, θ, ψ)` and `(φ + π, π − θ, ψ + π)`
/// are the same rotation; the output always gives the first form, as `euler_angles` of the
/// quaternion does, so that angles from both profiles compare. The σ of each angle is unchanged
/// (the map is a sign flip of θ and shifts of φ and ψ).
pub fn canonical_euler(e: &Vector3<f64>) -> Vector3<f64> {
    use std::f64::consts::{FRAC_PI_2, PI};
    // Angles already in range are returned bit for bit (outputs compare exactly in replays;
    // `wrap_pi` moves the last bit of some).
    let wrap = |a: f64| {
        if a > -PI && a <= PI {
            a
        } else {
            uavnav_core::rotation::wrap_pi(a)
        }
    };
    let pitch = wrap(e.y);
    if pitch.abs() <= FRAC_PI_2 {
        Vector3::new(wrap(e.x), pitch, wrap(e.z))
    } else {
        Vector3::new(wrap(e.x + PI), wrap(PI - pitch), wrap(e.z + PI))
    }
}

/// Roll/pitch/yaw σ from the global (NED) attitude-error covariance:
/// `δ(φ,θ,ψ) = J(φ,θ) Cᵀ δθⁿ` (a nav-frame error is the body-frame error `Cᵀ δθⁿ`).
pub fn euler_sigma(q: &UnitQuaternion<f64>, cov_th: &nalgebra::Matrix3<f64>) -> Vector3<f64> {
    let (roll, pitch, yaw) = q.euler_angles();
    euler_sigma_at(&Vector3::new(roll, pitch, yaw), cov_th)
}

/// [`euler_sigma`] for a caller that has the ZYX angles already (every output has): `J Cᵀ` in
/// closed form, which depends on pitch and yaw only,
/// `[[cψ/cθ, sψ/cθ, 0], [−sψ, cψ, 0], [tθ cψ, tθ sψ, 1]]` (the inverse of the nav-frame rate
/// `ωⁿ = ψ̇ e_z + Rz(ψ) θ̇ e_y + Rz(ψ) Ry(θ) φ̇ e_x`).
pub fn euler_sigma_at(euler_rad: &Vector3<f64>, cov_th: &nalgebra::Matrix3<f64>) -> Vector3<f64> {
    let (sp, cp) = euler_rad.y.sin_cos();
    let (sy, cy) = euler_rad.z.sin_cos();
    let tp = sp / cp;
    let m = nalgebra::Matrix3::new(cy / cp, sy / cp, 0.0, -sy, cy, 0.0, tp * cy, tp * sy, 1.0);
    let c = m * cov_th * m.transpose();
    Vector3::new(
        c[(0, 0)].max(0.0).sqrt(),
        c[(1, 1)].max(0.0).sqrt(),
        c[(2, 2)].max(0.0).sqrt(),
    )
}

/// Geodetic coordinates of local NED positions for every output, cheaply: an exact conversion at
/// a reference point refreshed every [`LLA_REFRESH_M`] of travel, and the first-order map around it
/// in between (error below a millimetre at the refresh distance).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LlaLinearizer {
    frame: uavnav_core::LocalFrame,
    ref_ned: Vector3<f64>,
    ref_lla: Lla,
    /// d(lat, lon, alt) / d(NED in the frame).
    map: nalgebra::Matrix3<f64>,
}

/// Travel after which the reference point is refreshed, m.
pub const LLA_REFRESH_M: f64 = 50.0;

impl LlaLinearizer {
    /// Linearised at `ned`.
    pub fn new(frame: uavnav_core::LocalFrame, ned: &Vector3<f64>) -> Self {
        use uavnav_core::geodesy::{ned_from_ecef, radius_meridian, radius_prime_vertical};
        let l = frame.ned_to_lla(ned);
        let o = frame.origin();
        let rot =
            ned_from_ecef(l.lat_rad, l.lon_rad) * ned_from_ecef(o.lat_rad, o.lon_rad).transpose();
        let scale = nalgebra::Matrix3::from_diagonal(&Vector3::new(
            1.0 / (radius_meridian(l.lat_rad) + l.alt_m),
            1.0 / ((radius_prime_vertical(l.lat_rad) + l.alt_m) * l.lat_rad.cos()),
            -1.0,
        ));
        Self {
            frame,
            ref_ned: *ned,
            ref_lla: l,
            map: scale * rot,
        }
    }

    /// LLA of `ned`, refreshing the reference when far from it.
    pub fn lla(&mut self, ned: &Vector3<f64>) -> Lla {
        let d = ned - self.ref_ned;
        if d.norm_squared() > LLA_REFRESH_M * LLA_REFRESH_M {
            *self = Self::new(self.frame, ned);
            return self.ref_lla;
        }
        let dl = self.map * d;
        Lla {
            lat_rad: self.ref_lla.lat_rad + dl.x,
            lon_rad: self.ref_lla.lon_rad + dl.y,
            alt_m: self.ref_lla.alt_m + dl.z,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_closed_form_is_j_times_c_transposed() {
        for (r, p, y) in [
            (0.3, -0.7, 2.5),
            (-1.2, 0.4, -0.3),
            (2.9, 1.3, 1.0),
            (0.0, 0.0, 0.0),
        ] {
            let q = UnitQuaternion::from_euler_angles(r, p, y);
            let m = euler_rate_matrix(r, p) * q.to_rotation_matrix().matrix().transpose();
            let cov = nalgebra::Matrix3::new(4.0, 0.5, -0.2, 0.5, 2.0, 0.3, -0.2, 0.3, 9.0) * 1e-6;
            let want = (m * cov * m.transpose()).diagonal().map(f64::sqrt);
            let got = euler_sigma_at(&Vector3::new(r, p, y), &cov);
            assert!((got - want).norm() < 1e-12 * want.norm(), "{got} vs {want}");
        }
    }

    #[test]
    fn canonical_angles_are_the_same_rotation_with_pitch_within_90_degrees() {
        use std::f64::consts::FRAC_PI_2;
        // A flipped vehicle as an Euler-state filter carries it (pitch −165°), angles past ±π,
        // and ordinary ones, which stay as they are.
        for e in [
            Vector3::new(0.14, -2.88, -1.3),
            Vector3::new(-3.0, 1.9, 3.1),
            Vector3::new(6.5, 0.2, -7.0),
            Vector3::new(0.3, -0.7, 2.5),
        ] {
            let c = canonical_euler(&e);
            assert!(
                c.y.abs() <= FRAC_PI_2 && c.x.abs() <= std::f64::consts::PI,
                "{c}"
            );
            let (qa, qb) = (
                UnitQuaternion::from_euler_angles(e.x, e.y, e.z),
                UnitQuaternion::from_euler_angles(c.x, c.y, c.z),
            );
            assert!(qa.angle_to(&qb) < 1e-12, "{e} -> {c}");
            let (r, p, y) = qb.euler_angles();
            assert!((Vector3::new(r, p, y) - c).norm() < 1e-9, "{c}");
        }
        let plain = Vector3::new(0.3, -0.7, 2.5);
        assert_eq!(canonical_euler(&plain), plain);
    }
}
