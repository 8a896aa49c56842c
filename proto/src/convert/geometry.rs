//! Geometric building blocks and ground truth.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use uavnav_core::{Lla, TruthSample};

use super::{ConvertError, finite, in_range, limits, required};
use crate::v1;

/// A finite 3-vector.
pub fn vector3(field: &str, v: &v1::Vector3) -> Result<Vector3<f64>, ConvertError> {
    let x = finite("x", v.x).map_err(|e| e.within(field))?;
    let y = finite("y", v.y).map_err(|e| e.within(field))?;
    let z = finite("z", v.z).map_err(|e| e.within(field))?;
    Ok(Vector3::new(x, y, z))
}

/// A required finite 3-vector.
pub fn required_vector3(
    field: &str,
    v: &Option<v1::Vector3>,
) -> Result<Vector3<f64>, ConvertError> {
    vector3(field, required(field, v)?)
}

/// A unit quaternion: finite, norm within [`limits::QUAT_NORM_TOL`] of 1, then normalised.
pub fn unit_quaternion(
    field: &str,
    q: &v1::Quaternion,
) -> Result<UnitQuaternion<f64>, ConvertError> {
    for (name, c) in [("w", q.w), ("x", q.x), ("y", q.y), ("z", q.z)] {
        finite(name, c).map_err(|e| e.within(field))?;
    }
    let raw = nalgebra::Quaternion::new(q.w, q.x, q.y, q.z);
    let norm = raw.norm();
    if (norm - 1.0).abs() > limits::QUAT_NORM_TOL {
        return Err(ConvertError::OutOfRange {
            field: field.to_owned(),
            value: norm,
            range: format!("norm 1 ± {}", limits::QUAT_NORM_TOL),
        });
    }
    // Already unit to rounding: keep the bits, so core → wire → core (and recordings) round-trip
    // exactly; otherwise normalise.
    if (norm - 1.0).abs() <= 4.0 * f64::EPSILON {
        Ok(UnitQuaternion::new_unchecked(raw))
    } else {
        Ok(UnitQuaternion::from_quaternion(raw))
    }
}

/// A required unit quaternion.
pub fn required_quaternion(
    field: &str,
    q: &Option<v1::Quaternion>,
) -> Result<UnitQuaternion<f64>, ConvertError> {
    unit_quaternion(field, required(field, q)?)
}

/// A rigid transform `a_from_b`.
pub fn isometry(field: &str, t: &v1::RigidTransform) -> Result<Isometry3<f64>, ConvertError> {
    let rotation = required_quaternion("rotation", &t.rotation).map_err(|e| e.within(field))?;
    let translation =
        required_vector3("translation_m", &t.translation_m).map_err(|e| e.within(field))?;
    Ok(Isometry3::from_parts(
        Translation3::from(translation),
        rotation,
    ))
}

impl From<&Vector3<f64>> for v1::Vector3 {
    fn from(v: &Vector3<f64>) -> Self {
        v1::Vector3 {
            x: v.x,
            y: v.y,
            z: v.z,
        }
    }
}

impl From<&UnitQuaternion<f64>> for v1::Quaternion {
    fn from(q: &UnitQuaternion<f64>) -> Self {
        v1::Quaternion {
            w: q.w,
            x: q.i,
            y: q.j,
            z: q.k,
        }
    }
}

impl From<&Isometry3<f64>> for v1::RigidTransform {
    fn from(t: &Isometry3<f64>) -> Self {
        v1::RigidTransform {
            rotation: Some((&t.rotation).into()),
            translation_m: Some((&t.translation.vector).into()),
        }
    }
}

impl TryFrom<&v1::GeodeticPosition> for Lla {
    type Error = ConvertError;
    fn try_from(p: &v1::GeodeticPosition) -> Result<Self, ConvertError> {
        let lat = in_range("latitude_deg", p.latitude_deg, -90.0, 90.0)?;
        let lon = in_range("longitude_deg", p.longitude_deg, -180.0, 180.0)?;
        let (lo, hi) = limits::ALT_RANGE_M;
        let alt = in_range("altitude_m", p.altitude_m, lo, hi)?;
        Ok(Lla::from_deg(lat, lon, alt))
    }
}

impl From<&Lla> for v1::GeodeticPosition {
    fn from(p: &Lla) -> Self {
        v1::GeodeticPosition {
            latitude_deg: p.lat_deg(),
            longitude_deg: p.lon_deg(),
            altitude_m: p.alt_m,
        }
    }
}

impl TryFrom<&v1::TruthSample> for TruthSample {
    type Error = ConvertError;
    fn try_from(s: &v1::TruthSample) -> Result<Self, ConvertError> {
        Ok(TruthSample {
            t_ns: s.t_ns,
            pos_ned_m: required_vector3("pos_ned_m", &s.pos_ned_m)?,
            nav_from_body: required_quaternion("nav_from_body", &s.nav_from_body)?,
            vel_ned_mps: required_vector3("vel_ned_mps", &s.vel_ned_mps)?,
            gyro_bias_radps: required_vector3("gyro_bias_radps", &s.gyro_bias_radps)?,
            accel_bias_mps2: required_vector3("accel_bias_mps2", &s.accel_bias_mps2)?,
        })
    }
}

impl From<&TruthSample> for v1::TruthSample {
    fn from(s: &TruthSample) -> Self {
        v1::TruthSample {
            t_ns: s.t_ns,
            pos_ned_m: Some((&s.pos_ned_m).into()),
            nav_from_body: Some((&s.nav_from_body).into()),
            vel_ned_mps: Some((&s.vel_ned_mps).into()),
            gyro_bias_radps: Some((&s.gyro_bias_radps).into()),
            accel_bias_mps2: Some((&s.accel_bias_mps2).into()),
        }
    }
}
