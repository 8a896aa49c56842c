//! The estimator's output vocabulary (`uavnav_core::output`) ↔ the wire `PoseEstimate`, both
//! directions, every field of [`PoseOutput`] carried.
//!
//! Core → wire → core gives back every field bit for bit except latitude and longitude, which the
//! wire carries in degrees (the radian ↔ degree round trip may move the last bit). The wire adds
//! what a core pose does not hold: `vehicle_id`, `ingest_wall_ns` and the optional
//! `covariance_9x9` (left empty here).
//!
//! The service sends a compact pose (no `pos_ned_m`, biases or per-pose health: those are on its
//! health stream); wire → core reads their absence as zero / default, so a pose received from the
//! service converts too.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use uavnav_core::output::{HeadingHealth, HeadingSource, MagCalibrationStatus, MagStatus};
use uavnav_core::{AidingFlags, Lla, Mode, PoseHealth, PoseOutput, SourceSummary};

use super::geometry::{required_vector3, vector3};
use super::{ConvertError, finite, non_negative, required};
use crate::v1;

/// Estimator mode → wire.
pub fn mode_to_wire(m: Mode) -> v1::EstimatorMode {
    match m {
        Mode::Initialising => v1::EstimatorMode::Initialising,
        Mode::Nominal => v1::EstimatorMode::Nominal,
        Mode::GnssDeniedVision => v1::EstimatorMode::GnssDeniedVision,
        Mode::InertialOnly => v1::EstimatorMode::InertialOnly,
        Mode::Diverged => v1::EstimatorMode::Diverged,
        Mode::AttitudeOnly => v1::EstimatorMode::AttitudeOnly,
    }
}

/// The heading's health → wire (`VehicleHealth.heading`), with the heading resets to the yaw bank.
pub fn heading_to_wire(h: &HeadingHealth, yaw_resets: u32) -> v1::HeadingStatus {
    let HeadingHealth {
        source,
        mag,
        mag_disturbed,
        mag_calibration,
        mag_offset_t,
        mag_calibration_test_ratio,
        mag_calibration_restarts,
    } = *h;
    let source = match source {
        HeadingSource::Unknown => v1::HeadingSource::Unknown,
        HeadingSource::Magnetometer => v1::HeadingSource::Magnetometer,
        HeadingSource::YawEstimator => v1::HeadingSource::YawEstimator,
        HeadingSource::Course => v1::HeadingSource::Course,
    };
    let mag = match mag {
        MagStatus::Off => v1::MagnetometerState::Off,
        MagStatus::Active => v1::MagnetometerState::Active,
        MagStatus::StoppedDead => v1::MagnetometerState::StoppedDead,
        MagStatus::StoppedContradicted => v1::MagnetometerState::StoppedContradicted,
    };
    let calibration = match mag_calibration {
        MagCalibrationStatus::Off => v1::MagnetometerCalibration::Off,
        MagCalibrationStatus::Learning => v1::MagnetometerCalibration::Learning,
        MagCalibrationStatus::Applied => v1::MagnetometerCalibration::Applied,
    };
    let [x, y, z] = mag_offset_t;
    v1::HeadingStatus {
        source: source as i32,
        magnetometer: mag as i32,
        magnetometer_disturbed: mag_disturbed,
        yaw_resets,
        magnetometer_calibration: calibration as i32,
        magnetometer_offset_t: (mag_calibration != MagCalibrationStatus::Off)
            .then_some(v1::Vector3 { x, y, z }),
        magnetometer_calibration_test_ratio: mag_calibration_test_ratio,
        magnetometer_calibration_restarts: mag_calibration_restarts,
    }
}

/// Wire → estimator mode; `UNSPECIFIED` and unknown values are refused (the service never sends
/// them).
pub fn mode_from_wire(field: &str, raw: i32) -> Result<Mode, ConvertError> {
    let unknown = || ConvertError::UnknownEnum {
        field: field.to_owned(),
        value: raw,
    };
    Ok(
        match v1::EstimatorMode::try_from(raw).map_err(|_| unknown())? {
            v1::EstimatorMode::Unspecified => return Err(unknown()),
            v1::EstimatorMode::Initialising => Mode::Initialising,
            v1::EstimatorMode::Nominal => Mode::Nominal,
            v1::EstimatorMode::GnssDeniedVision => Mode::GnssDeniedVision,
            v1::EstimatorMode::InertialOnly => Mode::InertialOnly,
            v1::EstimatorMode::Diverged => Mode::Diverged,
            v1::EstimatorMode::AttitudeOnly => Mode::AttitudeOnly,
        },
    )
}

/// The wire aiding sources of `a`, in wire order. `VISION` is set with either vision part, for
/// readers that only know it.
pub fn aiding_to_wire(a: &AidingFlags) -> impl Iterator<Item = v1::AidingSource> {
    let AidingFlags {
        gnss_pos,
        gnss_vel,
        vision_rot,
        vision_trans,
    } = *a;
    [
        (gnss_pos, v1::AidingSource::GnssPosition),
        (gnss_vel, v1::AidingSource::GnssVelocity),
        (vision_rot || vision_trans, v1::AidingSource::Vision),
        (vision_rot, v1::AidingSource::VisionRotation),
        (vision_trans, v1::AidingSource::VisionTranslation),
    ]
    .into_iter()
    .filter_map(|(on, s)| on.then_some(s))
}

/// Wire aiding sources → flags. A sender that only says `VISION` (no rotation/translation detail)
/// is read as both parts; unknown values are refused.
pub fn aiding_from_wire(field: &str, sources: &[i32]) -> Result<AidingFlags, ConvertError> {
    let mut a = AidingFlags::default();
    let mut vision_any = false;
    for (i, &raw) in sources.iter().enumerate() {
        let s = v1::AidingSource::try_from(raw).map_err(|_| ConvertError::UnknownEnum {
            field: format!("{field}[{i}]"),
            value: raw,
        })?;
        match s {
            v1::AidingSource::Unspecified => {
                return Err(ConvertError::UnknownEnum {
                    field: format!("{field}[{i}]"),
                    value: raw,
                });
            }
            v1::AidingSource::GnssPosition => a.gnss_pos = true,
            v1::AidingSource::GnssVelocity => a.gnss_vel = true,
            v1::AidingSource::Vision => vision_any = true,
            v1::AidingSource::VisionRotation => a.vision_rot = true,
            v1::AidingSource::VisionTranslation => a.vision_trans = true,
        }
    }
    if vision_any && !a.vision_rot && !a.vision_trans {
        a.vision_rot = true;
        a.vision_trans = true;
    }
    Ok(a)
}

impl From<&SourceSummary> for v1::SourceSummary {
    fn from(s: &SourceSummary) -> Self {
        let SourceSummary {
            test_ratio,
            fused,
            rejected,
        } = *s;
        v1::SourceSummary {
            test_ratio,
            fused,
            rejected,
        }
    }
}

impl TryFrom<&v1::SourceSummary> for SourceSummary {
    type Error = ConvertError;
    fn try_from(s: &v1::SourceSummary) -> Result<Self, ConvertError> {
        Ok(SourceSummary {
            test_ratio: non_negative("test_ratio", s.test_ratio)?,
            fused: s.fused,
            rejected: s.rejected,
        })
    }
}

impl From<&PoseHealth> for v1::PoseHealthSummary {
    /// The summary without the mode (the wire pose carries it in `mode`).
    fn from(h: &PoseHealth) -> Self {
        let PoseHealth {
            mode: _,
            gnss_pos,
            gnss_vel,
            vision_rot,
            vision_trans,
            mag,
            baro,
            gnss_tilt,
            position_hold,
            inputs_rejected,
            late_dropped,
            vision_no_clone,
            gnss_resets,
        } = h;
        v1::PoseHealthSummary {
            gnss_position: Some(gnss_pos.into()),
            gnss_velocity: Some(gnss_vel.into()),
            vision_rotation: Some(vision_rot.into()),
            vision_translation: Some(vision_trans.into()),
            magnetometer: Some(mag.into()),
            barometer: Some(baro.into()),
            gnss_tilt: Some(gnss_tilt.into()),
            position_hold: Some(position_hold.into()),
            inputs_rejected: *inputs_rejected,
            late_dropped: *late_dropped,
            vision_no_clone: *vision_no_clone,
            gnss_resets: *gnss_resets,
        }
    }
}

/// A wire summary with the pose's mode → the per-pose health. An absent source reads as never
/// fused.
pub fn pose_health_from_wire(
    mode: Mode,
    h: &v1::PoseHealthSummary,
) -> Result<PoseHealth, ConvertError> {
    let source = |name: &str, s: &Option<v1::SourceSummary>| -> Result<_, ConvertError> {
        s.as_ref().map_or(Ok(SourceSummary::default()), |s| {
            SourceSummary::try_from(s).map_err(|e| e.within(name))
        })
    };
    Ok(PoseHealth {
        mode,
        gnss_pos: source("gnss_position", &h.gnss_position)?,
        gnss_vel: source("gnss_velocity", &h.gnss_velocity)?,
        vision_rot: source("vision_rotation", &h.vision_rotation)?,
        vision_trans: source("vision_translation", &h.vision_translation)?,
        mag: source("magnetometer", &h.magnetometer)?,
        baro: source("barometer", &h.barometer)?,
        gnss_tilt: source("gnss_tilt", &h.gnss_tilt)?,
        position_hold: source("position_hold", &h.position_hold)?,
        inputs_rejected: h.inputs_rejected,
        late_dropped: h.late_dropped,
        vision_no_clone: h.vision_no_clone,
        gnss_resets: h.gnss_resets,
    })
}

/// The complete wire pose of an estimator output (every optional field set but, in
/// [`Mode::AttitudeOnly`], position, velocity and their σ; `covariance_9x9` empty).
pub fn pose_to_wire(vehicle_id: &str, p: &PoseOutput, ingest_wall_ns: i64) -> v1::PoseEstimate {
    let PoseOutput {
        t_ns,
        lla,
        pos_ned_m,
        vel_ned_mps,
        nav_from_body,
        euler_rad,
        sigma_pos_ned_m,
        sigma_vel_mps,
        sigma_att_rad,
        gyro_bias_radps,
        accel_bias_mps2,
        health,
        aiding,
    } = p;
    let pv = health.mode.has_position();
    v1::PoseEstimate {
        vehicle_id: vehicle_id.to_owned(),
        t_ns: *t_ns,
        position: pv.then(|| lla.into()),
        vel_ned_mps: pv.then(|| vel_ned_mps.into()),
        nav_from_body: Some(nav_from_body.into()),
        roll_rad: euler_rad.x,
        pitch_rad: euler_rad.y,
        yaw_rad: euler_rad.z,
        sigma_pos_ned_m: pv.then(|| sigma_pos_ned_m.into()),
        sigma_vel_ned_mps: pv.then(|| sigma_vel_mps.into()),
        sigma_att_rad: Some(sigma_att_rad.into()),
        covariance_9x9: Vec::new(),
        aiding_sources: aiding_to_wire(aiding).map(|s| s as i32).collect(),
        mode: mode_to_wire(health.mode) as i32,
        ingest_wall_ns,
        pos_ned_m: pv.then(|| pos_ned_m.into()),
        gyro_bias_radps: Some(gyro_bias_radps.into()),
        accel_bias_mps2: Some(accel_bias_mps2.into()),
        health: Some(health.into()),
    }
}

/// An optional finite 3-vector, zero when absent.
fn optional_vector3(field: &str, v: &Option<v1::Vector3>) -> Result<Vector3<f64>, ConvertError> {
    v.as_ref()
        .map_or(Ok(Vector3::zeros()), |v| vector3(field, v))
}

/// How a 3-vector field is read: its name and value.
type Vector3Reader = fn(&str, &Option<v1::Vector3>) -> Result<Vector3<f64>, ConvertError>;

/// An optional σ: as [`sigma3`] when present, zero when absent.
fn optional_sigma3(field: &str, v: &Option<v1::Vector3>) -> Result<Vector3<f64>, ConvertError> {
    match v {
        Some(_) => sigma3(field, v),
        None => Ok(Vector3::zeros()),
    }
}

/// A non-negative finite 3-vector (a σ).
fn sigma3(field: &str, v: &Option<v1::Vector3>) -> Result<Vector3<f64>, ConvertError> {
    let s = required_vector3(field, v)?;
    for (name, c) in [("x", s.x), ("y", s.y), ("z", s.z)] {
        non_negative(name, c).map_err(|e| e.within(field))?;
    }
    Ok(s)
}

impl TryFrom<&v1::PoseEstimate> for PoseOutput {
    type Error = ConvertError;
    /// Position, velocity, attitude, σ and mode are required (position, velocity and their σ
    /// not in [`Mode::AttitudeOnly`], where they read as zero); `pos_ned_m`, the biases and the
    /// health summary read as zero / default when absent (the service's compact pose).
    fn try_from(p: &v1::PoseEstimate) -> Result<Self, ConvertError> {
        let mode = mode_from_wire("mode", p.mode)?;
        let pv = mode.has_position();
        let lla = match (&p.position, pv) {
            (None, false) => Lla::from_deg(0.0, 0.0, 0.0),
            _ => Lla::try_from(required("position", &p.position)?)
                .map_err(|e| e.within("position"))?,
        };
        // Required where the mode estimates them, zero when absent otherwise.
        let (vector, sigma) = if pv {
            (required_vector3 as Vector3Reader, sigma3 as Vector3Reader)
        } else {
            (
                optional_vector3 as Vector3Reader,
                optional_sigma3 as Vector3Reader,
            )
        };
        let q = required("nav_from_body", &p.nav_from_body)?;
        for (name, c) in [("w", q.w), ("x", q.x), ("y", q.y), ("z", q.z)] {
            finite(name, c).map_err(|e| e.within("nav_from_body"))?;
        }
        let raw = Quaternion::new(q.w, q.x, q.y, q.z);
        // A unit quaternion written by `pose_to_wire` is kept bit for bit; anything else is
        // normalised (and refused when far from unit).
        let norm = raw.norm();
        if (norm - 1.0).abs() > super::limits::QUAT_NORM_TOL {
            return Err(ConvertError::OutOfRange {
                field: "nav_from_body".to_owned(),
                value: norm,
                range: format!("norm 1 ± {}", super::limits::QUAT_NORM_TOL),
            });
        }
        let nav_from_body = if (norm - 1.0).abs() <= 4.0 * f64::EPSILON {
            UnitQuaternion::new_unchecked(raw)
        } else {
            UnitQuaternion::from_quaternion(raw)
        };
        let health = match &p.health {
            Some(h) => pose_health_from_wire(mode, h).map_err(|e| e.within("health"))?,
            None => PoseHealth {
                mode,
                ..PoseHealth::default()
            },
        };
        Ok(PoseOutput {
            t_ns: p.t_ns,
            lla,
            pos_ned_m: optional_vector3("pos_ned_m", &p.pos_ned_m)?,
            vel_ned_mps: vector("vel_ned_mps", &p.vel_ned_mps)?,
            nav_from_body,
            euler_rad: Vector3::new(
                finite("roll_rad", p.roll_rad)?,
                finite("pitch_rad", p.pitch_rad)?,
                finite("yaw_rad", p.yaw_rad)?,
            ),
            sigma_pos_ned_m: sigma("sigma_pos_ned_m", &p.sigma_pos_ned_m)?,
            sigma_vel_mps: sigma("sigma_vel_ned_mps", &p.sigma_vel_ned_mps)?,
            sigma_att_rad: sigma3("sigma_att_rad", &p.sigma_att_rad)?,
            gyro_bias_radps: optional_vector3("gyro_bias_radps", &p.gyro_bias_radps)?,
            accel_bias_mps2: optional_vector3("accel_bias_mps2", &p.accel_bias_mps2)?,
            health,
            aiding: aiding_from_wire("aiding_sources", &p.aiding_sources)?,
        })
    }
}
