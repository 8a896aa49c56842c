//! Both profiles without GNSS (`eskf::gnssless`, `paper::gnssless`) on the simulated multirotor
//! (`scenarios/multirotor.toml`: hover, yaw in place, forward, sideways and backward flight, an
//! aggressive dash): attitude only, roll and pitch held by gravity, the heading by the compass
//! (`eskf`; `paper` reads none and says the heading is unknown); and a flight whose GNSS comes
//! late runs from its first fix exactly as if the filter had waited.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

mod common;

use uavnav_core::rotation::euler_error;
use uavnav_core::truth::truth_at;
use uavnav_core::{FilterProfile, Mode, VehicleConfig};
use uavnav_estimator::{Estimator, EstimatorParams, PoseOutput};
use uavnav_sim::{Flight, Scenario};

const S: i64 = 1_000_000_000;

fn flight() -> Flight {
    let path = format!(
        "{}/../scenarios/multirotor.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(path).unwrap();
    Flight::new(&Scenario::from_toml_str(&text).unwrap()).unwrap()
}

/// Feeds the flight in time order, GNSS only from `gnss_from_ns`; returns the poses.
fn fly(est: &mut Estimator, f: &Flight, gnss_from_ns: Option<i64>) -> Vec<PoseOutput> {
    common::fly_where(est, f, |t| gnss_from_ns.is_some_and(|g| t >= g), |_| true)
}

/// (roll/pitch/yaw RMSE, fraction of attitude axes within 3σ) after `after_ns`, rad.
fn attitude_scores(f: &Flight, poses: &[PoseOutput], after_ns: i64) -> ([f64; 3], f64) {
    let (mut sq, mut within, mut n) = ([0.0; 3], 0usize, 0usize);
    for p in poses.iter().filter(|p| p.t_ns >= after_ns) {
        let t = truth_at(f.truth(), p.t_ns).unwrap();
        let e = euler_error(&p.nav_from_body, &t.nav_from_body);
        for k in 0..3 {
            sq[k] += e[k] * e[k];
            within += usize::from(e[k].abs() <= 3.0 * p.sigma_att_rad[k]);
        }
        n += 1;
    }
    assert!(n > 0);
    (
        sq.map(|s| (s / n as f64).sqrt()),
        within as f64 / (3 * n) as f64,
    )
}

/// Checks a run without GNSS (first pose within `first_within_ns` of the first IMU sample,
/// attitude only throughout, every attitude σ finite and positive) and prints and returns its
/// roll/pitch/yaw RMSE in degrees after 30 s and the fraction within 3σ.
fn attitude_only_scores(
    label: &str,
    f: &Flight,
    poses: &[PoseOutput],
    first_within_ns: i64,
) -> ([f64; 3], f64) {
    let t0 = f.imu()[0].t_ns;
    assert!(
        poses.first().unwrap().t_ns - t0 < first_within_ns,
        "{label}: first pose late"
    );
    assert!(poses.iter().all(|p| p.health.mode == Mode::AttitudeOnly));
    assert!(
        poses
            .iter()
            .all(|p| p.sigma_att_rad.iter().all(|s| s.is_finite() && *s > 0.0))
    );
    let (rmse, within) = attitude_scores(f, poses, t0 + 30 * S);
    let deg = rmse.map(f64::to_degrees);
    eprintln!(
        "{label}: roll/pitch/yaw RMSE {:.2}/{:.2}/{:.2} deg, {:.1} % within 3 sigma",
        deg[0],
        deg[1],
        deg[2],
        100.0 * within
    );
    (deg, within)
}

#[test]
fn without_gnss_the_attitude_is_held_by_gravity_and_the_compass() {
    let f = flight();
    let config = VehicleConfig {
        gnss: None,
        ..f.vehicle_config()
    };
    // Where the vehicle is is not known either: the compass is fused against its own field.
    let mut est = Estimator::new(&config, EstimatorParams::default(), None);
    let poses = fly(&mut est, &f, None);
    // A vehicle without a receiver starts once level (the 0.5 s window, behind the horizon).
    let (deg, within) = attitude_only_scores("multirotor without GNSS", &f, &poses, S);
    assert!(deg[0] < 2.0 && deg[1] < 2.0, "{deg:?}");
    assert!(deg[2] < 10.0, "{deg:?}");
    assert!(within >= 0.95, "{within}");
    let h = est.health();
    assert!(h.mag.fused > 0, "compass never fused");
    // The hold is a source like the others: in the health and in every pose's summary.
    assert!(h.position_hold.fused > 0, "position hold never fused");
    let last = poses.last().unwrap().health.position_hold;
    assert_eq!(last.fused, h.position_hold.fused);
    assert!(last.test_ratio.is_finite());
}

#[test]
fn a_late_first_fix_starts_the_filter_as_if_it_had_waited() {
    for profile in [FilterProfile::Eskf, FilterProfile::Paper] {
        late_first_fix(profile);
    }
}

fn late_first_fix(profile: FilterProfile) {
    let f = flight();
    let config = VehicleConfig {
        profile,
        ..f.vehicle_config()
    };
    let late = f.imu()[0].t_ns + 25 * S;
    let waited = EstimatorParams {
        start_without_gnss_after_s: f64::INFINITY,
        ..EstimatorParams::default()
    };
    let mut a = Estimator::new(&config, EstimatorParams::default(), None);
    let mut b = Estimator::new(&config, waited, None);
    let with_start = fly(&mut a, &f, Some(late));
    let without = fly(&mut b, &f, Some(late));
    let first_fix_pose = without.first().unwrap().t_ns;
    // Attitude only from 10 s, then the same poses, bit for bit, from the first fix on.
    let early: Vec<&PoseOutput> = with_start
        .iter()
        .filter(|p| p.t_ns < first_fix_pose)
        .collect();
    assert!(!early.is_empty());
    assert!(early.iter().all(|p| p.health.mode == Mode::AttitudeOnly));
    let rest: Vec<PoseOutput> = with_start
        .iter()
        .filter(|p| p.t_ns >= first_fix_pose)
        .copied()
        .collect();
    assert_eq!(rest.len(), without.len(), "{profile:?}");
    assert!(
        rest == without,
        "{profile:?}: the poses after the first fix differ"
    );
}

#[test]
fn the_paper_profile_without_gnss_holds_roll_and_pitch_and_says_the_heading_is_unknown() {
    let f = flight();
    let config = VehicleConfig {
        gnss: None,
        profile: FilterProfile::Paper,
        ..f.vehicle_config()
    };
    let mut est = Estimator::new(&config, EstimatorParams::default(), None);
    let poses = fly(&mut est, &f, None);
    // Started once level (the paper's levelling window at 200 Hz).
    let (deg, within) = attitude_only_scores("paper, multirotor without GNSS", &f, &poses, 2 * S);
    assert!(deg[0] < 3.0 && deg[1] < 3.0, "{deg:?}");
    assert!(within >= 0.95, "{within}");
    // No compass in this profile: the heading stays unknown, and its σ says so.
    let last = poses.last().unwrap();
    assert!(last.sigma_att_rad.z > 1.0, "{}", last.sigma_att_rad.z);
    let h = est.health();
    assert!(h.gnss_tilt.fused > 10, "{:?}", h.gnss_tilt);
    assert_eq!(h.divergence_resets, 0);
}
