//! CPU-time helper for a loaded machine (criterion's wall clock suffers when cores are shared):
//! `/usr/bin/time -f %U target/release/examples/speed MODE REPEATS` with MODE = sim | eskf | eskf-video | paper | gnss-update;
//! (user time of MODE − user time of `sim`) / (REPEATS × samples) is the per-sample cost.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

#[path = "../tests/common/mod.rs"]
mod common;

use common::{Oracle, RunCfg, run, scenario};
use uavnav_core::FilterProfile;
use uavnav_sim::Flight;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mode = args.first().cloned().unwrap_or_else(|| "eskf".into());
    let repeats: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(5);
    let s = scenario("paper-small-lever", None);
    let flight = Flight::new(&s).expect("flight");
    let cfg = match mode.as_str() {
        "sim" => return println!("{} IMU samples", flight.imu().len()),
        "gnss-update" => return gnss_updates(&flight, repeats),
        "eskf" => RunCfg::new(FilterProfile::Eskf, true, None),
        "eskf-video" => RunCfg::new(FilterProfile::Eskf, true, Some(Oracle::default())),
        _ => RunCfg::new(FilterProfile::Paper, true, None),
    };
    let mut n = 0;
    for _ in 0..repeats {
        n += run(&flight, &cfg).len();
    }
    println!(
        "{n} outputs over {repeats} runs of {} IMU samples",
        flight.imu().len()
    );
}

/// `repeats` × 100 000 GNSS position+velocity updates on a mid-flight ESKF state.
fn gnss_updates(flight: &Flight, repeats: usize) {
    use nalgebra::Vector3;
    use uavnav_estimator::aid_sources::gnss_pos::{GnssMeas, GnssPosSource, white_noise};
    use uavnav_estimator::aid_sources::gnss_vel::GnssVelSource;
    let mut vc = flight.vehicle_config();
    vc.camera = None;
    let mut est = uavnav_estimator::Estimator::new(&vc, Default::default(), Some(flight.origin()));
    let mut gi = 0;
    for s in &flight.imu()[..8000] {
        while gi < flight.gnss().len() && flight.gnss()[gi].t_ns <= s.t_ns {
            est.push_gnss(&flight.gnss()[gi]).unwrap();
            gi += 1;
        }
        est.push_imu(s).unwrap();
    }
    let eskf = est.eskf().unwrap();
    let x = *eskf.nominal().unwrap();
    let p0 = *eskf.covariance();
    let lever = Vector3::new(0.0, 2.0, 0.0);
    let m = GnssMeas {
        t_ns: x.t_ns,
        pos_ned_m: x.p + x.q * lever + Vector3::new(0.3, -0.2, 0.5),
        vel_ned_mps: Some(x.v + Vector3::new(0.02, 0.01, -0.03)),
        vel_h_mps: Some((x.v + Vector3::new(0.02, 0.01, -0.03)).xy()),
        sigma_h_m: 1.58,
        sigma_v_m: 2.6,
        sigma_vel_mps: 0.05,
    };
    let r = white_noise(&m, 0.9, 0.05);
    let gyro = Vector3::new(0.01, -0.02, 0.05);
    let w_ie = Vector3::new(5e-5, 0.0, -4e-5);
    let mut acc = 0.0;
    for _ in 0..repeats * 100_000 {
        let mut p = std::hint::black_box(p0);
        let (mut sp, mut sv) = (GnssPosSource::default(), GnssVelSource::default());
        let a = sp.fuse(&x, &mut p, &lever, &m, &r, 3.29, 5_000_000_000, &[]);
        let v = sv.fuse(
            &x,
            &mut p,
            &lever,
            &gyro,
            1e-6,
            &w_ie,
            &m,
            3.29,
            5_000_000_000,
            &[],
        );
        acc += a.map_or(0.0, |d| d[0]) + v.map_or(0.0, |d| d[3]) + p[(0, 0)];
    }
    println!("{} updates (checksum {acc:.3})", repeats * 100_000);
}
