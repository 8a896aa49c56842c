//! EGM96 geoid undulation and the two altitude references a log or a dataset may use.
//!
//! uavnav's contract is height above the WGS84 ellipsoid; autopilots log altitude above mean sea
//! level (ArduPilot `GPS.Alt`, `AHR2.Alt`, PX4's old `alt`), which differs by the geoid undulation
//! `N` (`h = H_msl + N`, about +51 m in northern Spain, −30 m over India): reading one as the other
//! is a silent vertical bias.
//!
//! `N` comes from the EGM96 spherical-harmonic model (degree 360), whose coefficients the `egm96`
//! crate compiles in (its default features download raster maps at build time, so they are off).
//! The model is evaluated at the four surrounding nodes of the 15′ grid and interpolated
//! bilinearly: that is how NGA's published `WW15MGH.GRD` grid and the `egm96_15.gtx` file that
//! GDAL/PROJ and the shared dataset conversions use are read, so the values agree with them to
//! well under a millimetre (the harmonic value at the point itself differs from the grid's
//! interpolation by up to a few centimetres, as does NGA's own spline interpolation program). A synthesis costs ~2 ms, so the last grid cell's
//! node values are cached per thread: a flight stays in one or two cells.

use std::cell::Cell;

/// Grid spacing of the interpolation, degrees (the published 15′ grid).
const STEP_DEG: f64 = 0.25;

/// A cell's (row, column) and its node values (south-west, south-east, north-west, north-east).
type CachedCell = Option<((i64, i64), [f64; 4])>;

thread_local! {
    /// The last cell used. Only a cache: results do not depend on it.
    static LAST_CELL: Cell<CachedCell> = const { Cell::new(None) };
}

/// EGM96 geoid undulation `N` (geoid height above the WGS84 ellipsoid), m, at a geodetic latitude
/// and longitude in degrees (any longitude; latitude clamped to ±90°). NaN for non-finite input.
pub fn egm96_undulation_m(lat_deg: f64, lon_deg: f64) -> f64 {
    if !lat_deg.is_finite() || !lon_deg.is_finite() {
        return f64::NAN;
    }
    let lat = lat_deg.clamp(-90.0, 90.0);
    let lon = (lon_deg + 180.0).rem_euclid(360.0) - 180.0;
    // The cell's south-west node; at the pole the cell below is used (its north edge is the pole).
    let row = ((lat / STEP_DEG).floor() as i64).min(359);
    let col = (lon / STEP_DEG).floor() as i64;
    let lat0 = row as f64 * STEP_DEG;
    let lon0 = col as f64 * STEP_DEG;
    let nodes = LAST_CELL.with(|c| match c.get() {
        Some((key, n)) if key == (row, col) => n,
        _ => {
            let n = [
                egm96::egm96_compute_altitude_offset(lat0, lon0),
                egm96::egm96_compute_altitude_offset(lat0, lon0 + STEP_DEG),
                egm96::egm96_compute_altitude_offset(lat0 + STEP_DEG, lon0),
                egm96::egm96_compute_altitude_offset(lat0 + STEP_DEG, lon0 + STEP_DEG),
            ];
            c.set(Some(((row, col), n)));
            n
        }
    });
    let fy = ((lat - lat0) / STEP_DEG).clamp(0.0, 1.0);
    let fx = ((lon - lon0) / STEP_DEG).clamp(0.0, 1.0);
    let south = nodes[0] + fx * (nodes[1] - nodes[0]);
    let north = nodes[2] + fx * (nodes[3] - nodes[2]);
    south + fy * (north - south)
}

/// What a source's altitude is measured from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum AltitudeReference {
    /// Height above the WGS84 ellipsoid (uavnav's own convention).
    #[default]
    Ellipsoid,
    /// Height above mean sea level (the EGM96 geoid), as most autopilots log it.
    Msl,
}

impl AltitudeReference {
    /// The configuration / CLI name: `ellipsoid` or `msl`.
    pub fn as_str(self) -> &'static str {
        match self {
            AltitudeReference::Ellipsoid => "ellipsoid",
            AltitudeReference::Msl => "msl",
        }
    }

    /// Converts an altitude in this reference at (`lat_deg`, `lon_deg`) to height above the WGS84
    /// ellipsoid, m.
    pub fn to_ellipsoid(self, lat_deg: f64, lon_deg: f64, alt_m: f64) -> f64 {
        match self {
            AltitudeReference::Ellipsoid => alt_m,
            AltitudeReference::Msl => alt_m + egm96_undulation_m(lat_deg, lon_deg),
        }
    }
}

impl std::str::FromStr for AltitudeReference {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "ellipsoid" => Ok(AltitudeReference::Ellipsoid),
            "msl" => Ok(AltitudeReference::Msl),
            other => Err(format!(
                "unknown altitude reference '{other}' (expected ellipsoid or msl)"
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Grid nodes (published `WW15MGH.GRD` values, 3 decimals) and the shared 218 conversion's
    /// `geoid_n_m` (bilinear on `egm96_15.gtx`): millimetres.
    #[test]
    fn grid_values() {
        let cases = [
            (0.0, 0.0, 17.162),
            (90.0, 0.0, 13.606),
            (-90.0, 0.0, -29.534),
            (42.85377093685107, -2.6449947771975717, 51.19534793132853),
        ];
        for (lat, lon, n) in cases {
            let got = egm96_undulation_m(lat, lon);
            assert!(
                (got - n).abs() < 0.002,
                "N({lat}, {lon}) = {got}, expected {n}"
            );
        }
    }

    /// NGA's check values of its own interpolation program (`outintpt.dat` of the EGM96
    /// distribution): that program fits a spline over a 6×6 window, bilinear differs by up to
    /// ~6 cm between nodes where the geoid bends sharply.
    #[test]
    fn nga_interpolation_check_values() {
        let cases = [
            (38.628155, 269.779155, -31.628),
            (-14.621217, 305.021114, -2.969),
            (46.874319, 102.448729, -43.575),
            (-23.617446, 133.874712, 15.871),
            (38.625473, 359.999500, 50.066),
            (-0.466999, 0.002300, 17.329),
        ];
        for (lat, lon, n) in cases {
            let got = egm96_undulation_m(lat, lon);
            assert!(
                (got - n).abs() < 0.08,
                "N({lat}, {lon}) = {got}, expected {n}"
            );
        }
    }

    #[test]
    fn reference_names_round_trip() {
        for r in [AltitudeReference::Ellipsoid, AltitudeReference::Msl] {
            assert_eq!(r.as_str().parse::<AltitudeReference>(), Ok(r));
        }
        assert!("wgs84".parse::<AltitudeReference>().is_err());
        let h = AltitudeReference::Msl.to_ellipsoid(0.0, 0.0, 100.0);
        assert!((h - 117.162).abs() < 0.002);
        assert_eq!(
            AltitudeReference::Ellipsoid.to_ellipsoid(0.0, 0.0, 100.0),
            100.0
        );
        assert!(egm96_undulation_m(f64::NAN, 0.0).is_nan());
    }
}
