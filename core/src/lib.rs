//! # uavnav-core
//!
//! The vocabulary every other uavnav crate speaks. Pure: no I/O, no clock, no async.
//!
//! | module | what it holds |
//! |---|---|
//! | [`sensors`] | sensor samples (IMU, GNSS, magnetometer, barometer, camera frame) and the [`sensors::SensorEvent`] stream item |
//! | [`config`] | per-vehicle configuration: IMU noise, GNSS lever arm and delay, magnetometer, barometer, camera, terrain, filter profile |
//! | [`geodesy`] | WGS84: LLA ↔ ECEF ↔ local NED, normal gravity, radii of curvature |
//! | [`camera`] | pinhole + radial-tangential camera model (project, distort, undistort) |
//! | [`rotation`] | ZYX Euler angles, skew matrices, small-angle helpers |
//! | [`rng`] | a seeded, version-stable random generator (xoshiro256**) with Gaussian draws |
//! | [`egomotion`] | the camera relative-motion measurement shared by vision and estimator |
//! | [`truth`] | ground-truth state samples (the EuRoC `state_groundtruth_estimate0` row) and their interpolation |
//! | [`output`] | the estimator's output vocabulary: [`PoseOutput`], [`AidingFlags`], [`Mode`], [`PoseHealth`] |
//!
//! Conventions (project-wide): SI units; time is integer nanoseconds (`i64`, `t_ns`); world frame =
//! local NED; body = FRD = IMU frame; camera = OpenCV (x right, y down, z optical axis); quaternions
//! are Hamilton, `w` first; a transform named `a_from_b` maps coordinates in `b` into `a`.

pub mod camera;
pub mod config;
pub mod egomotion;
pub mod geodesy;
pub mod geoid;
pub mod magnetic;
pub mod output;
pub mod rng;
pub mod rotation;
pub mod sensors;
pub mod truth;

pub use camera::{CameraModel, Distortion};
pub use config::{
    Airframe, AltitudeReference, BaroConfig, CameraConfig, FilterProfile, GnssConfig, ImuConfig,
    MagConfig, VehicleConfig,
};
pub use egomotion::{Egomotion, EgomotionSolver, MotionPrior};
pub use geodesy::{Lla, LocalFrame};
pub use output::{AidingFlags, Mode, PoseHealth, PoseOutput, SourceSummary};
pub use sensors::{
    BaroSample, CameraFrame, FixType, GnssFix, GnssVelocity, ImageFormat, ImuSample, MagSample,
    SensorEvent,
};
pub use truth::TruthSample;

/// Nanoseconds per second, for `t_ns` ↔ seconds conversions.
pub const NS_PER_S: i64 = 1_000_000_000;

/// Converts a nanosecond duration to seconds.
pub fn ns_to_s(dt_ns: i64) -> f64 {
    dt_ns as f64 * 1e-9
}

/// Converts seconds to the nearest nanosecond.
pub fn s_to_ns(dt_s: f64) -> i64 {
    (dt_s * 1e9).round() as i64
}
