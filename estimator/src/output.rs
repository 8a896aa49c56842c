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

/// Roll/pitch/yaw σ from the global (NED) attitude-error covariance:
/// `δ(φ,θ,ψ) = J(φ,θ) Cᵀ δθⁿ` (a nav-frame error is the body-frame error `Cᵀ δθⁿ`).
pub fn euler_sigma(q: &UnitQuaternion<f64>, cov_th: &nalgebra::Matrix3<f64>) -> Vector3<f64> {
    let (roll, pitch, _) = q.euler_angles();
    let m = euler_rate_matrix(roll, pitch) * q.to_rotation_matrix().matrix().transpose();
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
