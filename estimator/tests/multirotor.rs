//! The heading on a simulated multirotor (`scenarios/multirotor.toml`: hover, yaw in place,
//! forward, sideways and backward flight, an aggressive dash): what the real quadcopters showed.
//! Without a magnetometer the yaw bank must find the heading from any start and the filter must
//! never be confidently wrong before it does; with a compass reading 0.7 of the model strength
//! the heading must be right from the start.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

mod common;

use common::fly_all;
use uavnav_core::rotation::wrap_pi;
use uavnav_core::truth::truth_at;
use uavnav_estimator::eskf::HeadingSource;
use uavnav_estimator::health::MagStatus;
use uavnav_estimator::paper::heading::BankState;
use uavnav_estimator::{Estimator, EstimatorParams, PoseOutput};
use uavnav_sim::scenario::{MagDisturbanceSpec, WindowSpec};
use uavnav_sim::{Flight, Scenario};

fn flight(heading_deg: f64, with_mag: bool) -> Flight {
    let text = multirotor_toml();
    assert!(text.contains("heading_deg = 0.0"));
    let text = text.replace(
        "heading_deg = 0.0",
        &format!("heading_deg = {heading_deg:.1}"),
    );
    let mut s = Scenario::from_toml_str(&text).unwrap();
    if !with_mag {
        s.mag = None;
    }
    Flight::new(&s).unwrap()
}

/// The text of `scenarios/multirotor.toml`.
fn multirotor_toml() -> String {
    let path = format!(
        "{}/../scenarios/multirotor.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    std::fs::read_to_string(path).unwrap()
}

/// `scenarios/multirotor.toml` as committed.
fn multirotor_scenario() -> Scenario {
    Scenario::from_toml_str(&multirotor_toml()).unwrap()
}

/// Runs the ESKF over every sensor of the flight; returns the poses and the heading source at the end.
fn run(f: &Flight) -> (Vec<PoseOutput>, HeadingSource) {
    run_with(f, &f.vehicle_config())
}

/// [`run`] with the vehicle configuration given.
fn run_with(f: &Flight, config: &uavnav_core::VehicleConfig) -> (Vec<PoseOutput>, HeadingSource) {
    let mut est = Estimator::new(config, EstimatorParams::default(), Some(f.origin()));
    let out = fly_all(&mut est, f);
    let src = est.eskf().unwrap().heading_source();
    (out, src)
}

/// (fraction of poses with |yaw error| ≤ 3σ, max |yaw error| after `after_s`, rad).
fn yaw_scores(f: &Flight, poses: &[PoseOutput], after_s: f64) -> (f64, f64) {
    let t_after = f.scenario().t0_ns + (after_s * 1e9) as i64;
    let (mut within, mut n, mut max_after) = (0usize, 0usize, 0.0f64);
    for p in poses {
        let t = truth_at(f.truth(), p.t_ns).unwrap();
        let e = wrap_pi(p.euler_rad.z - t.nav_from_body.euler_angles().2).abs();
        n += 1;
        if e <= 3.0 * p.sigma_att_rad.z {
            within += 1;
        } else if std::env::var("UAVNAV_MISSES").is_ok() {
            eprintln!(
                "miss t {:.2} err {:.2} sigma {:.2}",
                (p.t_ns - f.scenario().t0_ns) as f64 * 1e-9,
                e.to_degrees(),
                p.sigma_att_rad.z.to_degrees()
            );
        }
        if p.t_ns >= t_after {
            max_after = max_after.max(e);
        }
    }
    (within as f64 / n as f64, max_after)
}

/// The longest run of GNSS fixes refused in a row (position or velocity) while the heading is
/// still unknown (yaw σ above 90°), from the counters every pose carries.
fn longest_unaligned_rejection_run(poses: &[PoseOutput]) -> u64 {
    let (mut last_rej, mut last_fused, mut run, mut longest) = (0u64, 0u64, 0u64, 0u64);
    for p in poses {
        let h = &p.health;
        let rej = h.gnss_pos.rejected + h.gnss_vel.rejected;
        let fused = h.gnss_pos.fused + h.gnss_vel.fused;
        if fused > last_fused {
            run = 0;
        }
        if rej > last_rej && p.sigma_att_rad.z > std::f64::consts::FRAC_PI_2 {
            run += 1;
            longest = longest.max(run);
        }
        (last_rej, last_fused) = (rej, fused);
    }
    longest
}

#[test]
fn yaw_bank_finds_the_heading_from_every_start_without_a_magnetometer() {
    let only: Option<usize> = std::env::var("UAVNAV_START")
        .ok()
        .and_then(|v| v.parse().ok());
    for k in (0..12).filter(|k| only.is_none_or(|o| o == *k)) {
        let heading = -180.0 + 30.0 * k as f64 + 7.0;
        let f = flight(heading, false);
        let (poses, src) = run(&f);
        // The vehicle hovers and yaws in place for the first 10 s (nothing tells the heading),
        // then accelerates: from 20 s on the heading must be known within 2° (the issue asks 10°).
        let (within, max_after) = yaw_scores(&f, &poses, 20.0);
        let refused_run = longest_unaligned_rejection_run(&poses);
        eprintln!(
            "heading {heading:6.1}: source {src:?}, within 3 sigma {:.1} %, max |yaw error| after 20 s {:.2} deg, longest run of GNSS refused before alignment {refused_run}",
            100.0 * within,
            max_after.to_degrees()
        );
        assert_eq!(src, HeadingSource::YawEstimator, "heading {heading}");
        // 95 % is the target: every start meets it (99.6–100 %), since the velocity is reset to
        // the GNSS velocity when the bank hands over the heading (`Eskf::reset_velocity_to_gnss`).
        // Before, from 37° the bank handed over a heading 11.8° off, the velocity propagated
        // under the unknown heading was 0.8 m/s off, and the filter's yaw settled 5° off with σ
        // 0.4° (81.9 %); from −53°, 2.4° off (91.1 %).
        assert!(within >= 0.95, "heading {heading}: {within}");
        // Before the heading is known the inertial prediction is no evidence against a fix: the
        // second refused in a row is taken with a reset.
        assert!(refused_run <= 1, "heading {heading}: {refused_run}");
        assert!(
            max_after < 2f64.to_radians(),
            "heading {heading}: {max_after}"
        );
    }
}

/// Per NED horizontal axis: the fraction of poses whose tilt error (the global attitude error
/// `log(C_est C_trueᵀ)`, north and east) is within 3σ, and its RMS, rad.
fn tilt_scores(f: &Flight, poses: &[PoseOutput]) -> ([f64; 2], [f64; 2]) {
    let (mut within, mut sq) = ([0usize; 2], [0.0f64; 2]);
    for p in poses {
        let t = truth_at(f.truth(), p.t_ns).unwrap();
        let e = (p.nav_from_body * t.nav_from_body.inverse()).scaled_axis();
        for k in 0..2 {
            sq[k] += e[k] * e[k];
            if e[k].abs() <= 3.0 * p.sigma_att_rad[k] {
                within[k] += 1;
            } else if std::env::var("UAVNAV_MISSES").is_ok() && p.t_ns % 100_000_000 == 0 {
                eprintln!(
                    "tilt miss t {:.2} axis {k} err {:.2} sigma {:.2}",
                    (p.t_ns - f.scenario().t0_ns) as f64 * 1e-9,
                    e[k].to_degrees(),
                    p.sigma_att_rad[k].to_degrees()
                );
            }
        }
    }
    let n = poses.len().max(1) as f64;
    (within.map(|w| w as f64 / n), sq.map(|s| (s / n).sqrt()))
}

/// Without a compass and with large turn-on biases (an uncalibrated IMU: 0.02 rad/s and
/// 0.3 m/s² per axis, 1σ): the horizontal accelerometer bias is not learnt while the heading is
/// unknown (`Eskf::heading_unobservable_states`), and what the filter learnt of the tilt under
/// the unknown heading is not trusted once the yaw bank aligns it
/// (`Eskf::forget_horizontal_accel_bias`, eq. A1). Over the whole flight the east tilt was
/// 89.5 % within 3σ with the second alone, 99.6 % with both. Before either, the roll stayed
/// 1–2.5° off at a σ of 0.3–0.6° for 20 s after the alignment and 1.3° off at 0.27° until the
/// dash at 36 s separated tilt from bias (after 30 s, east tilt 68.5 % within 3σ, RMS 0.70°;
/// now 99.2 %, 0.44°).
#[test]
fn large_turn_on_biases_without_a_compass_leave_the_tilt_sigma_honest() {
    let mut s = multirotor_scenario();
    s.mag = None;
    s.imu.gyro_bias_sigma_radps = 0.02;
    s.imu.accel_bias_sigma_mps2 = 0.3;
    let f = Flight::new(&s).unwrap();
    let (poses, src) = run(&f);
    assert_eq!(src, HeadingSource::YawEstimator);
    // Also scored after 30 s, as `estimate --report` scores.
    let t30 = f.scenario().t0_ns + 30_000_000_000;
    let after_30s: Vec<_> = poses.iter().filter(|p| p.t_ns >= t30).copied().collect();
    assert!(after_30s.len() > 4000, "{}", after_30s.len());
    let (whole, _) = tilt_scores(&f, &poses);
    eprintln!(
        "large biases, no compass: tilt within 3 sigma over the whole flight {:.1} / {:.1} %",
        100.0 * whole[0],
        100.0 * whole[1]
    );
    assert!(whole.iter().all(|w| *w >= 0.95), "{whole:?}");
    let (within, rms) = tilt_scores(&f, &after_30s);
    eprintln!(
        "large biases, no compass: tilt within 3 sigma {:.1} / {:.1} %, RMS {:.2} / {:.2} deg",
        100.0 * within[0],
        100.0 * within[1],
        rms[0].to_degrees(),
        rms[1].to_degrees()
    );
    assert!(within.iter().all(|w| *w >= 0.95), "{within:?}");
    assert!(rms.iter().all(|r| *r < 1.5f64.to_radians()), "{rms:?}");
}

#[test]
fn compass_at_0_7_of_the_model_strength_gives_the_heading_from_the_start() {
    let f = flight(0.0, true);
    let (poses, src) = run(&f);
    let (within, max_after) = yaw_scores(&f, &poses, 2.0);
    eprintln!(
        "with magnetometer: source {src:?}, within 3 sigma {:.1} %, max |yaw error| after 2 s {:.2} deg",
        100.0 * within,
        max_after.to_degrees()
    );
    assert_eq!(src, HeadingSource::Magnetometer);
    assert!(within >= 0.95, "{within}");
    assert!(max_after < 5f64.to_radians(), "{max_after}");
}

/// A compass mounted 15° off what the configuration says (under the 45° that counts as a gross
/// contradiction): once the vehicle manoeuvres, the GNSS velocity corrects the heading and the
/// compass does not hold it off, and the yaw σ covers the error. (The floor on the reported σ
/// from the compass's disagreement with the yaw bank, `Eskf::compass_conflict_rad`, is not what
/// carries this flight: it passes without it. It was measured on the public flights of the
/// README's survey, where a compass drifts for a minute in a hover.)
#[test]
fn a_compass_mounted_off_is_not_confidently_wrong() {
    let f = flight(0.0, true);
    let mut config = f.vehicle_config();
    let mag = config.mag.as_mut().unwrap();
    mag.body_from_mag = nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, 15f64.to_radians())
        * mag.body_from_mag;
    let (poses, src) = run_with(&f, &config);
    // For the first 10 s the vehicle hovers and yaws in place: nothing but the compass sees the
    // heading, and nothing can tell it is off. Scored from 20 s, as the bank's test is.
    let t20 = f.scenario().t0_ns + 20_000_000_000;
    let after: Vec<_> = poses.into_iter().filter(|p| p.t_ns >= t20).collect();
    let (within, max_after) = yaw_scores(&f, &after, 20.0);
    eprintln!(
        "compass 15 deg off: source {src:?}, within 3 sigma after 20 s {:.1} %, max |yaw error| {:.2} deg",
        100.0 * within,
        max_after.to_degrees()
    );
    assert_eq!(src, HeadingSource::Magnetometer);
    assert!(max_after < 2f64.to_radians(), "{max_after}");
    assert!(within >= 0.9, "{within}");
}

/// The `paper` profile on the same flight without a magnetometer: its heading comes from the yaw
/// bank (`EstimatorParams::paper_yaw_bank`, our addition), so once the vehicle has accelerated
/// it is known, and before that the stated σ covers the error. With `paper_yaw_bank = false` the
/// profile has no heading for a multirotor at all (it does not take the course as the heading).
#[test]
fn paper_profile_takes_a_multirotor_heading_from_the_yaw_bank() {
    for k in [0usize, 3, 6, 9] {
        let heading = -180.0 + 30.0 * k as f64 + 7.0;
        let f = flight(heading, false);
        let mut config = f.vehicle_config();
        config.profile = uavnav_core::FilterProfile::Paper;
        let run_paper = |params: EstimatorParams| {
            let mut est = Estimator::new(&config, params, Some(f.origin()));
            let out = fly_all(&mut est, &f);
            let source = est.paper().unwrap().heading_source();
            (out, (est.health().yaw_resets, source.state))
        };
        let (poses, (resets, state)) = run_paper(EstimatorParams::default());
        assert_eq!(state, BankState::Active, "heading {heading}");
        let (within, max_after) = yaw_scores(&f, &poses, 30.0);
        eprintln!(
            "paper, heading {heading:6.1}: within 3 sigma {:.1} %, max |yaw error| after 30 s {:.2} deg, yaw resets {resets}",
            100.0 * within,
            max_after.to_degrees()
        );
        assert!(within >= 0.95, "heading {heading}: {within}");
        assert!(
            max_after < 5f64.to_radians(),
            "heading {heading}: {max_after}"
        );
        // As written, the paper's filter never learns this heading (it starts at 0).
        let (as_written, _) = run_paper(EstimatorParams {
            paper_yaw_bank: false,
            ..EstimatorParams::default()
        });
        let (_, max_written) = yaw_scores(&f, &as_written, 30.0);
        if wrap_pi(heading.to_radians()).abs() > 0.5 {
            assert!(max_written > 0.4, "heading {heading}: {max_written}");
        }
    }
}

/// A receiver whose position error wanders with a 20 s correlation time (the scenario's is
/// 300 s) while its velocities stay white: one 5 s window of positions a little over what the
/// receiver states must not be read as a persistent velocity error (`gnss_consistency`, eq. V1),
/// or the velocities are fused 8× too loosely and the vertical velocity follows the wandering
/// positions (with the compass and barometer: vertical 35.2 % within 3σ and 0.59 m/s off at
/// worst before the three-window test; 100 % and 0.075 m/s after).
#[test]
fn positions_that_wander_fast_leave_the_velocity_sigma_honest() {
    let mut s = multirotor_scenario();
    s.gnss.gm_tau_s = 20.0;
    let f = Flight::new(&s).unwrap();
    let (poses, _) = run(&f);
    let t10 = f.scenario().t0_ns + 10_000_000_000;
    let (mut n, mut within, mut worst) = (0usize, [0usize; 3], 0.0f64);
    for p in poses.iter().filter(|p| p.t_ns >= t10) {
        let Some(t) = truth_at(f.truth(), p.t_ns) else {
            continue;
        };
        n += 1;
        for (k, w) in within.iter_mut().enumerate() {
            let e = (p.vel_ned_mps[k] - t.vel_ned_mps[k]).abs();
            worst = worst.max(e);
            if e <= 3.0 * p.sigma_vel_mps[k] {
                *w += 1;
            }
        }
    }
    assert!(n > 8000, "{n}");
    let share = within.map(|w| w as f64 / n as f64);
    eprintln!(
        "GNSS error tau 20 s: velocity within 3 sigma N/E/D {:.1} / {:.1} / {:.1} %, worst error {worst:.3} m/s",
        100.0 * share[0],
        100.0 * share[1],
        100.0 * share[2]
    );
    assert!(share.iter().all(|s| *s >= 0.95), "{share:?}");
    assert!(worst < 0.3, "{worst}");
}

/// Mean attitude NEES over the poses (3 degrees of freedom: the north and east tilt errors and
/// the yaw error against their stated σ; a consistent filter averages about 3), and the share of
/// poses whose yaw error is within 3σ.
fn attitude_nees(f: &Flight, poses: &[PoseOutput]) -> (f64, f64) {
    let (mut sum, mut within) = (0.0, 0usize);
    for p in poses {
        let t = truth_at(f.truth(), p.t_ns).unwrap();
        let e = (p.nav_from_body * t.nav_from_body.inverse()).scaled_axis();
        let e_yaw = wrap_pi(p.euler_rad.z - t.nav_from_body.euler_angles().2);
        let s = p.sigma_att_rad;
        sum += (e.x / s.x).powi(2) + (e.y / s.y).powi(2) + (e_yaw / s.z).powi(2);
        if e_yaw.abs() <= 3.0 * s.z {
            within += 1;
        }
    }
    let n = poses.len().max(1) as f64;
    (sum / n, within as f64 / n)
}

/// A disturbed-field window: start and end, s, and the field added in the body axes, T.
type Disturbance = (f64, f64, [f64; 3]);

/// Magnetometer disturbances on the simulated multirotor, in the body axes, as motor currents
/// or a steel structure passed over make them (the compass reads 0.7 of the model strength, as
/// the scenario says: its horizontal component is about 17 µT there). A gross one (strength
/// off by a third) must be detected and left out; a subtle one, under every detection
/// threshold (3 µT across the field: its heading 10° off while it lasts), cannot be told from
/// the heading, and the attitude must stay consistent through both (mean NEES, yaw within
/// 3σ). The disturbances fall in the forward and sideways legs (12–20 s), and a second gross
/// one in the dash (36–40 s), where the GNSS velocity sees the heading too.
#[test]
fn a_disturbed_compass_leaves_the_attitude_consistent() {
    let cases: [(&str, Vec<Disturbance>); 5] = [
        ("none", vec![]),
        (
            "gross",
            vec![
                (12.0, 20.0, [1.2e-5, -8.0e-6, 4.0e-6]),
                (36.0, 40.0, [-1.0e-5, 0.0, 8.0e-6]),
            ],
        ),
        ("subtle", vec![(12.0, 20.0, [3.0e-6, 0.0, 0.0])]),
        ("subtle in the hover", vec![(0.0, 10.0, [3.0e-6, 0.0, 0.0])]),
        (
            "gross in the yaw turn",
            vec![(4.0, 9.0, [1.2e-5, -8.0e-6, 4.0e-6])],
        ),
    ];
    for (label, windows) in cases {
        let mut s = multirotor_scenario();
        s.mag.as_mut().unwrap().disturbances = windows
            .iter()
            .map(|&(start_s, end_s, field_body_t)| MagDisturbanceSpec {
                window: WindowSpec { start_s, end_s },
                field_body_t,
            })
            .collect();
        let f = Flight::new(&s).unwrap();
        let config = f.vehicle_config();
        let mut est = Estimator::new(&config, EstimatorParams::default(), Some(f.origin()));
        let poses = fly_all(&mut est, &f);
        let eskf = est.eskf().unwrap();
        let disturbed = eskf.mag_source().disturbed;
        let diag = eskf.mag_source().diag;
        let src = eskf.heading_source();
        let t2 = f.scenario().t0_ns + 2_000_000_000;
        let after: Vec<_> = poses.into_iter().filter(|p| p.t_ns >= t2).collect();
        let (nees, within) = attitude_nees(&f, &after);
        let (_, max_yaw) = yaw_scores(&f, &after, 2.0);
        let t12 = f.scenario().t0_ns + 12_000_000_000;
        let t20 = f.scenario().t0_ns + 20_000_000_000;
        let window: Vec<_> = after
            .iter()
            .filter(|p| p.t_ns >= t12 && p.t_ns < t20)
            .copied()
            .collect();
        let (_, max_in) = yaw_scores(&f, &window, 0.0);
        eprintln!(
            "compass disturbance {label}: source {src:?}, samples disturbed {disturbed}, fused {} rejected {}, attitude NEES {nees:.2}, yaw within 3 sigma {:.1} %, max |yaw error| {:.2} deg, in 12-20 s {:.2} deg",
            diag.fused,
            diag.rejected,
            100.0 * within,
            max_yaw.to_degrees(),
            max_in.to_degrees()
        );
        // Measured: NEES 1.9–2.8, 100 % within 3σ in every case.
        assert!(nees <= 4.0, "{label}: NEES {nees}");
        assert!(within >= 0.95, "{label}: {within}");
        assert_eq!(src, HeadingSource::Magnetometer, "{label}");
        let h = est.health().heading;
        assert_eq!(h.source, HeadingSource::Magnetometer, "{label}");
        assert_eq!(h.mag, MagStatus::Active, "{label}");
        assert_eq!(h.mag_disturbed, disturbed, "{label}");
        match label {
            // Detected (19 of the 24 fusion attempts in the windows), not fused: the heading is
            // as good as without the disturbance (0.45° at worst in 12–20 s).
            "gross" => {
                assert!(disturbed >= 10, "{label}: {disturbed}");
                assert!(max_in < 1f64.to_radians(), "{label}: {max_in}");
            }
            // Fused: the compass's σ (`mag_heading_sigma_rad`) leaves a heading the GNSS
            // velocity sees to within a degree little gain; 0.32° at worst.
            "subtle" => assert!(max_in < 1f64.to_radians(), "{label}: {max_in}"),
            "none" => assert_eq!(disturbed, 0),
            // While nothing else sees the heading (the hover), or before the compass's own
            // typical strength is learnt (the yaw turn at 4 s): 4.3° and 5.2° at worst, within 3σ.
            _ => assert!(max_yaw < 6f64.to_radians(), "{label}: {max_yaw}"),
        }
    }
}
