//! Wire poses → the `uavnav estimate` CSV columns (plus `vehicle_id`) and TUM lines, through the
//! estimator's own formatters so the columns stay identical.
//!
//! The wire pose does not carry the estimator's innovation diagnostics: the test-ratio and
//! rejection columns are 0 in `watch` output (they are in the health stream instead).

use nalgebra::{UnitQuaternion, Vector3};
use uavnav_core::{Lla, LocalFrame};
use uavnav_estimator::health::{Mode, PoseHealth};
use uavnav_estimator::output::PoseOutput;

use uavnav_client::pb;

/// The CSV header: the `estimate` columns, then `vehicle_id`.
pub fn csv_header() -> String {
    format!("{},vehicle_id", uavnav_estimator::format::csv_header())
}

fn v3(v: &Option<pb::Vector3>) -> Vector3<f64> {
    v.as_ref()
        .map_or_else(Vector3::zeros, |v| Vector3::new(v.x, v.y, v.z))
}

fn mode(m: i32) -> Mode {
    match pb::EstimatorMode::try_from(m).unwrap_or(pb::EstimatorMode::Unspecified) {
        pb::EstimatorMode::Nominal => Mode::Nominal,
        pb::EstimatorMode::GnssDeniedVision => Mode::GnssDeniedVision,
        pb::EstimatorMode::InertialOnly => Mode::InertialOnly,
        pb::EstimatorMode::Diverged => Mode::Diverged,
        _ => Mode::Initialising,
    }
}

/// The estimator output a wire pose stands for; `frame` gives the local NED position (TUM).
pub fn to_output(p: &pb::PoseEstimate, frame: Option<&LocalFrame>) -> Option<PoseOutput> {
    let pos = p.position.as_ref()?;
    let lla = Lla::try_from(pos).ok()?;
    let q = p.nav_from_body.as_ref()?;
    let nav_from_body =
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z));
    let pos_ned_m = frame.map_or_else(Vector3::zeros, |f| f.lla_to_ned(&lla));
    let health = PoseHealth {
        mode: mode(p.mode),
        ..PoseHealth::default()
    };
    Some(PoseOutput {
        t_ns: p.t_ns,
        lla,
        pos_ned_m,
        vel_ned_mps: v3(&p.vel_ned_mps),
        nav_from_body,
        euler_rad: Vector3::new(p.roll_rad, p.pitch_rad, p.yaw_rad),
        sigma_pos_ned_m: v3(&p.sigma_pos_ned_m),
        sigma_vel_mps: v3(&p.sigma_vel_ned_mps),
        sigma_att_rad: v3(&p.sigma_att_rad),
        gyro_bias_radps: Vector3::zeros(),
        accel_bias_mps2: Vector3::zeros(),
        health,
        aiding: Default::default(),
    })
}

/// One CSV row (no newline), or `None` for a pose without position/attitude.
pub fn csv_row(p: &pb::PoseEstimate) -> Option<String> {
    let o = to_output(p, None)?;
    Some(format!(
        "{},{}",
        uavnav_estimator::format::csv_row(&o),
        p.vehicle_id
    ))
}

/// One TUM line in the local NED frame `frame` (no newline).
pub fn tum_line(p: &pb::PoseEstimate, frame: &LocalFrame) -> Option<String> {
    to_output(p, Some(frame)).map(|o| uavnav_estimator::format::tum_line(&o))
}
