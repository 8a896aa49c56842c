//! The heading of a simulated fixed wing without a magnetometer, from twelve starts round the
//! circle (`scenarios/mag-baro.toml` with its compass removed: level flight at 28 m/s, a climb,
//! and a 56° right turn from 4 to 14 s). The yaw bank must find the heading from any start, with
//! the airframe declared and without it (no vehicle-type switch is needed for it: undeclared,
//! the course is never taken for the heading), and the filter must never be confidently wrong
//! before it does. The multirotor's twelve starts are in `multirotor.rs`.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

mod common;

use common::fly_all;
use uavnav_core::Airframe;
use uavnav_core::rotation::wrap_pi;
use uavnav_core::truth::truth_at;
use uavnav_estimator::eskf::HeadingSource;
use uavnav_estimator::{Estimator, EstimatorParams, PoseOutput};
use uavnav_sim::{Flight, Scenario};

/// `scenarios/mag-baro.toml` without its compass, starting on `heading_deg`.
fn flight(heading_deg: f64) -> Flight {
    let path = format!("{}/../scenarios/mag-baro.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.contains("heading_deg = 45.0"));
    let text = text.replace(
        "heading_deg = 45.0",
        &format!("heading_deg = {heading_deg:.1}"),
    );
    let mut s = Scenario::from_toml_str(&text).unwrap();
    s.mag = None;
    Flight::new(&s).unwrap()
}

/// The fraction of poses whose yaw error is within 3σ, and the largest yaw error after
/// `after_s`, rad.
fn yaw_scores(f: &Flight, poses: &[PoseOutput], after_s: f64) -> (f64, f64) {
    let t_after = f.scenario().t0_ns + (after_s * 1e9) as i64;
    let (mut within, mut max_after) = (0usize, 0.0f64);
    for p in poses {
        let t = truth_at(f.truth(), p.t_ns).unwrap();
        let e = wrap_pi(p.euler_rad.z - t.nav_from_body.euler_angles().2).abs();
        if e <= 3.0 * p.sigma_att_rad.z {
            within += 1;
        }
        if p.t_ns >= t_after {
            max_after = max_after.max(e);
        }
    }
    (within as f64 / poses.len().max(1) as f64, max_after)
}

#[test]
fn the_heading_is_found_from_every_start_on_a_fixed_wing_without_a_magnetometer() {
    for airframe in [Airframe::FixedWing, Airframe::Unknown] {
        let mut worst: (f64, f64) = (1.0, 0.0);
        for k in 0..12 {
            let heading = -180.0 + 30.0 * k as f64 + 7.0;
            let f = flight(heading);
            let mut config = f.vehicle_config();
            config.airframe = airframe;
            let mut est = Estimator::new(&config, EstimatorParams::default(), Some(f.origin()));
            let poses = fly_all(&mut est, &f);
            let src = est.eskf().unwrap().heading_source();
            // The turn (4–14 s) is what tells the heading; scored from its end.
            let (within, max_after) = yaw_scores(&f, &poses, 14.0);
            eprintln!(
                "{airframe:?}, heading {heading:6.1}: source {src:?}, yaw within 3 sigma {:.1} %, \
                 max |yaw error| after 14 s {:.2} deg",
                100.0 * within,
                max_after.to_degrees()
            );
            assert!(poses.len() > 3000, "{}", poses.len());
            assert_ne!(src, HeadingSource::Unknown, "{airframe:?} {heading}");
            assert_ne!(src, HeadingSource::Magnetometer, "{airframe:?} {heading}");
            if airframe == Airframe::Unknown {
                // Undeclared, the course is never taken for the heading.
                assert_ne!(src, HeadingSource::Course, "{heading}");
            }
            assert!(within >= 0.95, "{airframe:?} {heading}: {within}");
            assert!(
                max_after < 2f64.to_radians(),
                "{airframe:?} {heading}: {}",
                max_after.to_degrees()
            );
            worst = (worst.0.min(within), worst.1.max(max_after));
        }
        eprintln!(
            "{airframe:?}: worst yaw within 3 sigma {:.1} %, worst max |yaw error| after 14 s {:.2} deg",
            100.0 * worst.0,
            worst.1.to_degrees()
        );
    }
}
