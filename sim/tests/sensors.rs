//! IMU, GNSS and determinism checks on the smoke and paper scenarios.
#![allow(clippy::unwrap_used)]

use nalgebra::Vector3;
use uavnav_core::{Lla, SensorEvent};
use uavnav_sim::sensors::antenna_state;
use uavnav_sim::{Flight, Scenario};

const SMOKE: &str = include_str!("../../scenarios/smoke.toml");
const PAPER_BIG: &str = include_str!("../../scenarios/paper-big-lever.toml");

fn smoke() -> Scenario {
    Scenario::from_toml_str(SMOKE).unwrap()
}

#[test]
fn level_flight_accelerometer_reads_minus_gravity() {
    let flight = Flight::new(&smoke()).unwrap();
    let s = flight.ideal_imu()[0];
    // Level, unaccelerated, pitch = α = 2°: f ≈ C_n^b (0, 0, −g), so f_x ≈ g·sin α, f_z ≈ −g·cos α.
    let g = 9.80;
    let alpha = 2f64.to_radians();
    assert!(
        (s.accel_mps2.x - g * alpha.sin()).abs() < 0.02,
        "{:?}",
        s.accel_mps2
    );
    assert!(
        (s.accel_mps2.z + g * alpha.cos()).abs() < 0.02,
        "{:?}",
        s.accel_mps2
    );
    // Only the Earth rate in straight flight: |ω| = Ω.
    assert!((s.gyro_radps.norm() - 7.292_115e-5).abs() < 1e-9);
}

#[test]
fn gnss_lever_arm_holds_without_noise() {
    let mut sc = Scenario::from_toml_str(PAPER_BIG).unwrap();
    sc.duration_s = 60.0;
    let g = &mut sc.gnss;
    (
        g.white_sigma_h_m,
        g.white_sigma_v_m,
        g.gm_sigma_h_m,
        g.gm_sigma_v_m,
        g.vel_sigma_mps,
    ) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let flight = Flight::new(&sc).unwrap();
    let frame = flight.local_frame();
    let lever = Vector3::new(10.0, 10.0, 10.0);
    let dt_ns = flight.truth()[1].t_ns - flight.truth()[0].t_ns;
    let mut max_vel_lever = 0.0f64;
    for fix in flight.gnss() {
        let k = ((fix.t_ns - flight.truth()[0].t_ns) / dt_ns) as usize;
        let t = &flight.truth()[k];
        // Body rate by central difference of the truth attitude.
        let (a, b) = (
            &flight.truth()[k.saturating_sub(1)],
            &flight.truth()[(k + 1).min(flight.truth().len() - 1)],
        );
        let omega = (a.nav_from_body.inverse() * b.nav_from_body).scaled_axis()
            / ((b.t_ns - a.t_ns) as f64 * 1e-9);
        let (p_ant, v_ant) = antenna_state(
            &t.pos_ned_m,
            &t.vel_ned_mps,
            &t.nav_from_body,
            &omega,
            &lever,
        );
        let ned = frame.lla_to_ned(&Lla::from_deg(fix.lat_deg, fix.lon_deg, fix.alt_m));
        assert!(
            (ned - p_ant).norm() < 1e-3,
            "position at {}: {:?} vs {:?}",
            fix.t_ns,
            ned,
            p_ant
        );
        assert!(
            (fix.velocity.unwrap().ned_mps().unwrap() - v_ant).norm() < 1e-3,
            "velocity at {}",
            fix.t_ns
        );
        max_vel_lever = max_vel_lever.max((v_ant - t.vel_ned_mps).norm());
    }
    // The flight turns, so the lever arm moves the antenna velocity by a visible amount.
    assert!(max_vel_lever > 0.5, "{max_vel_lever}");
}

#[test]
fn outages_and_glitches() {
    let flight = Flight::new(&smoke()).unwrap();
    let t0 = flight.truth()[0].t_ns;
    let times: Vec<f64> = flight
        .gnss()
        .iter()
        .map(|g| (g.t_ns - t0) as f64 * 1e-9)
        .collect();
    assert!(
        times.iter().all(|t| !(12.0..15.0).contains(t)),
        "fix inside the outage"
    );
    assert!(times.iter().any(|t| *t > 15.0) && times.iter().any(|t| *t < 12.0));
    // 20 s at 5 Hz = 101 epochs, 15 of them (12.0 … 14.8 s) in the outage.
    assert_eq!(flight.gnss().len(), 101 - 15);
    let paper = Flight::new(&Scenario::from_toml_str(PAPER_BIG).unwrap()).unwrap();
    let t0 = paper.truth()[0].t_ns;
    assert!(
        paper
            .gnss()
            .iter()
            .all(|g| !(120.0..240.0).contains(&((g.t_ns - t0) as f64 * 1e-9)))
    );
    for g in paper.gnss() {
        assert!(g.sigma_h_m > 1.0 && g.sigma_v_m > 1.0 && g.num_sats > 4);
    }
}

#[test]
fn same_seed_same_values_different_seed_different_noise() {
    let a = Flight::new(&smoke()).unwrap();
    let b = Flight::new(&smoke()).unwrap();
    assert_eq!(a.imu(), b.imu());
    assert_eq!(a.gnss(), b.gnss());
    assert_eq!(a.truth(), b.truth());
    for i in [0, 57, 199] {
        assert_eq!(
            a.render_frame(i).unwrap().data,
            b.render_frame(i).unwrap().data,
            "frame {i}"
        );
    }
    let mut other = smoke();
    other.seed += 1;
    let c = Flight::new(&other).unwrap();
    assert_ne!(a.imu()[10].gyro_radps, c.imu()[10].gyro_radps);
    assert_ne!(a.gnss()[3].lat_deg, c.gnss()[3].lat_deg);
    assert_ne!(
        a.render_frame(0).unwrap().data,
        c.render_frame(0).unwrap().data
    );
    // The trajectory itself does not depend on the seed.
    assert_eq!(a.truth()[500].pos_ned_m, c.truth()[500].pos_ned_m);
}

#[test]
fn imu_noise_has_the_configured_size() {
    let mut sc = smoke();
    (sc.imu.gyro_bias_sigma_radps, sc.imu.accel_bias_sigma_mps2) = (0.0, 0.0);
    (sc.imu.gyro_random_walk, sc.imu.accel_random_walk) = (0.0, 0.0);
    let f = Flight::new(&sc).unwrap();
    let ideal = f.ideal_imu();
    let n = ideal.len() as f64;
    let var: f64 = f
        .imu()
        .iter()
        .zip(&ideal)
        .map(|(m, i)| (m.gyro_radps - i.gyro_radps).norm_squared())
        .sum::<f64>()
        / (3.0 * n);
    let expect = sc.imu.gyro_noise_density.powi(2) * sc.imu.rate_hz;
    assert!(
        (var / expect - 1.0).abs() < 0.05,
        "gyro noise variance {var} vs {expect}"
    );
}

#[test]
fn events_are_time_ordered_and_complete() {
    let mut sc = smoke();
    sc.duration_s = 3.0;
    let f = Flight::new(&sc).unwrap();
    let events: Vec<SensorEvent> = f.events().collect::<Result<_, _>>().unwrap();
    assert_eq!(
        events.len(),
        f.imu().len() + f.gnss().len() + f.camera_times_ns().len()
    );
    let rank = SensorEvent::rank;
    for w in events.windows(2) {
        assert!((w[0].t_ns(), rank(&w[0])) <= (w[1].t_ns(), rank(&w[1])));
    }
    assert!(matches!(events[0], SensorEvent::Imu(_)) && matches!(events[1], SensorEvent::Gnss(_)));
    assert!(matches!(events[2], SensorEvent::Camera(_)));
}
