//! The Earth's main magnetic field from the World Magnetic Model WMM2025 (NOAA NCEI / BGS, epoch
//! 2025.0, valid 2025–2030; the Gauss coefficients below are the published model data).
//!
//! The estimator needs the local field's direction (declination, inclination) to turn a
//! magnetometer into a heading. The field is synthesised from the degree-12 spherical-harmonic
//! expansion of the geomagnetic potential:
//!
//! `V(r, θ, λ) = a Σₙ Σₘ (a/r)ⁿ⁺¹ (gₙᵐ cos mλ + hₙᵐ sin mλ) Pₙᵐ(cos θ)`
//!
//! with Schmidt semi-normalised associated Legendre functions `Pₙᵐ`, `a` = 6371.2 km, and
//! `B = −∇V` in geocentric spherical coordinates, rotated from the geocentric to the geodetic
//! vertical. Coefficients at a date are `g(t) = g + ġ (t − 2025.0)`; outside 2025–2030 the linear
//! secular variation is extrapolated, which degrades slowly (about 0.1–0.2° of declination per
//! year at mid latitudes): [`MagneticModel::years_outside_validity`] says by how much, so a caller
//! can widen its trust.

use nalgebra::Vector3;

use crate::geodesy::Lla;

/// Highest degree of the model.
const N_MAX: usize = 12;
/// Geomagnetic reference radius, m.
const REFERENCE_RADIUS_M: f64 = 6_371_200.0;
/// Epoch of the coefficients, decimal year.
pub const WMM_EPOCH_YEAR: f64 = 2025.0;
/// End of the model's validity, decimal year.
pub const WMM_END_YEAR: f64 = 2030.0;

/// WMM2025: `(n, m, g, h, ġ, ḣ)`, nT and nT/year.
#[rustfmt::skip]
const WMM2025: [(u8, u8, f64, f64, f64, f64); 90] = [
    (1, 0, -29351.8, 0.0, 12.0, 0.0), (1, 1, -1410.8, 4545.4, 9.7, -21.5),
    (2, 0, -2556.6, 0.0, -11.6, 0.0), (2, 1, 2951.1, -3133.6, -5.2, -27.7),
    (2, 2, 1649.3, -815.1, -8.0, -12.1),
    (3, 0, 1361.0, 0.0, -1.3, 0.0), (3, 1, -2404.1, -56.6, -4.2, 4.0),
    (3, 2, 1243.8, 237.5, 0.4, -0.3), (3, 3, 453.6, -549.5, -15.6, -4.1),
    (4, 0, 895.0, 0.0, -1.6, 0.0), (4, 1, 799.5, 278.6, -2.4, -1.1),
    (4, 2, 55.7, -133.9, -6.0, 4.1), (4, 3, -281.1, 212.0, 5.6, 1.6),
    (4, 4, 12.1, -375.6, -7.0, -4.4),
    (5, 0, -233.2, 0.0, 0.6, 0.0), (5, 1, 368.9, 45.4, 1.4, -0.5),
    (5, 2, 187.2, 220.2, 0.0, 2.2), (5, 3, -138.7, -122.9, 0.6, 0.4),
    (5, 4, -142.0, 43.0, 2.2, 1.7), (5, 5, 20.9, 106.1, 0.9, 1.9),
    (6, 0, 64.4, 0.0, -0.2, 0.0), (6, 1, 63.8, -18.4, -0.4, 0.3),
    (6, 2, 76.9, 16.8, 0.9, -1.6), (6, 3, -115.7, 48.8, 1.2, -0.4),
    (6, 4, -40.9, -59.8, -0.9, 0.9), (6, 5, 14.9, 10.9, 0.3, 0.7),
    (6, 6, -60.7, 72.7, 0.9, 0.9),
    (7, 0, 79.5, 0.0, -0.0, 0.0), (7, 1, -77.0, -48.9, -0.1, 0.6),
    (7, 2, -8.8, -14.4, -0.1, 0.5), (7, 3, 59.3, -1.0, 0.5, -0.8),
    (7, 4, 15.8, 23.4, -0.1, 0.0), (7, 5, 2.5, -7.4, -0.8, -1.0),
    (7, 6, -11.1, -25.1, -0.8, 0.6), (7, 7, 14.2, -2.3, 0.8, -0.2),
    (8, 0, 23.2, 0.0, -0.1, 0.0), (8, 1, 10.8, 7.1, 0.2, -0.2),
    (8, 2, -17.5, -12.6, 0.0, 0.5), (8, 3, 2.0, 11.4, 0.5, -0.4),
    (8, 4, -21.7, -9.7, -0.1, 0.4), (8, 5, 16.9, 12.7, 0.3, -0.5),
    (8, 6, 15.0, 0.7, 0.2, -0.6), (8, 7, -16.8, -5.2, -0.0, 0.3),
    (8, 8, 0.9, 3.9, 0.2, 0.2),
    (9, 0, 4.6, 0.0, -0.0, 0.0), (9, 1, 7.8, -24.8, -0.1, -0.3),
    (9, 2, 3.0, 12.2, 0.1, 0.3), (9, 3, -0.2, 8.3, 0.3, -0.3),
    (9, 4, -2.5, -3.3, -0.3, 0.3), (9, 5, -13.1, -5.2, 0.0, 0.2),
    (9, 6, 2.4, 7.2, 0.3, -0.1), (9, 7, 8.6, -0.6, -0.1, -0.2),
    (9, 8, -8.7, 0.8, 0.1, 0.4), (9, 9, -12.9, 10.0, -0.1, 0.1),
    (10, 0, -1.3, 0.0, 0.1, 0.0), (10, 1, -6.4, 3.3, 0.0, 0.0),
    (10, 2, 0.2, 0.0, 0.1, -0.0), (10, 3, 2.0, 2.4, 0.1, -0.2),
    (10, 4, -1.0, 5.3, -0.0, 0.1), (10, 5, -0.6, -9.1, -0.3, -0.1),
    (10, 6, -0.9, 0.4, 0.0, 0.1), (10, 7, 1.5, -4.2, -0.1, 0.0),
    (10, 8, 0.9, -3.8, -0.1, -0.1), (10, 9, -2.7, 0.9, -0.0, 0.2),
    (10, 10, -3.9, -9.1, -0.0, -0.0),
    (11, 0, 2.9, 0.0, 0.0, 0.0), (11, 1, -1.5, 0.0, -0.0, -0.0),
    (11, 2, -2.5, 2.9, 0.0, 0.1), (11, 3, 2.4, -0.6, 0.0, -0.0),
    (11, 4, -0.6, 0.2, 0.0, 0.1), (11, 5, -0.1, 0.5, -0.1, -0.0),
    (11, 6, -0.6, -0.3, 0.0, -0.0), (11, 7, -0.1, -1.2, -0.0, 0.1),
    (11, 8, 1.1, -1.7, -0.1, -0.0), (11, 9, -1.0, -2.9, -0.1, 0.0),
    (11, 10, -0.2, -1.8, -0.1, 0.0), (11, 11, 2.6, -2.3, -0.1, 0.0),
    (12, 0, -2.0, 0.0, 0.0, 0.0), (12, 1, -0.2, -1.3, 0.0, -0.0),
    (12, 2, 0.3, 0.7, -0.0, 0.0), (12, 3, 1.2, 1.0, -0.0, -0.1),
    (12, 4, -1.3, -1.4, -0.0, 0.1), (12, 5, 0.6, -0.0, -0.0, -0.0),
    (12, 6, 0.6, 0.6, 0.1, -0.0), (12, 7, 0.5, -0.1, -0.0, -0.0),
    (12, 8, -0.1, 0.8, 0.0, 0.0), (12, 9, -0.4, 0.1, 0.0, -0.0),
    (12, 10, -0.2, -1.0, -0.1, -0.0), (12, 11, -1.3, 0.1, -0.0, 0.0),
    (12, 12, -0.7, 0.2, -0.1, -0.1),
];

/// The local main field at one place and date.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MagneticField {
    /// Flux density in local NED, T.
    pub ned_t: Vector3<f64>,
}

impl MagneticField {
    /// Declination (east of true north positive), rad.
    pub fn declination_rad(&self) -> f64 {
        self.ned_t.y.atan2(self.ned_t.x)
    }

    /// Inclination (down positive), rad.
    pub fn inclination_rad(&self) -> f64 {
        self.ned_t.z.atan2(self.ned_t.xy().norm())
    }

    /// Total intensity, T.
    pub fn strength_t(&self) -> f64 {
        self.ned_t.norm()
    }
}

/// The WMM2025 main-field model.
#[derive(Debug, Clone, Copy, Default)]
pub struct MagneticModel;

impl MagneticModel {
    /// Years by which `year` lies outside the model's validity (0 inside 2025–2030).
    pub fn years_outside_validity(year: f64) -> f64 {
        if year < WMM_EPOCH_YEAR {
            WMM_EPOCH_YEAR - year
        } else {
            (year - WMM_END_YEAR).max(0.0)
        }
    }

    /// The field at a geodetic position (height above the ellipsoid) and decimal year.
    pub fn field(lla: &Lla, year: f64) -> MagneticField {
        let dt_years = year - WMM_EPOCH_YEAR;
        // Geodetic → geocentric spherical (WGS84).
        const A: f64 = 6_378_137.0;
        const E2: f64 = 6.694_379_990_14e-3;
        let (sin_lat, cos_lat) = lla.lat_rad.sin_cos();
        let rn = A / (1.0 - E2 * sin_lat * sin_lat).sqrt();
        let p = (rn + lla.alt_m) * cos_lat;
        let z = (rn * (1.0 - E2) + lla.alt_m) * sin_lat;
        let r = p.hypot(z);
        let lat_gc = z.atan2(p);
        // x = cos θ (θ the geocentric colatitude) = sin of the geocentric latitude.
        let (x, s) = lat_gc.sin_cos();

        let (pnm, dpnm) = schmidt_legendre(x, s);
        let (sin_l, cos_l) = lla.lon_rad.sin_cos();
        let mut cos_ml = [0.0; N_MAX + 1];
        let mut sin_ml = [0.0; N_MAX + 1];
        cos_ml[0] = 1.0;
        for m in 1..=N_MAX {
            cos_ml[m] = cos_ml[m - 1] * cos_l - sin_ml[m - 1] * sin_l;
            sin_ml[m] = sin_ml[m - 1] * cos_l + cos_ml[m - 1] * sin_l;
        }
        let ratio = REFERENCE_RADIUS_M / r;
        // B = −∇V: north = (1/r) ∂V/∂θ, east = −(1/(r sin θ)) ∂V/∂λ, down = ∂V/∂r.
        let (mut north, mut east_s, mut down) = (0.0, 0.0, 0.0);
        for &(n, m, g0, h0, gd, hd) in &WMM2025 {
            let (n, m) = (usize::from(n), usize::from(m));
            let g = g0 + gd * dt_years;
            let h = h0 + hd * dt_years;
            let rn2 = ratio.powi(n as i32 + 2);
            let gc = g * cos_ml[m] + h * sin_ml[m];
            let gs = g * sin_ml[m] - h * cos_ml[m];
            north += rn2 * gc * dpnm[n][m];
            east_s += rn2 * m as f64 * gs * pnm[n][m];
            down -= rn2 * (n as f64 + 1.0) * gc * pnm[n][m];
        }
        // At the poles sin θ → 0; the model is not used there (the heading is meaningless).
        let east = if s.abs() > 1e-9 { east_s / s } else { 0.0 };
        // Rotate from the geocentric to the geodetic vertical.
        let psi = lat_gc - lla.lat_rad;
        let (sp, cp) = psi.sin_cos();
        let north_gd = north * cp - down * sp;
        let down_gd = north * sp + down * cp;
        MagneticField {
            ned_t: Vector3::new(north_gd, east, down_gd) * 1e-9,
        }
    }
}

type Table = [[f64; N_MAX + 1]; N_MAX + 1];

/// Schmidt semi-normalised `Pₙᵐ(cos θ)` and `∂Pₙᵐ/∂θ` for `x = cos θ`, `s = sin θ`: the Gauss
/// recursion, then the Schmidt factors `Sₙ,₀ = Sₙ₋₁,₀ (2n−1)/n`,
/// `Sₙ,ₘ = Sₙ,ₘ₋₁ √((n−m+1)(δₘ₁+1)/(n+m))`.
fn schmidt_legendre(x: f64, s: f64) -> (Table, Table) {
    let mut p = [[0.0; N_MAX + 1]; N_MAX + 1];
    let mut dp = [[0.0; N_MAX + 1]; N_MAX + 1];
    p[0][0] = 1.0;
    for n in 1..=N_MAX {
        for m in 0..=n {
            if n == m {
                p[n][m] = s * p[n - 1][m - 1];
                dp[n][m] = s * dp[n - 1][m - 1] + x * p[n - 1][m - 1];
            } else if n == 1 {
                p[n][m] = x;
                dp[n][m] = -s;
            } else {
                let k = if n >= 2 && m + 2 <= n {
                    (((n - 1) * (n - 1) - m * m) as f64) / (((2 * n - 1) * (2 * n - 3)) as f64)
                } else {
                    0.0
                };
                let (p2, dp2) = if m + 2 <= n {
                    (p[n - 2][m], dp[n - 2][m])
                } else {
                    (0.0, 0.0)
                };
                p[n][m] = x * p[n - 1][m] - k * p2;
                dp[n][m] = x * dp[n - 1][m] - s * p[n - 1][m] - k * dp2;
            }
        }
    }
    let mut sch = [[0.0; N_MAX + 1]; N_MAX + 1];
    sch[0][0] = 1.0;
    for n in 1..=N_MAX {
        sch[n][0] = sch[n - 1][0] * (2 * n - 1) as f64 / n as f64;
        for m in 1..=n {
            let delta = if m == 1 { 2.0 } else { 1.0 };
            sch[n][m] = sch[n][m - 1] * ((n - m + 1) as f64 * delta / (n + m) as f64).sqrt();
        }
    }
    for n in 0..=N_MAX {
        for m in 0..=n {
            p[n][m] *= sch[n][m];
            dp[n][m] *= sch[n][m];
        }
    }
    (p, dp)
}

/// Decimal year of a UNIX time in ns (UTC; leap seconds do not matter at this resolution).
pub fn decimal_year(t_unix_ns: i64) -> f64 {
    let days = t_unix_ns.div_euclid(86_400 * 1_000_000_000);
    let (y, doy) = year_and_day(days);
    let len = if is_leap(y) { 366.0 } else { 365.0 };
    let day_frac = t_unix_ns.rem_euclid(86_400 * 1_000_000_000) as f64 / 86_400e9;
    y as f64 + (doy as f64 + day_frac) / len
}

fn is_leap(y: i64) -> bool {
    (y % 4 == 0 && y % 100 != 0) || y % 400 == 0
}

/// (year, day of year from 0) of a day count since 1970-01-01.
fn year_and_day(mut days: i64) -> (i64, i64) {
    let mut y = 1970;
    loop {
        let len = if is_leap(y) { 366 } else { 365 };
        if days < 0 {
            y -= 1;
            days += if is_leap(y) { 366 } else { 365 };
        } else if days >= len {
            days -= len;
            y += 1;
        } else {
            return (y, days);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimal_year_of_known_dates() {
        assert!((decimal_year(0) - 1970.0).abs() < 1e-12);
        // 2014-12-05 10:54:52 UTC (the shared copter_218 flight)
        let t = 1_417_776_892_000_000_000_i64;
        let y = decimal_year(t);
        assert!(
            (y - (2014.0 + (338.0 + 10.914 / 24.0) / 365.0)).abs() < 1e-4,
            "{y}"
        );
        // 2024-03-01 00:00 UTC: a leap year, day 60
        assert!((decimal_year(1_709_251_200_000_000_000) - (2024.0 + 60.0 / 366.0)).abs() < 1e-9);
    }

    #[test]
    fn field_in_northern_spain_matches_the_published_model_values() {
        // 42.85° N, 2.65° W, 600 m: the place of the shared real flights. IGRF for 2014-12 gives
        // inclination 58.1°, declination −0.9°, 45.7 µT; WMM2025 extrapolated back 10 years must
        // land within its secular-variation error of that.
        let lla = Lla::from_deg(42.85, -2.65, 600.0);
        let f = MagneticModel::field(&lla, 2014.93);
        assert!(
            (f.inclination_rad().to_degrees() - 58.1).abs() < 0.6,
            "{f:?}"
        );
        assert!(
            (f.declination_rad().to_degrees() + 0.9).abs() < 1.0,
            "{f:?}"
        );
        assert!((f.strength_t() * 1e6 - 45.7).abs() < 0.6, "{f:?}");
        // and in 2025 the declination there has turned east (about +0.6°)
        let f25 = MagneticModel::field(&lla, 2025.5);
        assert!(f25.declination_rad() > f.declination_rad());
    }

    #[test]
    fn dipole_dominates_far_from_the_earth_and_points_down_in_the_north() {
        let north = MagneticModel::field(&Lla::from_deg(60.0, 10.0, 0.0), 2026.0);
        let south = MagneticModel::field(&Lla::from_deg(-60.0, 10.0, 0.0), 2026.0);
        assert!(north.ned_t.z > 0.0 && south.ned_t.z < 0.0);
        let s = north.strength_t();
        assert!((30e-6..70e-6).contains(&s), "{s}");
        // ~1/r³ with height
        let high = MagneticModel::field(&Lla::from_deg(60.0, 10.0, 6_371_000.0), 2026.0);
        let r = high.strength_t() / s;
        assert!((0.10..0.16).contains(&r), "{r}");
    }

    #[test]
    fn validity_window() {
        assert_eq!(MagneticModel::years_outside_validity(2027.0), 0.0);
        assert!((MagneticModel::years_outside_validity(2014.9) - 10.1).abs() < 1e-9);
        assert!((MagneticModel::years_outside_validity(2031.0) - 1.0).abs() < 1e-9);
    }
}
