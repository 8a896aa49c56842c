//! The truth is strapdown-consistent: integrating the noise-free IMU reproduces it.
#![allow(clippy::unwrap_used)]

use uavnav_sim::strapdown::{NavState, integrate};
use uavnav_sim::{Flight, Scenario};

const PAPER_SMALL: &str = include_str!("../../scenarios/paper-small-lever.toml");

#[test]
fn noise_free_imu_reproduces_truth_for_120_s() {
    let mut scenario = Scenario::from_toml_str(PAPER_SMALL).unwrap();
    scenario.duration_s = 130.0;
    let flight = Flight::new(&scenario).unwrap();
    let n = (120.0 * scenario.imu.rate_hz) as usize + 1;
    let imu = &flight.ideal_imu()[..n];
    let truth = &flight.truth()[..n];
    let t0 = truth[0];
    let init = NavState {
        pos_ned_m: t0.pos_ned_m,
        vel_ned_mps: t0.vel_ned_mps,
        nav_from_body: t0.nav_from_body,
    };
    let states = integrate(flight.local_frame(), init, imu);
    let (mut max_pos, mut max_att_deg, mut max_vel) = (0.0f64, 0.0f64, 0.0f64);
    for (s, t) in states.iter().zip(truth) {
        max_pos = max_pos.max((s.pos_ned_m - t.pos_ned_m).norm());
        max_vel = max_vel.max((s.vel_ned_mps - t.vel_ned_mps).norm());
        max_att_deg = max_att_deg.max(s.nav_from_body.angle_to(&t.nav_from_body).to_degrees());
    }
    let end = (states[n - 1].pos_ned_m - truth[n - 1].pos_ned_m).norm();
    eprintln!(
        "after 120 s: end pos err {end:.2e} m, max pos {max_pos:.2e} m, max vel {max_vel:.2e} m/s, max att {max_att_deg:.2e}°"
    );
    assert!(end < 0.1, "position error after 120 s: {end} m");
    assert!(max_pos < 0.1, "max position error {max_pos} m");
    assert!(max_att_deg < 0.01, "max attitude error {max_att_deg}°");
    // The flight did something: it turned and moved.
    let travelled = (truth[n - 1].pos_ned_m - truth[0].pos_ned_m).norm();
    assert!(travelled > 1000.0);
}
