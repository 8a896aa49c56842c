//! Seeded scenario tests on the simulator's paper flights (250 s, 120 s GNSS outage), with the
//! egomotion ORACLE synthesized from truth (tests only). Targets from issue 3, measured after 30 s.
//! A full paper flight takes a few seconds in the dev profile, so all run in the normal `cargo test`.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

mod common;

use common::{Oracle, RunCfg, outages_ns, run, scenario};
use uavnav_core::FilterProfile;
use uavnav_report::accuracy::AccuracyReport;
use uavnav_sim::Flight;

fn report(name: &str, cfg: &RunCfg) -> AccuracyReport {
    let s = scenario(name, None);
    let flight = Flight::new(&s).unwrap();
    let outs = run(&flight, cfg);
    let r = AccuracyReport::compute(name, &outs, flight.truth(), &outages_ns(&s));
    eprintln!("{}", r.markdown_row());
    r
}

/// At least 95 % of the samples within 3σ, and the drift at the end of the outage within the
/// stated uncertainty (no overconfidence when GNSS returns).
fn assert_consistent(name: &str, r: &AccuracyReport) {
    let drift = r.outages[0];
    assert!(
        drift.horizontal_error_m <= 3.0 * drift.stated_sigma_h_m,
        "{name}: {drift:?}"
    );
    assert!(
        r.consistency.all_within_3sigma >= 0.95,
        "{name}: {:?}",
        r.consistency
    );
}

fn eskf_targets(name: &str) -> AccuracyReport {
    let r = report(
        name,
        &RunCfg::new(FilterProfile::Eskf, true, Some(Oracle::default())),
    );
    let att = r.att_rmse_deg.unwrap();
    assert!(
        att.x <= 0.1 && att.y <= 0.1,
        "{name}: roll/pitch RMSE {att:?} deg"
    );
    assert!(att.z <= 0.3, "{name}: yaw RMSE {att:?} deg");
    let drift = r.outages[0];
    assert!(drift.percent <= 1.0, "{name}: outage drift {drift:?}");
    assert_consistent(name, &r);
    r
}

#[test]
fn eskf_meets_targets_small_lever_and_video_triples_yaw_accuracy() {
    let with = eskf_targets("paper-small-lever");
    let without = report(
        "paper-small-lever",
        &RunCfg::new(FilterProfile::Eskf, true, None),
    );
    let (yw, yo) = (
        with.att_rmse_deg.unwrap().z,
        without.att_rmse_deg.unwrap().z,
    );
    // 2.5× since the IMU-noise adaptation and the yaw bank (GNSS-only 0.112° where it was
    // 0.12–0.13°; with video 0.041°).
    assert!(
        yo >= 2.5 * yw,
        "yaw RMSE GNSS-only {yo:.3}° vs with video {yw:.3}°: less than 2.5×"
    );
    // Without vision the outage is inertial coasting: worse than with the direction of travel.
    assert!(without.outages[0].percent > with.outages[0].percent);
    assert!(
        without.consistency.all_within_3sigma >= 0.95,
        "{:?}",
        without.consistency
    );
}

#[test]
fn eskf_meets_targets_big_lever() {
    eskf_targets("paper-big-lever");
}

/// Paper profile with its default parameters (the gyro-bias allowance
/// `EstimatorParams::paper_gyro_instability_psd` is derived from the simulated IMU), and an oracle
/// whose noise is that of the vision front end on these flights: rotation 40–90 µrad per axis (the
/// default oracle's 175 µrad accumulates in the eq. (34) pseudo-attitude to more than the gyro
/// drift), direction of travel 0.22° per axis (the front end's median error of 0.26°; the default
/// oracle's 1° is 4× that).
fn paper_cfg(video: bool) -> RunCfg {
    let oracle = Oracle {
        rot_sigma_rad: 70e-6,
        dir_sigma_rad: 0.22f64.to_radians(),
        ..Oracle::default()
    };
    RunCfg::new(FilterProfile::Paper, true, video.then_some(oracle))
}

/// [`paper_cfg`] without our addition of roll and pitch from the GNSS acceleration
/// (`EstimatorParams::paper_gnss_tilt`): the paper's filter as written, for its section VI.
fn paper_as_written(video: bool) -> RunCfg {
    let mut cfg = paper_cfg(video);
    cfg.params.paper_gnss_tilt = false;
    cfg
}

#[test]
fn paper_profile_reproduces_the_qualitative_results() {
    // Section VI, on both lever-arm configurations (RMSE after 30 s, including the outage).
    // Measured (roll/pitch/yaw °): small lever video 0.082/0.083/0.064, GNSS-only
    // 0.512/0.460/0.562; big lever video 0.085/0.086/0.061, GNSS-only 0.392/0.343/0.154.
    let small_v = report("paper-small-lever", &paper_as_written(true));
    let small_g = report("paper-small-lever", &paper_as_written(false));
    let big_v = report("paper-big-lever", &paper_as_written(true));
    let big_g = report("paper-big-lever", &paper_as_written(false));
    let att = |r: &AccuracyReport| r.att_rmse_deg.unwrap();
    // (a) Figs. 2–3: video-aided attitude beats GNSS-aided in every axis in both configurations,
    // by more than 2× (measured 0.11–0.18× small lever, 0.22–0.40× big lever; the big-lever yaw,
    // which the lever arm already observes, is the closest).
    for (name, v, g) in [("small", &small_v, &small_g), ("big", &big_v, &big_g)] {
        let (av, ag) = (att(v), att(g));
        assert!(
            (0..3).all(|k| av[k] < 0.5 * ag[k]),
            "{name} lever: video {av:?} vs GNSS-only {ag:?}"
        );
    }
    // (b) Fig. 3: without video the small lever arm leaves yaw much worse (the GNSS reaches the
    // attitude only through the lever arm; measured 3.6×); with video both configurations are
    // alike in all three axes (measured within 1.05×): the eq. (D1) direction of travel against
    // the GNSS velocity observes the heading and the pitch whatever the lever arm (without it,
    // `paper_video_direction = false`, the video-aided yaw is 0.32° small vs 0.12° big: the
    // eq. (34) chain is relative and drifts with the video's rotation errors).
    let (sg, bg) = (att(&small_g), att(&big_g));
    assert!(
        sg.z > 2.5 * bg.z,
        "GNSS-only yaw small {sg:?} vs big {bg:?}"
    );
    let (sv, bv) = (att(&small_v), att(&big_v));
    for k in 0..3 {
        assert!(
            sv[k] < 1.3 * bv[k] && bv[k] < 1.3 * sv[k],
            "video {sv:?} vs {bv:?}"
        );
    }
    // (c) Figs. 4–5: with video (VIDEO-IMU(2)) the outage is bridged far better than by coasting
    // (measured 2.3 % against 21.7 % / 15.6 % of the distance flown).
    for (v, g) in [(&small_v, &small_g), (&big_v, &big_g)] {
        assert!(
            v.outages[0].percent < 0.5 * g.outages[0].percent,
            "{:?} vs {:?}",
            v.outages,
            g.outages
        );
    }
}

#[test]
fn gnss_recovery_after_the_outage_moves_no_more_than_the_stated_uncertainty() {
    let s = scenario("paper-small-lever", None);
    let flight = Flight::new(&s).unwrap();
    let outs = run(&flight, &RunCfg::new(FilterProfile::Eskf, true, None));
    let (_, end) = outages_ns(&s)[0];
    let around: Vec<_> = outs
        .iter()
        .filter(|o| o.t_ns > end - 2_000_000_000 && o.t_ns < end + 5_000_000_000)
        .collect();
    let mut worst = 0.0f64;
    for w in around.windows(2) {
        let step = (w[1].pos_ned_m
            - w[0].pos_ned_m
            - w[0].vel_ned_mps * ((w[1].t_ns - w[0].t_ns) as f64 * 1e-9))
            .xy()
            .norm();
        let sigma = w[0].sigma_pos_ned_m.xy().norm();
        worst = worst.max(step / sigma);
    }
    assert!(
        worst <= 3.0,
        "a correction step of {worst:.2} σ at GNSS recovery"
    );
    let after = outs.iter().find(|o| o.t_ns > end + 8_000_000_000).unwrap();
    let t = uavnav_core::truth::truth_at(flight.truth(), after.t_ns).unwrap();
    assert!(
        (after.pos_ned_m - t.pos_ned_m).xy().norm() < 5.0,
        "not recovered 8 s after the outage"
    );
}

#[test]
fn eskf_with_metric_translation_from_the_terrain_distance() {
    // The vision front end may give the metric t (terrain distance known): 2 % relative noise.
    let oracle = Oracle {
        metric_rel_sigma: Some(0.02),
        ..Oracle::default()
    };
    let r = report(
        "paper-small-lever",
        &RunCfg::new(FilterProfile::Eskf, true, Some(oracle)),
    );
    let att = r.att_rmse_deg.unwrap();
    assert!(att.x <= 0.1 && att.y <= 0.1 && att.z <= 0.3, "{att:?}");
    assert!(r.outages[0].percent <= 1.0, "{:?}", r.outages);
    assert!(
        r.consistency.all_within_3sigma >= 0.95,
        "{:?}",
        r.consistency
    );
}

/// The plane solver's metric translation is `t · d̂ / d`: scaled by the filter's own distance to
/// the terrain (its motion prior). With a consumer-grade IMU (noise and bias walks 20× the
/// tactical one's, turn-on biases 5e-3 rad/s and 0.2 m/s²) the height drifts through the 120 s
/// outage, and a filter that took `t_m` as independent of its state counted its own height error
/// as fresh velocity information at every frame (eq. V2, `aid_sources::vision::metric_model`).
#[test]
fn a_plane_scaled_translation_through_an_outage_with_a_consumer_imu_stays_consistent() {
    let s = consumer_grade_small_lever();
    let flight = Flight::new(&s).unwrap();
    let run_with = |report_distance: bool| {
        let oracle = Oracle {
            metric_rel_sigma: Some(0.007),
            plane_scaled: Some(report_distance),
            ..Oracle::default()
        };
        let outs = run(
            &flight,
            &RunCfg::new(FilterProfile::Eskf, true, Some(oracle)),
        );
        let r = AccuracyReport::compute("consumer", &outs, flight.truth(), &outages_ns(&s));
        eprintln!(
            "distance reported {report_distance}: {} {:?}",
            r.markdown_row(),
            r.consistency
        );
        r
    };
    let modelled = run_with(true);
    let hidden = run_with(false);
    assert_consistent("consumer, distance reported", &modelled);
    let drift = modelled.outages[0];
    // Measured: 99.6 % within 3σ and 3.7 m at the end of the outage, against 95.4 % (velocity
    // 91 %) and 22.3 m when the filter is not told the distance.
    assert!(
        drift.horizontal_error_m < hidden.outages[0].horizontal_error_m,
        "modelled {drift:?}, hidden {:?}",
        hidden.outages[0]
    );
    assert!(
        modelled.consistency.all_within_3sigma > hidden.consistency.all_within_3sigma,
        "modelled {:?}, hidden {:?}",
        modelled.consistency,
        hidden.consistency
    );
}

/// The gyro in the GNSS lever-arm velocity `C (ω × r)` carries its noise into the prediction:
/// a consumer-grade gyro (2e-3 rad/s/√Hz, 0.028 rad/s per 200 Hz sample) on an 8 m lever arm
/// adds 0.23 m/s per sample, four times the receiver's velocity σ. The filter averages the gyro
/// around the fix and adds what noise is left to the velocity's covariance (eq. 33n): 99.9 %
/// within 3σ on this flight, 90.1 % before.
#[test]
fn a_big_lever_arm_with_a_consumer_gyro_stays_consistent() {
    let mut s = consumer_grade_small_lever();
    s.gnss.lever_arm_m = [0.0, 8.0, 0.0];
    let flight = Flight::new(&s).unwrap();
    let outs = run(&flight, &RunCfg::new(FilterProfile::Eskf, true, None));
    let r = AccuracyReport::compute("consumer-big", &outs, flight.truth(), &outages_ns(&s));
    eprintln!("{} {:?}", r.markdown_row(), r.consistency);
    assert!(
        r.consistency.all_within_3sigma >= 0.95,
        "{:?}",
        r.consistency
    );
    let att = r.att_rmse_deg.unwrap();
    assert!(att.x <= 1.5 && att.y <= 1.5 && att.z <= 3.0, "{att:?}");
}

/// Our addition to the `paper` profile (`paper::gnss_tilt`): without video, roll and pitch from
/// the GNSS acceleration against the accelerometers. On the small-lever flight without video the
/// paper's filter as written integrates the gyros (roll/pitch RMSE 0.51/0.46°, GNSS reaches the
/// attitude only through the lever arm); with the addition 0.084/0.076°, as with video. The yaw
/// is left to the lever arm (0.59 against 0.56°: the windows fuse it only once its σ is small).
#[test]
fn paper_gnss_tilt_holds_roll_and_pitch_without_video() {
    let with = report("paper-small-lever", &paper_cfg(false));
    let without = report("paper-small-lever", &paper_as_written(false));
    let (a, b) = (with.att_rmse_deg.unwrap(), without.att_rmse_deg.unwrap());
    eprintln!("with {a:?} without {b:?}");
    assert!(
        a.x < 0.3 * b.x && a.y < 0.3 * b.y,
        "with {a:?} vs without {b:?}"
    );
    assert!(a.z < 1.1 * b.z, "with {a:?} vs without {b:?}");
}

/// The `paper` profile states what it knows: the GNSS fixes' correlated error is in its position
/// σ (its GPS-IMU takes them as white), VIDEO-IMU(2) carries the attitude error as a slowly
/// varying acceleration error through the outage, and the speed that eq. (35) holds is one error
/// shared by every frame. Before, 50 % of the positions and 72–74 % of the velocities were
/// within 3σ on these flights.
#[test]
fn paper_profile_is_consistent_with_and_without_video() {
    for video in [false, true] {
        let r = report("paper-small-lever", &paper_cfg(video));
        eprintln!("video {video}: {:?}", r.consistency);
        assert_consistent(&format!("paper, video {video}"), &r);
    }
}

/// The `paper` profile has no gyro-bias state (as the paper); with a consumer IMU's turn-on bias
/// (0.29 °/s) the attitude drifts through the 120 s outage far beyond what white process noise
/// grows. Its covariance now grows by what the bias builds up since the angles were last
/// measured (`AttitudeEkf::predict`): before, 33.5 % of the attitude rows were within 3σ here
/// (NEES 5145), and the yaw RMSE was 106° (the course gated out when GNSS returned).
#[test]
fn paper_profile_states_the_attitude_error_a_consumer_gyro_bias_builds_up() {
    let s = consumer_grade_small_lever();
    let flight = Flight::new(&s).unwrap();
    let outs = run(&flight, &paper_cfg(false));
    let r = AccuracyReport::compute("consumer-paper", &outs, flight.truth(), &outages_ns(&s));
    eprintln!("{} {:?}", r.markdown_row(), r.consistency);
    assert!(
        r.consistency.att_within_3sigma >= 0.95,
        "{:?}",
        r.consistency
    );
}

/// The small-lever flight with a consumer-grade IMU: noise and bias walks 20× the tactical
/// one's, turn-on biases 5e-3 rad/s and 0.2 m/s².
fn consumer_grade_small_lever() -> uavnav_sim::Scenario {
    let mut s = scenario("paper-small-lever", None);
    for v in [
        &mut s.imu.gyro_noise_density,
        &mut s.imu.gyro_random_walk,
        &mut s.imu.accel_noise_density,
        &mut s.imu.accel_random_walk,
    ] {
        *v *= 20.0;
    }
    s.imu.gyro_bias_sigma_radps = 5e-3;
    s.imu.accel_bias_sigma_mps2 = 0.2;
    s
}
