//! Conversions between the wire types ([`crate::v1`]) and the `uavnav_core` types.
//!
//! Wire → core is `TryFrom` and validates everything a sender could get wrong (missing fields,
//! NaN/Inf, out-of-range values, unknown enum values, empty or mislabelled images); the error names
//! the field. Core → wire is infallible (`From<&core>`).
//!
//! | module | types |
//! |---|---|
//! | [`sensors`] | `ImuSample`, `ImuBatch` ↔ `Vec<ImuSample>`, `GnssFix`, `CameraFrame`, `SensorEvent` |
//! | [`config`] | `VehicleConfig`, `ImuConfig`, `GnssConfig`, `CameraConfig`, `CameraModel` |
//! | [`geometry`] | `Vector3`, `Quaternion`, `RigidTransform`, `GeodeticPosition` ↔ `Lla`, `TruthSample` |
//! | [`output`] | `PoseEstimate` ↔ `PoseOutput` (every field), `EstimatorMode` ↔ `Mode`, aiding sources ↔ `AidingFlags`, `PoseHealthSummary` ↔ `PoseHealth` |

pub mod config;
pub mod geometry;
pub mod output;
pub mod sensors;

use std::fmt;

/// Plausibility limits applied to wire input. Values beyond these are physically absurd for a UAV
/// and are rejected rather than fed to the estimator.
pub mod limits {
    /// Largest accepted angular rate magnitude per axis, rad/s (≈ 5700 °/s).
    pub const MAX_GYRO_RADPS: f64 = 100.0;
    /// Largest accepted specific force per axis, m/s² (≈ 100 g).
    pub const MAX_ACCEL_MPS2: f64 = 1000.0;
    /// Accepted ellipsoidal altitude range, m.
    pub const ALT_RANGE_M: (f64, f64) = (-2_000.0, 100_000.0);
    /// Largest accepted velocity component, m/s.
    pub const MAX_VEL_MPS: f64 = 2_000.0;
    /// Accepted range of 1-σ GNSS errors (m or m/s): strictly positive, below this bound.
    pub const MAX_SIGMA: f64 = 1.0e5;
    /// Largest accepted magnetic flux density per axis, T (the Earth's field is 22–67 µT; a
    /// millitesla is a saturated or broken sensor).
    pub const MAX_MAG_FIELD_T: f64 = 1.0e-3;
    /// Accepted static pressure range, Pa (30 km altitude to below the Dead Sea, with margin).
    pub const PRESSURE_RANGE_PA: (f64, f64) = (500.0, 120_000.0);
    /// Accepted sensor temperature range, °C.
    pub const TEMPERATURE_RANGE_DEGC: (f64, f64) = (-90.0, 150.0);
    /// Longest accepted GNSS stamp delay, s (autopilots report 0.1–0.5 s: ArduPilot's
    /// `EK3_GPS_DELAY` tops at 0.25 s, PX4's `EKF2_GPS_DELAY` at 0.3 s). The fusion horizon trails
    /// by it, and the estimator's IMU history (2,048 samples) covers a second plus the fusion
    /// delay at 1 kHz; longer means a wrong unit.
    pub const MAX_GNSS_DELAY_S: f64 = 1.0;
    /// Largest accepted deviation of a quaternion's norm from 1 (the quaternion is then normalised).
    pub const QUAT_NORM_TOL: f64 = 1.0e-2;
    /// Most IMU samples in one `ImuBatch` (counted on the wire before decoding: see
    /// [`crate::wire`]).
    pub const MAX_IMU_BATCH_SAMPLES: usize = 10_000;
    /// Most vehicle ids in one `WatchRequest`.
    pub const MAX_WATCH_IDS: usize = 10_000;

    // Plausibility of vehicle configurations: generous bounds (orders of magnitude beyond any
    // UAV sensor), so that a value in the wrong unit or a garbage number is refused with the field
    // named instead of driving the filter to NaN.

    /// Accepted IMU sample rate, Hz (a 10 Hz logged IMU is the slowest seen).
    pub const IMU_RATE_HZ: (f64, f64) = (1.0, 100_000.0);
    /// Accepted rate of the aiding sensors (GNSS, magnetometer, barometer, camera), Hz.
    pub const AIDING_RATE_HZ: (f64, f64) = (0.01, 10_000.0);
    /// Largest gyro white noise density, rad/s/√Hz (MEMS: 1e-4–1e-2).
    pub const MAX_GYRO_NOISE_DENSITY: f64 = 1.0;
    /// Largest gyro bias random walk, rad/s²/√Hz (MEMS: 1e-6–1e-3).
    pub const MAX_GYRO_RANDOM_WALK: f64 = 0.1;
    /// Largest accelerometer white noise density, m/s²/√Hz (MEMS: 1e-3–1e-1).
    pub const MAX_ACCEL_NOISE_DENSITY: f64 = 10.0;
    /// Largest accelerometer bias random walk, m/s³/√Hz (MEMS: 1e-5–1e-2).
    pub const MAX_ACCEL_RANDOM_WALK: f64 = 1.0;
    /// Largest turn-on gyro bias σ, rad/s (about 10 °/s: uncalibrated MEMS reach a few °/s).
    pub const MAX_GYRO_BIAS_SIGMA_RADPS: f64 = 0.2;
    /// Largest turn-on accelerometer bias σ, m/s² (MEMS: 0.01–0.5).
    pub const MAX_ACCEL_BIAS_SIGMA_MPS2: f64 = 2.0;
    /// Largest component of a sensor's offset from the IMU (GNSS lever arm, camera mount), m.
    pub const MAX_OFFSET_M: f64 = 100.0;
    /// Accepted focal lengths, px.
    pub const FOCAL_RANGE_PX: (f64, f64) = (1.0, 1.0e6);
    /// Largest magnitude of a radial-tangential distortion coefficient.
    pub const MAX_DISTORTION_COEFF: f64 = 100.0;
}

/// What is wrong with a wire message, naming the field (a dotted path such as
/// `samples[3].gyro_x_radps`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConvertError {
    /// A required sub-message is absent.
    #[error("{field}: missing")]
    Missing {
        /// The field path.
        field: String,
    },
    /// A number is NaN or infinite.
    #[error("{field}: not a finite number ({value})")]
    NotFinite {
        /// The field path.
        field: String,
        /// The offending value.
        value: f64,
    },
    /// A number lies outside its accepted range.
    #[error("{field}: {value} is out of range ({range})")]
    OutOfRange {
        /// The field path.
        field: String,
        /// The offending value.
        value: f64,
        /// The accepted range, human-readable.
        range: String,
    },
    /// An enum value that is unknown or `*_UNSPECIFIED` where a value is required.
    #[error("{field}: unknown or unspecified enum value {value}")]
    UnknownEnum {
        /// The field path.
        field: String,
        /// The raw value.
        value: i32,
    },
    /// Any other inconsistency (empty image, wrong magic bytes, unordered batch...).
    #[error("{field}: {reason}")]
    Invalid {
        /// The field path.
        field: String,
        /// What is wrong.
        reason: String,
    },
}

impl ConvertError {
    /// The path of the offending field.
    pub fn field(&self) -> &str {
        match self {
            ConvertError::Missing { field }
            | ConvertError::NotFinite { field, .. }
            | ConvertError::OutOfRange { field, .. }
            | ConvertError::UnknownEnum { field, .. }
            | ConvertError::Invalid { field, .. } => field,
        }
    }

    /// Prefixes the field path with the enclosing field, e.g. `samples[3]` + `t_ns`.
    pub fn within(mut self, parent: impl fmt::Display) -> Self {
        let field = match &mut self {
            ConvertError::Missing { field }
            | ConvertError::NotFinite { field, .. }
            | ConvertError::OutOfRange { field, .. }
            | ConvertError::UnknownEnum { field, .. }
            | ConvertError::Invalid { field, .. } => field,
        };
        *field = format!("{parent}.{field}");
        self
    }

    pub(crate) fn missing(field: &str) -> Self {
        ConvertError::Missing {
            field: field.to_owned(),
        }
    }

    pub(crate) fn invalid(field: &str, reason: impl Into<String>) -> Self {
        ConvertError::Invalid {
            field: field.to_owned(),
            reason: reason.into(),
        }
    }
}

/// A finite number.
pub(crate) fn finite(field: &str, value: f64) -> Result<f64, ConvertError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(ConvertError::NotFinite {
            field: field.to_owned(),
            value,
        })
    }
}

/// A finite number in `[lo, hi]`.
pub(crate) fn in_range(field: &str, value: f64, lo: f64, hi: f64) -> Result<f64, ConvertError> {
    finite(field, value)?;
    if (lo..=hi).contains(&value) {
        Ok(value)
    } else {
        Err(ConvertError::OutOfRange {
            field: field.to_owned(),
            value,
            range: format!("[{lo}, {hi}]"),
        })
    }
}

/// A finite, strictly positive number below `hi`.
pub(crate) fn positive(field: &str, value: f64, hi: f64) -> Result<f64, ConvertError> {
    finite(field, value)?;
    if value > 0.0 && value <= hi {
        Ok(value)
    } else {
        Err(ConvertError::OutOfRange {
            field: field.to_owned(),
            value,
            range: format!("(0, {hi}]"),
        })
    }
}

/// A finite, non-negative number.
pub(crate) fn non_negative(field: &str, value: f64) -> Result<f64, ConvertError> {
    finite(field, value)?;
    if value >= 0.0 {
        Ok(value)
    } else {
        Err(ConvertError::OutOfRange {
            field: field.to_owned(),
            value,
            range: "[0, inf)".to_owned(),
        })
    }
}

/// A required sub-message.
pub(crate) fn required<'a, T>(field: &str, value: &'a Option<T>) -> Result<&'a T, ConvertError> {
    value.as_ref().ok_or_else(|| ConvertError::missing(field))
}
