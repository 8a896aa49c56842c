//! Per-vehicle configuration: what the estimator must know about the sensors and the terrain.

use nalgebra::{Isometry3, UnitQuaternion, Vector3};

use crate::camera::CameraModel;

/// IMU noise model (continuous-time densities, as in the EuRoC/Kalibr `sensor.yaml`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuConfig {
    /// Nominal sample rate, Hz.
    pub rate_hz: f64,
    /// Gyro white noise density, rad/s/√Hz.
    pub gyro_noise_density: f64,
    /// Gyro bias random walk, rad/s²/√Hz.
    pub gyro_random_walk: f64,
    /// Accelerometer white noise density, m/s²/√Hz.
    pub accel_noise_density: f64,
    /// Accelerometer bias random walk, m/s³/√Hz.
    pub accel_random_walk: f64,
    /// 1-σ gyro bias per axis left at start (turn-on bias after any calibration), rad/s; 0 when
    /// not known. The `eskf` starts its bias states with the larger of this and its own default
    /// (`EstimatorParams::init_gyro_bias_sigma_radps`), so a consumer-grade IMU can say that its
    /// biases are larger than the filter assumes.
    pub gyro_bias_sigma_radps: f64,
    /// 1-σ accelerometer bias per axis left at start, m/s²; 0 when not known (as the gyro's).
    pub accel_bias_sigma_mps2: f64,
}

impl ImuConfig {
    /// A tactical-grade MEMS IMU (the simulator's default and the estimator's fallback).
    pub const TACTICAL_MEMS: ImuConfig = ImuConfig {
        rate_hz: 200.0,
        gyro_noise_density: 1.0e-4,
        gyro_random_walk: 2.0e-6,
        accel_noise_density: 1.0e-3,
        accel_random_walk: 1.0e-4,
        gyro_bias_sigma_radps: 0.0,
        accel_bias_sigma_mps2: 0.0,
    };
}

impl Default for ImuConfig {
    fn default() -> Self {
        Self::TACTICAL_MEMS
    }
}

/// GNSS receiver configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssConfig {
    /// Nominal fix rate, Hz.
    pub rate_hz: f64,
    /// Antenna phase centre in the body frame (the lever arm from the IMU), m.
    pub lever_arm_body_m: Vector3<f64>,
    /// How long after its time of validity a fix is stamped, ns (an autopilot stamps a fix when it
    /// processes it: ArduPilot `EK3_GPS_DELAY`, PX4 `EKF2_GPS_DELAY`). 0 when stamps are validity
    /// times.
    pub delay_ns: i64,
    /// What the fixes' altitude is measured from.
    pub altitude_reference: AltitudeReference,
}

/// What a GNSS altitude is measured from (receivers and autopilots often give height above mean
/// sea level: ArduPilot `GPS.Alt`, NMEA GGA, MAVLink `GPS_RAW_INT.alt`); see [`crate::geoid`].
pub use crate::geoid::AltitudeReference;

impl Default for GnssConfig {
    fn default() -> Self {
        Self {
            rate_hz: 5.0,
            lever_arm_body_m: Vector3::zeros(),
            delay_ns: 0,
            altitude_reference: AltitudeReference::Ellipsoid,
        }
    }
}

/// Magnetometer configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MagConfig {
    /// Nominal sample rate, Hz.
    pub rate_hz: f64,
    /// Rotation from the magnetometer frame into the body frame (`T_BS` of `mag0/sensor.yaml`).
    pub body_from_mag: UnitQuaternion<f64>,
    /// 1-σ white noise per axis and sample, T.
    pub sigma_t: f64,
}

impl Default for MagConfig {
    fn default() -> Self {
        Self {
            rate_hz: 10.0,
            body_from_mag: UnitQuaternion::identity(),
            // a typical MEMS magnetometer (~0.1 µT per sample); real in-flight disturbances are
            // larger and are the estimator's business, not the sensor's
            sigma_t: 1.0e-7,
        }
    }
}

/// Barometer configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaroConfig {
    /// Nominal sample rate, Hz.
    pub rate_hz: f64,
    /// 1-σ white noise per sample, Pa.
    pub sigma_pressure_pa: f64,
}

impl Default for BaroConfig {
    fn default() -> Self {
        Self {
            rate_hz: 10.0,
            // an MS5611-class sensor at its highest oversampling: ~1 Pa (8 cm of height)
            sigma_pressure_pa: 1.0,
        }
    }
}

/// One camera's intrinsics and mounting.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraConfig {
    /// Nominal frame rate, Hz.
    pub rate_hz: f64,
    /// Intrinsics and distortion.
    pub model: CameraModel,
    /// Camera pose in the body frame: `p_body = body_from_cam * p_cam` (EuRoC `T_BS`).
    pub body_from_cam: Isometry3<f64>,
}

/// Which fusion architecture runs for a vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum FilterProfile {
    /// The error-state EKF (default).
    #[default]
    Eskf,
    /// The paper's three-EKF architecture (baseline).
    Paper,
}

impl FilterProfile {
    /// The profile's CLI / config name.
    pub fn as_str(self) -> &'static str {
        match self {
            FilterProfile::Eskf => "eskf",
            FilterProfile::Paper => "paper",
        }
    }
}

impl std::str::FromStr for FilterProfile {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "eskf" => Ok(FilterProfile::Eskf),
            "paper" => Ok(FilterProfile::Paper),
            other => Err(format!(
                "unknown filter profile '{other}' (expected eskf or paper)"
            )),
        }
    }
}

/// Everything the estimator is told about one vehicle.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct VehicleConfig {
    /// IMU noise model.
    pub imu: ImuConfig,
    /// GNSS receiver, if fitted.
    pub gnss: Option<GnssConfig>,
    /// Magnetometer, if fitted.
    pub mag: Option<MagConfig>,
    /// Barometer, if fitted.
    pub baro: Option<BaroConfig>,
    /// Camera 0, if fitted.
    pub camera: Option<CameraConfig>,
    /// Terrain elevation above the WGS84 ellipsoid, m (the flat-Earth-surface model of the paper).
    pub terrain_elevation_m: f64,
    /// Fusion architecture.
    pub profile: FilterProfile,
    /// What kind of vehicle it is: whether its heading may be taken from its course.
    pub airframe: Airframe,
}

/// The vehicle's kind, as far as the estimator cares: a fixed wing flies nose first (its heading
/// is its course up to sideslip and wind crab), a multirotor flies in any direction. This is the
/// one vehicle-type switch of the estimator, and it is needed: in straight, constant-speed flight
/// nothing in IMU and GNSS data tells the heading, and only a fixed wing may then take its course.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Airframe {
    /// Not said: treated as able to fly in any direction (never heading = course).
    #[default]
    Unknown,
    /// Fixed wing (or a VTOL in forward flight).
    FixedWing,
    /// Multirotor or helicopter.
    Multirotor,
}

impl Airframe {
    /// The name used in files and on the command line.
    pub fn as_str(self) -> &'static str {
        match self {
            Airframe::Unknown => "unknown",
            Airframe::FixedWing => "fixed_wing",
            Airframe::Multirotor => "multirotor",
        }
    }
}

impl std::str::FromStr for Airframe {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "unknown" => Ok(Airframe::Unknown),
            "fixed_wing" => Ok(Airframe::FixedWing),
            "multirotor" => Ok(Airframe::Multirotor),
            other => Err(format!(
                "airframe: unknown value {other:?} (expected unknown, fixed_wing or multirotor)"
            )),
        }
    }
}
