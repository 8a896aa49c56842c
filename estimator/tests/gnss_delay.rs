//! The GNSS velocity's delay learnt from the data (`gnss_delay`, eq. L1) on a simulated fixed
//! wing (`scenarios/paper-small-lever.toml` without its camera and its outage) whose receiver
//! delay is stated wrongly: the fixes are valid at their stamps, the configuration says 0.2 s
//! before. A seeded scenario test; the shared real flights have theirs in `real_flights.rs`.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use uavnav_core::truth::truth_at;
use uavnav_estimator::{Estimator, EstimatorParams, PoseOutput};
use uavnav_sim::{Flight, Scenario};

fn flight() -> Flight {
    let path = format!(
        "{}/../scenarios/paper-small-lever.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let mut s = Scenario::from_toml_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    s.camera.enabled = false;
    s.gnss.outages.clear();
    Flight::new(&s).unwrap()
}

/// Runs the ESKF with the GNSS delay stated as `stated_ns`; the poses and the delay it ended with.
fn run(f: &Flight, stated_ns: i64, learn: bool) -> (Vec<PoseOutput>, f64) {
    let mut config = f.vehicle_config();
    if let Some(g) = config.gnss.as_mut() {
        g.delay_ns = stated_ns;
    }
    let params = EstimatorParams {
        learn_gnss_delay: learn,
        ..EstimatorParams::default()
    };
    let mut est = Estimator::new(&config, params, Some(f.origin()));
    let mut g = 0;
    let mut out = Vec::new();
    for s in f.imu() {
        while g < f.gnss().len() && f.gnss()[g].t_ns <= s.t_ns {
            est.push_gnss(&f.gnss()[g]).unwrap();
            g += 1;
        }
        if let Some(p) = est.push_imu(s).unwrap() {
            out.push(p);
        }
    }
    let delay_s = est.health().gnss_velocity_delay_s.unwrap();
    (out, delay_s)
}

/// RMS tilt error (the global attitude error's north and east parts) after `after_s`, rad.
fn tilt_rms(f: &Flight, poses: &[PoseOutput], after_s: f64) -> f64 {
    let t_after = f.scenario().t0_ns + (after_s * 1e9) as i64;
    let (mut sq, mut n) = (0.0, 0usize);
    for p in poses.iter().filter(|p| p.t_ns >= t_after) {
        let t = truth_at(f.truth(), p.t_ns).unwrap();
        let e = (p.nav_from_body * t.nav_from_body.inverse()).scaled_axis();
        sq += e.x * e.x + e.y * e.y;
        n += 1;
    }
    (sq / n.max(1) as f64).sqrt()
}

#[test]
fn a_wrongly_stated_delay_is_learnt_and_the_tilt_follows() {
    let f = flight();
    let (right, right_delay) = run(&f, 0, true);
    let (fixed, _) = run(&f, 200_000_000, false);
    let (learnt, delay_s) = run(&f, 200_000_000, true);
    let [r, x, l] = [&right, &fixed, &learnt].map(|p| tilt_rms(&f, p, 60.0).to_degrees());
    eprintln!(
        "tilt RMS after 60 s: delay stated right {r:.3} deg, 0.2 s too long {x:.3} deg, the same \
         learnt {l:.3} deg (learnt {delay_s:.3} s)"
    );
    // Stated right, nothing moves.
    assert_eq!(right_delay, 0.0);
    // The learner finds the velocity's true delay (0.033 s when written; the positions, still
    // fused 0.2 s early, pull the attitude it integrates with a little towards the stated one).
    assert!(delay_s.abs() <= 0.08, "{delay_s}");
    // Tilt RMS 0.211 -> 0.175 deg when written (0.028 deg with the delay stated right: the rest
    // is the positions' timing, which the learner leaves as stated).
    assert!(l < 0.9 * x, "learnt {l} deg, not learnt {x} deg");
}
