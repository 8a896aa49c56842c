//! Seeded scenario tests on the simulator's paper flights (250 s, 120 s GNSS outage), with the
//! egomotion ORACLE synthesized from truth (tests only). Targets from issue 3, measured after 30 s.
//! A full paper flight takes a few seconds in the dev profile, so all run in the normal `cargo test`.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

mod common;

use common::{Oracle, RunCfg, outages_ns, run, scenario};
use uavnav_core::FilterProfile;
use uavnav_estimator::accuracy::AccuracyReport;
use uavnav_sim::Flight;

fn report(name: &str, cfg: &RunCfg) -> AccuracyReport {
    let s = scenario(name, None);
    let flight = Flight::new(&s).unwrap();
    let outs = run(&flight, cfg);
    let r = AccuracyReport::compute(name, &outs, flight.truth(), &outages_ns(&s));
    eprintln!("{}", r.markdown_row());
    r
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
    // The drift must lie within the stated uncertainty (no overconfidence at the end of the outage).
    assert!(
        drift.horizontal_error_m <= 3.0 * drift.stated_sigma_h_m,
        "{name}: {drift:?}"
    );
    assert!(
        r.consistency.all_within_3sigma >= 0.95,
        "{name}: {:?}",
        r.consistency
    );
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
    assert!(
        yo >= 3.0 * yw,
        "yaw RMSE GNSS-only {yo:.3}° vs with video {yw:.3}°: less than 3×"
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
/// whose rotation noise is that of the vision front end on these flights (40–90 µrad per axis; the
/// default oracle's 175 µrad accumulates in the eq. (34) pseudo-attitude to more than the gyro
/// drift).
fn paper_cfg(video: bool) -> RunCfg {
    let oracle = Oracle {
        rot_sigma_rad: 70e-6,
        ..Oracle::default()
    };
    RunCfg::new(FilterProfile::Paper, true, video.then_some(oracle))
}

#[test]
fn paper_profile_reproduces_the_qualitative_results() {
    // Section VI, on both lever-arm configurations (RMSE after 30 s, including the outage).
    let small_v = report("paper-small-lever", &paper_cfg(true));
    let small_g = report("paper-small-lever", &paper_cfg(false));
    let big_v = report("paper-big-lever", &paper_cfg(true));
    let big_g = report("paper-big-lever", &paper_cfg(false));
    let att = |r: &AccuracyReport| r.att_rmse_deg.unwrap();
    // (a) Figs. 2–3: video-aided attitude beats GNSS-aided in every axis in both configurations;
    // by more than 30 % except the big-lever yaw, which the lever arm already observes well
    // (measured 0.12° with video vs 0.15° without).
    for (name, v, g) in [("small", &small_v, &small_g), ("big", &big_v, &big_g)] {
        let (av, ag) = (att(v), att(g));
        assert!(
            (0..3).all(|k| av[k] < ag[k]) && av[0] < 0.7 * ag[0] && av[1] < 0.7 * ag[1],
            "{name} lever: video {av:?} vs GNSS-only {ag:?}"
        );
    }
    let (sv, sg) = (att(&small_v), att(&small_g));
    assert!(
        sv.z < 0.7 * sg.z,
        "small lever yaw: video {sv:?} vs GNSS-only {sg:?}"
    );
    // (b) Fig. 3: without video the small lever arm leaves yaw worse (the GNSS reaches the
    // attitude only through the lever arm; measured 1.6×, the gyro drift of the outage weighs on
    // both); with video both configurations are alike in roll and pitch (within 1.7×: measured
    // 0.16/0.17° small vs 0.12/0.11° big). NOT asserted because it does not hold: that the
    // video-aided yaw is alike too (measured 0.32° small vs 0.12° big: the eq. (34) chain is
    // relative; it drifts with the video's slowly varying yaw error, which only the lever arm
    // corrects).
    let (sg, bg) = (att(&small_g), att(&big_g));
    assert!(
        sg.z > 1.3 * bg.z,
        "GNSS-only yaw small {sg:?} vs big {bg:?}"
    );
    let (sv, bv) = (att(&small_v), att(&big_v));
    for k in 0..2 {
        assert!(
            sv[k] < 1.7 * bv[k] && bv[k] < 1.7 * sv[k],
            "video {sv:?} vs {bv:?}"
        );
    }
    // (c) Figs. 4–5: with video (VIDEO-IMU(2)) the outage is bridged far better than by coasting.
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
    let t = uavnav_estimator::accuracy::truth_at(flight.truth(), after.t_ns).unwrap();
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
