//! The multirotor family: the flight does what its scenario says (hover, yaw in place, forward,
//! sideways, backward, an aggressive dash), the IMU integrates back to it, and the vehicle is
//! described as a multirotor.
#![allow(clippy::unwrap_used)]

use nalgebra::Vector3;
use uavnav_core::Airframe;
use uavnav_sim::multirotor::MultirotorTrajectory;
use uavnav_sim::scenario::VelocityChangeSpec;
use uavnav_sim::strapdown::{NavState, integrate};
use uavnav_sim::trajectory::FlightPath;
use uavnav_sim::{Flight, Scenario, SimError};

const MULTIROTOR: &str = include_str!("../../scenarios/multirotor.toml");
const SMOKE: &str = include_str!("../../scenarios/smoke.toml");

fn multirotor() -> Scenario {
    Scenario::from_toml_str(MULTIROTOR).unwrap()
}

#[test]
fn the_flight_hovers_yaws_and_flies_forward_sideways_backward() {
    let sc = multirotor();
    let flight = Flight::new(&sc).unwrap();
    let dt_s = 1.0 / sc.imu.rate_hz;
    let at = |t_s: f64| &flight.truth()[(t_s / dt_s).round() as usize];
    let yaw_deg = |t_s: f64| at(t_s).nav_from_body.euler_angles().2.to_degrees();
    let body_vel = |t_s: f64| {
        let t = at(t_s);
        t.nav_from_body.inverse_transform_vector(&t.vel_ned_mps)
    };
    let tilt_deg = |t_s: f64| {
        let z = at(t_s).nav_from_body.transform_vector(&Vector3::z());
        z.z.acos().to_degrees()
    };
    // Hover facing north, then yaw in place to east.
    assert!(at(2.0).vel_ned_mps.norm() < 1e-12 && tilt_deg(2.0) < 1e-9);
    assert!(yaw_deg(2.0).abs() < 1e-9);
    let mid_yaw = at(6.25);
    assert!(mid_yaw.vel_ned_mps.norm() < 1e-12 && (yaw_deg(6.25) - 45.0).abs() < 1e-6);
    assert!((yaw_deg(9.0) - 90.0).abs() < 1e-6 && tilt_deg(9.0) < 1e-9);
    // Forward (body x), sideways to the left (body −y), backward (body −x).
    let v = body_vel(14.0);
    assert!((v - Vector3::new(6.0, 0.0, 0.0)).norm() < 1e-6, "{v:?}");
    let v = body_vel(20.0);
    assert!((v - Vector3::new(0.0, -6.0, 0.0)).norm() < 1e-6, "{v:?}");
    let v = body_vel(26.0);
    assert!((v - Vector3::new(-5.0, 0.0, 0.0)).norm() < 1e-6, "{v:?}");
    // The dash tilts ~50° (under the 60° limit), and the half turn during it ends facing west.
    let max_tilt = (3600..4200)
        .map(|k| tilt_deg(k as f64 * 0.01))
        .fold(0.0f64, f64::max);
    assert!((45.0..60.0).contains(&max_tilt), "{max_tilt}");
    assert!((yaw_deg(42.0) + 90.0).abs() < 1e-6, "{}", yaw_deg(42.0));
    // Climb 8 m, descend 9 m: 1 m below the start, hovering at the end.
    let end = flight.truth().last().unwrap();
    assert!(end.vel_ned_mps.norm() < 1e-9);
    assert!((end.pos_ned_m.z - 1.0).abs() < 1e-6, "{:?}", end.pos_ned_m);
    eprintln!(
        "multirotor: max tilt {max_tilt:.1}°, end position {:?} m",
        end.pos_ned_m
    );
}

#[test]
fn noise_free_imu_integrates_back_to_the_trajectory() {
    let flight = Flight::new(&multirotor()).unwrap();
    let truth = flight.truth();
    let t0 = truth[0];
    let init = NavState {
        pos_ned_m: t0.pos_ned_m,
        vel_ned_mps: t0.vel_ned_mps,
        nav_from_body: t0.nav_from_body,
    };
    let states = integrate(flight.local_frame(), init, &flight.ideal_imu());
    let (mut max_pos, mut max_vel, mut max_att_deg) = (0.0f64, 0.0f64, 0.0f64);
    for (s, t) in states.iter().zip(truth) {
        max_pos = max_pos.max((s.pos_ned_m - t.pos_ned_m).norm());
        max_vel = max_vel.max((s.vel_ned_mps - t.vel_ned_mps).norm());
        max_att_deg = max_att_deg.max(s.nav_from_body.angle_to(&t.nav_from_body).to_degrees());
    }
    eprintln!(
        "multirotor strapdown over {} s: max pos {max_pos:.2e} m, max vel {max_vel:.2e} m/s, max att {max_att_deg:.2e}°",
        flight.scenario().duration_s
    );
    assert!(max_pos < 0.01, "max position error {max_pos} m");
    assert!(max_vel < 1e-3, "max velocity error {max_vel} m/s");
    assert!(max_att_deg < 1e-3, "max attitude error {max_att_deg}°");
}

#[test]
fn airframe_follows_the_trajectory_kind() {
    let flight = Flight::new(&multirotor()).unwrap();
    assert_eq!(flight.vehicle_config().airframe, Airframe::Multirotor);
    assert!(flight.vehicle_config().mag.is_some());
    let smoke = Flight::new(&Scenario::from_toml_str(SMOKE).unwrap()).unwrap();
    assert_eq!(smoke.vehicle_config().airframe, Airframe::FixedWing);
    assert!(matches!(
        FlightPath::new(&multirotor().trajectory),
        FlightPath::Multirotor(_)
    ));
}

#[test]
fn too_hard_a_manoeuvre_is_refused_by_its_tilt() {
    let mut sc = multirotor();
    sc.trajectory.velocity_changes.push(VelocityChangeSpec {
        start_s: 53.0,
        ramp_s: 0.5,
        to_ned_mps: [10.0, 0.0, 0.0],
    });
    let e = Flight::new(&sc).unwrap_err();
    assert!(
        matches!(&e, SimError::Invalid(m) if m.contains("tilt") && m.contains("ramp_s")),
        "{e}"
    );
    // The helper the check uses agrees with the attitude: level at hover.
    let tr = MultirotorTrajectory::new(&multirotor().trajectory);
    assert!(MultirotorTrajectory::tilt_rad(&tr.kinematics(1.0)) < 1e-12);
}

#[test]
fn fixed_wing_keys_in_a_multirotor_file_are_refused_at_the_table() {
    let text = MULTIROTOR.replace(
        "kind = \"multirotor\"",
        "kind = \"multirotor\"\nspeed_mps = 5.0",
    );
    let e = Scenario::from_toml_str(&text).unwrap_err();
    let header = MULTIROTOR
        .lines()
        .position(|l| l.starts_with("[trajectory]"))
        .unwrap()
        + 1;
    assert_eq!(e.line, header, "{e}");
    assert!(e.message.contains("speed_mps"), "{e}");
    let e = Scenario::from_toml_str(&MULTIROTOR.replace("\"multirotor\"", "\"helicopter\""))
        .unwrap_err();
    assert!(e.message.contains("helicopter"), "{e}");
}
