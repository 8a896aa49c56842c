//! WGS84 geodesy: geodetic (LLA) ↔ ECEF ↔ local NED, normal gravity and radii of curvature.
//!
//! The paper's reference systems (section II): `e` = ECEF, `n` = NED tangent to the ellipsoid at a
//! reference latitude/longitude. `C_e^n` below is the paper's rotation from ECEF to that NED.

use nalgebra::{Matrix3, Vector3};

/// WGS84 semi-major axis, m.
pub const WGS84_A: f64 = 6_378_137.0;
/// WGS84 flattening.
pub const WGS84_F: f64 = 1.0 / 298.257_223_563;
/// WGS84 first eccentricity squared.
pub const WGS84_E2: f64 = WGS84_F * (2.0 - WGS84_F);
/// WGS84 semi-minor axis, m.
pub const WGS84_B: f64 = WGS84_A * (1.0 - WGS84_F);
/// Earth rotation rate, rad/s.
pub const OMEGA_EARTH_RADPS: f64 = 7.292_115e-5;
/// Somigliana normal gravity at the equator, m/s².
const GAMMA_E: f64 = 9.780_325_335_9;
/// Somigliana constant k = (b·γp)/(a·γe) − 1.
const SOMIGLIANA_K: f64 = 0.001_931_852_652_41;
/// WGS84 m = ω²a²b/GM, for the free-air height correction.
const WGS84_M: f64 = 0.003_449_786_003_08;

/// A geodetic position on WGS84.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lla {
    /// Latitude, rad.
    pub lat_rad: f64,
    /// Longitude, rad.
    pub lon_rad: f64,
    /// Height above the ellipsoid, m.
    pub alt_m: f64,
}

impl Lla {
    /// From degrees (the edge unit) and metres.
    pub fn from_deg(lat_deg: f64, lon_deg: f64, alt_m: f64) -> Self {
        Self {
            lat_rad: lat_deg.to_radians(),
            lon_rad: lon_deg.to_radians(),
            alt_m,
        }
    }

    /// Latitude in degrees.
    pub fn lat_deg(&self) -> f64 {
        self.lat_rad.to_degrees()
    }

    /// Longitude in degrees.
    pub fn lon_deg(&self) -> f64 {
        self.lon_rad.to_degrees()
    }
}

/// Prime-vertical radius of curvature N(φ), m.
pub fn radius_prime_vertical(lat_rad: f64) -> f64 {
    let s = lat_rad.sin();
    WGS84_A / (1.0 - WGS84_E2 * s * s).sqrt()
}

/// Meridian radius of curvature M(φ), m.
pub fn radius_meridian(lat_rad: f64) -> f64 {
    let s = lat_rad.sin();
    WGS84_A * (1.0 - WGS84_E2) / (1.0 - WGS84_E2 * s * s).powf(1.5)
}

/// Geodetic → ECEF, m.
pub fn lla_to_ecef(p: &Lla) -> Vector3<f64> {
    let n = radius_prime_vertical(p.lat_rad);
    let (sl, cl) = p.lat_rad.sin_cos();
    let (so, co) = p.lon_rad.sin_cos();
    Vector3::new(
        (n + p.alt_m) * cl * co,
        (n + p.alt_m) * cl * so,
        (n * (1.0 - WGS84_E2) + p.alt_m) * sl,
    )
}

/// ECEF → geodetic, by Bowring's initial guess and Newton refinement (sub-millimetre anywhere
/// from the Earth's centre region excluded to orbit).
pub fn ecef_to_lla(x: &Vector3<f64>) -> Lla {
    let lon = x.y.atan2(x.x);
    let p = (x.x * x.x + x.y * x.y).sqrt();
    if p < 1e-9 {
        // On the polar axis.
        let lat = if x.z >= 0.0 {
            std::f64::consts::FRAC_PI_2
        } else {
            -std::f64::consts::FRAC_PI_2
        };
        return Lla {
            lat_rad: lat,
            lon_rad: 0.0,
            alt_m: x.z.abs() - WGS84_B,
        };
    }
    let ep2 = WGS84_E2 / (1.0 - WGS84_E2);
    let theta = (x.z * WGS84_A).atan2(p * WGS84_B);
    let (st, ct) = theta.sin_cos();
    let mut lat = (x.z + ep2 * WGS84_B * st.powi(3)).atan2(p - WGS84_E2 * WGS84_A * ct.powi(3));
    let mut alt = 0.0;
    for _ in 0..3 {
        let n = radius_prime_vertical(lat);
        let (sl, cl) = lat.sin_cos();
        alt = if cl.abs() > 1e-3 {
            p / cl - n
        } else {
            x.z / sl - n * (1.0 - WGS84_E2)
        };
        lat = (x.z / p / (1.0 - WGS84_E2 * n / (n + alt))).atan();
    }
    Lla {
        lat_rad: lat,
        lon_rad: lon,
        alt_m: alt,
    }
}

/// `C_e^n`: rotation taking ECEF vectors into NED at (lat, lon).
pub fn ned_from_ecef(lat_rad: f64, lon_rad: f64) -> Matrix3<f64> {
    let (sl, cl) = lat_rad.sin_cos();
    let (so, co) = lon_rad.sin_cos();
    Matrix3::new(
        -sl * co,
        -sl * so,
        cl, //
        -so,
        co,
        0.0, //
        -cl * co,
        -cl * so,
        -sl,
    )
}

/// Normal gravity magnitude (Somigliana with the free-air correction), m/s², positive.
pub fn normal_gravity(lat_rad: f64, alt_m: f64) -> f64 {
    let s2 = lat_rad.sin().powi(2);
    let g0 = GAMMA_E * (1.0 + SOMIGLIANA_K * s2) / (1.0 - WGS84_E2 * s2).sqrt();
    let h = alt_m;
    g0 * (1.0 - 2.0 / WGS84_A * (1.0 + WGS84_F + WGS84_M - 2.0 * WGS84_F * s2) * h
        + 3.0 / (WGS84_A * WGS84_A) * h * h)
}

/// A local NED tangent frame fixed at an origin (the paper's `n` frame at a reference LLA).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalFrame {
    origin: Lla,
    origin_ecef: Vector3<f64>,
    ned_from_ecef: Matrix3<f64>,
}

impl LocalFrame {
    /// The NED frame tangent to the ellipsoid at `origin` (its origin at `origin`'s height).
    pub fn new(origin: Lla) -> Self {
        Self {
            origin,
            origin_ecef: lla_to_ecef(&origin),
            ned_from_ecef: ned_from_ecef(origin.lat_rad, origin.lon_rad),
        }
    }

    /// The origin.
    pub fn origin(&self) -> Lla {
        self.origin
    }

    /// Geodetic → local NED, m.
    pub fn lla_to_ned(&self, p: &Lla) -> Vector3<f64> {
        self.ned_from_ecef * (lla_to_ecef(p) - self.origin_ecef)
    }

    /// Local NED, m → geodetic.
    pub fn ned_to_lla(&self, ned_m: &Vector3<f64>) -> Lla {
        ecef_to_lla(&(self.origin_ecef + self.ned_from_ecef.transpose() * ned_m))
    }

    /// Gravity vector (pointing down, mostly +D) at a local NED position, m/s², expressed in this
    /// frame. Includes the tilt of the local vertical away from the origin.
    pub fn gravity_ned(&self, ned_m: &Vector3<f64>) -> Vector3<f64> {
        let lla = self.ned_to_lla(ned_m);
        let g = normal_gravity(lla.lat_rad, lla.alt_m);
        // Local "down" at that point, rotated into this frame.
        let down_ecef = ned_from_ecef(lla.lat_rad, lla.lon_rad).transpose() * Vector3::z();
        self.ned_from_ecef * down_ecef * g
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn known_points() {
        let e = lla_to_ecef(&Lla::from_deg(0.0, 0.0, 0.0));
        assert!((e - Vector3::new(WGS84_A, 0.0, 0.0)).norm() < 1e-6);
        let n = lla_to_ecef(&Lla::from_deg(90.0, 0.0, 0.0));
        assert!((n - Vector3::new(0.0, 0.0, WGS84_B)).norm() < 1e-6);
        // Normal gravity at the equator and pole (WGS84 published values).
        assert!((normal_gravity(0.0, 0.0) - 9.780_325_3).abs() < 1e-6);
        assert!((normal_gravity(std::f64::consts::FRAC_PI_2, 0.0) - 9.832_184_9).abs() < 1e-6);
        // Free-air gradient ≈ −3.086e-6 s⁻² at mid latitudes.
        let dg = normal_gravity(0.8, 1000.0) - normal_gravity(0.8, 0.0);
        assert!((dg + 3.086e-3).abs() < 2e-5, "{dg}");
    }

    #[test]
    fn ned_axes() {
        let f = LocalFrame::new(Lla::from_deg(41.1, 14.2, 100.0));
        let up = f.ned_to_lla(&Vector3::new(0.0, 0.0, -10.0));
        assert!((up.alt_m - 110.0).abs() < 1e-6);
        let north = f.ned_to_lla(&Vector3::new(100.0, 0.0, 0.0));
        assert!(north.lat_rad > f.origin().lat_rad);
        let east = f.ned_to_lla(&Vector3::new(0.0, 100.0, 0.0));
        assert!(east.lon_rad > f.origin().lon_rad);
        let g = f.gravity_ned(&Vector3::zeros());
        assert!(g.x.abs() < 1e-9 && g.y.abs() < 1e-9 && g.z > 9.7);
    }

    proptest! {
        #[test]
        fn lla_ecef_round_trip(lat in -89.9f64..89.9, lon in -180.0f64..180.0, alt in -500.0f64..20_000.0) {
            let p = Lla::from_deg(lat, lon, alt);
            let q = ecef_to_lla(&lla_to_ecef(&p));
            let err = lla_to_ecef(&q) - lla_to_ecef(&p);
            prop_assert!(err.norm() < 1e-3);
            prop_assert!((q.alt_m - alt).abs() < 1e-3);
        }

        #[test]
        fn ned_round_trip(n in -50_000.0f64..50_000.0, e in -50_000.0f64..50_000.0, d in -5_000.0f64..500.0) {
            let f = LocalFrame::new(Lla::from_deg(40.8, 14.3, 50.0));
            let x = Vector3::new(n, e, d);
            let back = f.lla_to_ned(&f.ned_to_lla(&x));
            prop_assert!((back - x).norm() < 1e-3);
        }
    }
}
