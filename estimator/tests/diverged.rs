//! The estimator never outputs a non-finite pose: a configuration that drives the filter to NaN
//! (a lever arm or noise density of 1e300, which the wire contract now refuses, but a library user
//! can still build) restarts it, and the health says DIVERGED until it has a pose again.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use nalgebra::{UnitQuaternion, Vector3};
use uavnav_core::{
    FilterProfile, FixType, GnssConfig, GnssFix, GnssVelocity, ImuSample, Lla, LocalFrame,
    VehicleConfig,
};
use uavnav_estimator::{Estimator, EstimatorParams, Mode, PoseOutput};

const T0: i64 = 5_000_000_000;
const DT: i64 = 5_000_000;

/// Every number of a pose is finite, and no σ is 0 (a NaN variance used to come out as σ = 0).
fn sound(o: &PoseOutput) -> bool {
    let v = [
        o.pos_ned_m,
        o.vel_ned_mps,
        o.euler_rad,
        o.sigma_pos_ned_m,
        o.sigma_vel_mps,
        o.sigma_att_rad,
    ];
    v.iter().all(|x| x.iter().all(|c| c.is_finite()))
        && [o.lla.lat_rad, o.lla.lon_rad, o.lla.alt_m]
            .iter()
            .all(|c| c.is_finite())
        && o.nav_from_body.coords.iter().all(|c| c.is_finite())
        && o.sigma_pos_ned_m.iter().all(|&s| s > 0.0)
}

/// Runs 20 s of a level vehicle at rest (IMU 200 Hz, GNSS 5 Hz) through `config`; returns the
/// poses, whether the health said DIVERGED at some point and the final health's resets.
fn run(config: &VehicleConfig) -> (Vec<PoseOutput>, bool, u32) {
    let origin = Lla::from_deg(45.0, 7.0, 300.0);
    let frame = LocalFrame::new(origin);
    let g = frame.gravity_ned(&Vector3::zeros());
    let q = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.5);
    let mut est = Estimator::new(config, EstimatorParams::default(), Some(origin));
    let (mut poses, mut diverged) = (Vec::new(), false);
    for k in 0..4000i64 {
        let t = T0 + k * DT;
        let s = ImuSample {
            t_ns: t,
            gyro_radps: Vector3::new(1e-4, -2e-4, 1e-4) * ((k % 7) as f64 - 3.0),
            accel_mps2: q.inverse() * (-g) + Vector3::new(0.01, -0.01, 0.02) * ((k % 5) as f64),
        };
        if let Ok(Some(p)) = est.push_imu(&s) {
            poses.push(p);
        }
        if k % 40 == 0 {
            let fix = GnssFix {
                t_ns: t,
                lat_deg: 45.0,
                lon_deg: 7.0,
                alt_m: 300.0,
                velocity: Some(GnssVelocity {
                    north_mps: 0.0,
                    east_mps: 0.0,
                    down_mps: Some(0.0),
                    sigma_mps: 0.1,
                }),
                sigma_h_m: 1.0,
                sigma_v_m: 2.0,
                fix_type: FixType::Fix3d,
                num_sats: 10,
            };
            let _ = est.push_gnss(&fix);
        }
        diverged |= est.health().mode == Mode::Diverged;
    }
    (poses, diverged, est.health().divergence_resets)
}

#[test]
fn a_diverging_filter_never_outputs_nan_and_reports_diverged() {
    let gnss = GnssConfig {
        rate_hz: 5.0,
        ..GnssConfig::default()
    };
    let mut cases = Vec::new();
    for profile in [FilterProfile::Eskf, FilterProfile::Paper] {
        let mut lever = VehicleConfig {
            gnss: Some(GnssConfig {
                lever_arm_body_m: Vector3::new(1e300, 0.0, 0.0),
                ..gnss
            }),
            profile,
            ..Default::default()
        };
        lever.imu.rate_hz = 200.0;
        let mut noise = VehicleConfig {
            gnss: Some(gnss),
            profile,
            ..Default::default()
        };
        noise.imu.gyro_noise_density = 1e300;
        noise.imu.accel_noise_density = 1e300;
        cases.push((format!("{profile:?} lever arm 1e300"), lever));
        cases.push((format!("{profile:?} noise 1e300"), noise));
    }
    let mut total_resets = 0;
    for (name, config) in cases {
        let (poses, diverged, resets) = run(&config);
        let bad = poses.iter().filter(|p| !sound(p)).count();
        assert_eq!(bad, 0, "{name}: {bad} of {} poses not finite", poses.len());
        if resets > 0 {
            assert!(diverged, "{name}: reset without reporting DIVERGED");
        }
        eprintln!(
            "{name}: {} poses, all finite; {resets} divergence resets",
            poses.len()
        );
        total_resets += resets;
    }
    assert!(
        total_resets > 0,
        "no case diverged: the guard was not exercised"
    );
    // A sound configuration never diverges.
    let (poses, diverged, resets) = run(&VehicleConfig {
        gnss: Some(gnss),
        ..Default::default()
    });
    assert!(!diverged && resets == 0 && poses.len() > 3000);
}
