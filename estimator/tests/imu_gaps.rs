//! A link that drops for a few seconds: every sensor of a simulated flight withheld over a window,
//! as a ground station streaming telemetry sees it. Both profiles bridge gaps up to
//! `EstimatorParams::max_bridge_gap_ns` (integrating across with the samples either side and
//! widening the covariance) instead of restarting, which forgot the heading a vehicle without a
//! compass had found; longer gaps still restart.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

mod common;

use uavnav_core::rotation::wrap_pi;
use uavnav_core::truth::truth_at;
use uavnav_core::{Airframe, FilterProfile, PoseOutput};
use uavnav_estimator::{Estimator, EstimatorParams};
use uavnav_sim::{Flight, Scenario};

fn flight(name: &str) -> Flight {
    let path = format!("{}/../scenarios/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let mut s = Scenario::from_toml_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    s.mag = None;
    Flight::new(&s).unwrap()
}

/// Feeds every sensor of `f` but what falls in `[from_s, to_s)` after its start; returns the
/// poses and the estimator.
fn fly_with_gap(
    f: &Flight,
    airframe: Airframe,
    params: EstimatorParams,
    gap: (f64, f64),
) -> (Vec<PoseOutput>, Estimator) {
    fly_profile_with_gap(f, FilterProfile::Eskf, airframe, params, gap)
}

/// [`fly_with_gap`] with the profile given.
fn fly_profile_with_gap(
    f: &Flight,
    profile: FilterProfile,
    airframe: Airframe,
    params: EstimatorParams,
    (from_s, to_s): (f64, f64),
) -> (Vec<PoseOutput>, Estimator) {
    let mut config = f.vehicle_config();
    config.airframe = airframe;
    config.profile = profile;
    let mut est = Estimator::new(&config, params, Some(f.origin()));
    let t0 = f.scenario().t0_ns;
    let kept = |t: i64| {
        let s = (t - t0) as f64 * 1e-9;
        s < from_s || s >= to_s
    };
    let out = common::fly_where(&mut est, f, kept, kept);
    (out, est)
}

/// From `after_s` on: the share of poses with every attitude axis within 3σ, and the RMS yaw
/// error, rad.
fn scores(f: &Flight, poses: &[PoseOutput], after_s: f64) -> (f64, f64) {
    let t_after = f.scenario().t0_ns + (after_s * 1e9) as i64;
    let (mut within, mut n, mut sq) = (0usize, 0usize, 0.0);
    for p in poses.iter().filter(|p| p.t_ns >= t_after) {
        let t = truth_at(f.truth(), p.t_ns).unwrap();
        let e = (p.nav_from_body * t.nav_from_body.inverse()).scaled_axis();
        let yaw = wrap_pi(p.euler_rad.z - t.nav_from_body.euler_angles().2);
        n += 1;
        sq += yaw * yaw;
        if (0..3).all(|k| e[k].abs() <= 3.0 * p.sigma_att_rad[k]) {
            within += 1;
        }
    }
    (
        within as f64 / n.max(1) as f64,
        (sq / n.max(1) as f64).sqrt(),
    )
}

fn restarting() -> EstimatorParams {
    EstimatorParams {
        max_bridge_gap_ns: 0,
        ..EstimatorParams::default()
    }
}

#[test]
fn a_dropped_link_is_bridged_and_the_heading_kept() {
    // (scenario, airframe, gap, scored from)
    let cases = [
        ("multirotor", Airframe::Multirotor, (30.0, 32.0), 32.0),
        ("multirotor", Airframe::Multirotor, (44.0, 48.5), 48.5),
        ("mag-baro", Airframe::Unknown, (15.0, 17.0), 17.0),
        // Into the dash and the half turn at 60°/s: the rates either side differ.
        ("multirotor", Airframe::Multirotor, (35.5, 37.5), 37.5),
        // Into the fixed wing's turn.
        ("mag-baro", Airframe::FixedWing, (5.0, 7.0), 7.0),
    ];
    for (name, airframe, gap, after) in cases {
        let f = flight(name);
        let (bridged, est) = fly_with_gap(&f, airframe, EstimatorParams::default(), gap);
        let h = est.health();
        let (within, yaw_rms) = scores(&f, &bridged, after);
        let (restarted, old) = fly_with_gap(&f, airframe, restarting(), gap);
        let (within_r, yaw_rms_r) = scores(&f, &restarted, after);
        eprintln!(
            "{name} {airframe:?}, gap {gap:?} s: bridged ({} bridged, {} restarts): attitude \
             within 3 sigma {:.1} %, yaw RMS {:.2} deg; restarting ({} refused): {:.1} %, {:.2} deg",
            h.imu_gaps_bridged,
            h.divergence_resets,
            100.0 * within,
            yaw_rms.to_degrees(),
            old.health().inputs_rejected,
            100.0 * within_r,
            yaw_rms_r.to_degrees(),
        );
        assert_eq!(h.imu_gaps_bridged, 1, "{name}");
        assert_eq!(h.inputs_rejected, 0, "{name}");
        assert!(within >= 0.95, "{name} {gap:?}: {within}");
        assert!(
            yaw_rms < 3f64.to_radians(),
            "{name} {gap:?}: {}",
            yaw_rms.to_degrees()
        );
        assert!(yaw_rms < yaw_rms_r, "{name} {gap:?}");
    }
}

#[test]
fn a_long_gap_still_restarts() {
    let f = flight("multirotor");
    let (poses, est) = fly_with_gap(
        &f,
        Airframe::Multirotor,
        EstimatorParams::default(),
        (30.0, 40.0),
    );
    let h = est.health();
    assert_eq!(h.imu_gaps_bridged, 0);
    // Refused until five continuous samples, then restarted.
    assert_eq!(h.inputs_rejected, 5);
    let t40 = f.scenario().t0_ns + 40_000_000_000;
    assert!(poses.iter().any(|p| p.t_ns > t40));
}

/// The `paper` profile bridges the same gaps (both its filters running, with GNSS): eq. G1 on its
/// attitude and position/velocity filters, the tilt window across the gap dropped.
#[test]
fn the_paper_profile_bridges_too() {
    let cases = [
        ("multirotor", Airframe::Multirotor, (30.0, 32.0), 32.0),
        ("mag-baro", Airframe::FixedWing, (15.0, 17.0), 17.0),
    ];
    for (name, airframe, gap, after) in cases {
        let f = flight(name);
        let p = FilterProfile::Paper;
        let (bridged, est) = fly_profile_with_gap(&f, p, airframe, EstimatorParams::default(), gap);
        let (within, yaw_rms) = scores(&f, &bridged, after);
        let (restarted, _) = fly_profile_with_gap(&f, p, airframe, restarting(), gap);
        let (within_r, yaw_rms_r) = scores(&f, &restarted, after);
        let h = est.health();
        eprintln!(
            "paper {name} {airframe:?}, gap {gap:?} s: bridged ({}): attitude within 3 sigma \
             {:.1} %, yaw RMS {:.2} deg; restarting: {:.1} %, {:.2} deg",
            h.imu_gaps_bridged,
            100.0 * within,
            yaw_rms.to_degrees(),
            100.0 * within_r,
            yaw_rms_r.to_degrees(),
        );
        assert_eq!(h.imu_gaps_bridged, 1, "{name}");
        assert!(within >= 0.9, "{name}: {within}");
        // The fixed wing restarted takes its heading from the course at once (0.11°): bridged
        // it keeps its own, within 1°.
        assert!(yaw_rms <= yaw_rms_r.max(1f64.to_radians()), "{name}");
    }
}
