//! The IMU noise the `eskf` measures and reports in its health (`Health::imu_noise_ratio`): a
//! vehicle whose IMU is as noisy as configured reads about 1; the same IMU configured with
//! datasheet densities ten times too low (a real multirotor's vibration against its datasheet)
//! reads about 10, and the filter stays consistent because its process noise follows it.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

mod common;

use common::fly_all;
use uavnav_core::rotation::euler_error;
use uavnav_core::truth::truth_at;
use uavnav_estimator::{Estimator, EstimatorParams};
use uavnav_sim::{Flight, Scenario};

fn multirotor() -> Flight {
    let path = format!(
        "{}/../scenarios/multirotor.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let s = Scenario::from_toml_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    Flight::new(&s).unwrap()
}

/// Runs the flight with the IMU's configured noise densities scaled by `scale`; returns the
/// noise ratios at the end and the share of poses whose tilt error is within 3σ.
fn run(f: &Flight, scale: f64) -> ([f64; 2], f64) {
    let mut config = f.vehicle_config();
    config.imu.gyro_noise_density *= scale;
    config.imu.accel_noise_density *= scale;
    let mut est = Estimator::new(&config, EstimatorParams::default(), Some(f.origin()));
    let poses = fly_all(&mut est, f);
    let within = poses
        .iter()
        .filter(|p| {
            let t = truth_at(f.truth(), p.t_ns).unwrap();
            let e = euler_error(&p.nav_from_body, &t.nav_from_body);
            e.x.abs() <= 3.0 * p.sigma_att_rad.x && e.y.abs() <= 3.0 * p.sigma_att_rad.y
        })
        .count();
    let ratio = est.health().imu_noise_ratio.unwrap();
    (ratio, within as f64 / poses.len() as f64)
}

#[test]
fn the_measured_imu_noise_is_reported_against_the_configured() {
    let f = multirotor();
    let (as_configured, within) = run(&f, 1.0);
    eprintln!(
        "as configured: gyro / accel ratio {as_configured:.2?}, tilt within 3σ {:.1} %",
        100.0 * within
    );
    for r in as_configured {
        assert!((0.8..1.5).contains(&r), "{as_configured:?}");
    }
    let (vibrating, within) = run(&f, 0.1);
    eprintln!(
        "datasheet 10x too low: gyro / accel ratio {vibrating:.2?}, tilt within 3σ {:.1} %",
        100.0 * within
    );
    for r in vibrating {
        assert!((8.0..15.0).contains(&r), "{vibrating:?}");
    }
    assert!(within >= 0.95, "{within}");
}
