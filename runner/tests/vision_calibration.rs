//! The vision chain's covariance is calibrated per frame: on the smoke flight, the joint error
//! `[δθ; t − t_true]` of every metric egomotion, normalised by its own 6×6 covariance, averages
//! about 6 (its dimension). The estimator's `vision_cov_scale` (the allowance for the errors' time
//! correlation) assumes exactly this; a front-end or solver change that makes the covariance
//! optimistic or pessimistic again fails here.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use nalgebra::{UnitQuaternion, Vector3, Vector6};
use uavnav_core::truth::truth_at;
use uavnav_core::{SensorEvent, TruthSample};
use uavnav_runner::{RunnerParams, VehicleRunner};
use uavnav_sim::{Flight, Scenario};

/// The true camera motion between two truth samples (`x1 = R x0 + t`, camera-1 frame).
fn true_motion(
    flight: &Flight,
    a: &TruthSample,
    b: &TruthSample,
) -> (UnitQuaternion<f64>, Vector3<f64>) {
    let bfc = flight.body_from_cam();
    let nav_from_cam0 = a.nav_from_body * bfc.rotation;
    let nav_from_cam1 = b.nav_from_body * bfc.rotation;
    let p_cam0 = a.pos_ned_m + a.nav_from_body * bfc.translation.vector;
    let p_cam1 = b.pos_ned_m + b.nav_from_body * bfc.translation.vector;
    (
        nav_from_cam1.inverse() * nav_from_cam0,
        nav_from_cam1.inverse() * (p_cam0 - p_cam1),
    )
}

#[test]
fn metric_egomotion_covariance_matches_its_errors() {
    let text = include_str!("../../scenarios/smoke.toml");
    let scenario = Scenario::from_toml_str(text).expect("smoke scenario parses");
    let flight = Flight::new(&scenario).expect("smoke flight");
    let mut runner = VehicleRunner::new(
        flight.vehicle_config(),
        RunnerParams::default(),
        Some(flight.origin()),
    );
    let mut nees = Vec::new();
    for e in flight.events() {
        let e = e.expect("event");
        let is_frame = matches!(e, SensorEvent::Camera(_));
        runner.push_inline(e).expect("accepted");
        if !is_frame {
            continue;
        }
        let Some(Ok(ego)) = runner.last_frame_result().map(|r| &r.outcome) else {
            continue;
        };
        let (Some(t_m), Some(a), Some(b)) = (
            ego.t_cam1_m,
            truth_at(flight.truth(), ego.t0_ns),
            truth_at(flight.truth(), ego.t1_ns),
        ) else {
            continue;
        };
        let (r_true, t_true) = true_motion(&flight, &a, &b);
        let d = (ego.cam1_from_cam0 * r_true.inverse()).scaled_axis();
        let dt = t_m - t_true;
        let err = Vector6::new(d.x, d.y, d.z, dt.x, dt.y, dt.z);
        let inv = ego.joint_cov.try_inverse().expect("invertible covariance");
        nees.push((err.transpose() * inv * err)[0]);
    }
    assert!(nees.len() > 100, "metric measurements: {}", nees.len());
    let mean = nees.iter().sum::<f64>() / nees.len() as f64;
    eprintln!(
        "joint NEES mean {mean:.2} over {} metric egomotions (6 expected)",
        nees.len()
    );
    // Measured 5.8 on the 250 s paper flights (with the old 0.3 px noise floor: 1.15).
    assert!((3.5..=10.0).contains(&mean), "joint NEES mean {mean}");
}
