//! The default profile stays honest across sensor grades: the simulated fixed wing (the paper's
//! small-lever flight, 120 s GNSS outage) and multirotor (no compass: the heading from the yaw
//! bank), GNSS only, each with one sensor changed from the scenario's: a consumer IMU, a 50 Hz
//! IMU, a 1 Hz receiver, a receiver 4× noisier, one whose position error wanders with a 20 s
//! correlation time (the scenario's: 300 s), and a 1.4 m lever arm. Position, velocity and
//! attitude each at least 95 % within 3σ, scored as `uavnav estimate --report` scores
//! (`AccuracyReport`, after its 30 s settling time). The `paper` profile on the same variants
//! (before eq. T3 of `paper::gnss_tilt` and the alignment's tilt σ, the noisy receiver left it
//! 83.7 % (fixed wing) and 82.8 % (multirotor) within 3σ in attitude; now 98.6 and 100 %). And
//! the `paper` profile with a consumer IMU uses its camera; the fixed wing with oracle video
//! across the same variants (`eskf`).
//! Release figures: `cargo run --release -p uavnav-runner --example paper_run -- FILE --no-vision`
//! on the same edits.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

mod common;

use common::{Oracle, RunCfg, outages_ns, run, scenario};
use uavnav_core::FilterProfile;
use uavnav_report::accuracy::AccuracyReport;
use uavnav_sim::{Flight, Scenario};

/// One sensor changed from the scenario's.
#[derive(Debug, Clone, Copy)]
enum Variant {
    /// Noise and bias walks 20× the tactical IMU's, turn-on biases 0.29 °/s and 0.2 m/s².
    ConsumerImu,
    Imu50Hz,
    Gnss1Hz,
    /// White position noise 2 / 3 m, correlated 4 / 6 m, velocity 0.3 m/s.
    NoisyReceiver,
    /// The correlated position error's time constant 20 s.
    WanderingReceiver,
    /// The antenna at [1.0, −0.8, −0.5] m.
    LongLever,
}

const ALL: [Variant; 6] = [
    Variant::ConsumerImu,
    Variant::Imu50Hz,
    Variant::Gnss1Hz,
    Variant::NoisyReceiver,
    Variant::WanderingReceiver,
    Variant::LongLever,
];

fn apply(s: &mut Scenario, v: Variant) {
    match v {
        Variant::ConsumerImu => {
            s.imu.gyro_noise_density = 2.0e-3;
            s.imu.gyro_random_walk = 4.0e-5;
            s.imu.accel_noise_density = 2.0e-2;
            s.imu.accel_random_walk = 2.0e-3;
            s.imu.gyro_bias_sigma_radps = 5.0e-3;
            s.imu.accel_bias_sigma_mps2 = 0.2;
        }
        Variant::Imu50Hz => s.imu.rate_hz = 50.0,
        Variant::Gnss1Hz => s.gnss.rate_hz = 1.0,
        Variant::NoisyReceiver => {
            s.gnss.white_sigma_h_m = 2.0;
            s.gnss.white_sigma_v_m = 3.0;
            s.gnss.gm_sigma_h_m = 4.0;
            s.gnss.gm_sigma_v_m = 6.0;
            s.gnss.vel_sigma_mps = 0.3;
        }
        Variant::WanderingReceiver => s.gnss.gm_tau_s = 20.0,
        Variant::LongLever => s.gnss.lever_arm_m = [1.0, -0.8, -0.5],
    }
}

/// Runs every variant of `name` and asserts the shares; returns nothing, prints a row each.
fn check(name: &str, without_mag: bool, profile: FilterProfile, variants: &[Variant]) {
    check_with(name, without_mag, profile, variants, false);
}

/// [`check`], with the camera's egomotion from the oracle when `video`.
fn check_with(
    name: &str,
    without_mag: bool,
    profile: FilterProfile,
    variants: &[Variant],
    video: bool,
) {
    let mut failed = Vec::new();
    for &v in variants {
        let mut s = scenario(name, None);
        if without_mag {
            s.mag = None;
        }
        s.camera.enabled = video;
        apply(&mut s, v);
        let flight = Flight::new(&s).unwrap();
        let outs = run(
            &flight,
            &RunCfg::new(profile, true, video.then(Oracle::default)),
        );
        let name_v = format!(
            "{name} {profile:?} {v:?}{}",
            if video { " video" } else { "" }
        );
        let c =
            AccuracyReport::compute(&name_v, &outs, flight.truth(), &outages_ns(&s)).consistency;
        eprintln!(
            "{name_v}: pos / vel / att within 3 sigma {:.1} / {:.1} / {:.1} % ({} samples)",
            100.0 * c.pos_within_3sigma,
            100.0 * c.vel_within_3sigma,
            100.0 * c.att_within_3sigma,
            c.samples
        );
        let shares = [
            c.pos_within_3sigma,
            c.vel_within_3sigma,
            c.att_within_3sigma,
        ];
        if c.samples < 1000 || shares.iter().any(|s| *s < 0.95) {
            failed.push(format!("{v:?}: {c:?}"));
        }
    }
    assert!(failed.is_empty(), "{name}: {failed:#?}");
}

#[test]
fn a_fixed_wing_stays_within_3_sigma_across_sensor_grades() {
    check("paper-small-lever", false, FilterProfile::Eskf, &ALL);
}

/// The same with the camera (oracle egomotion, white errors): 98.9–100 % each on 2026-12-02. The
/// `paper` profile is not asserted here: with the noisy receiver its attitude is 91.9 % within
/// 3σ (the README's *Simulated flights*, "Still short").
#[test]
fn a_fixed_wing_with_video_stays_within_3_sigma_across_sensor_grades() {
    check_with("paper-small-lever", false, FilterProfile::Eskf, &ALL, true);
}

#[test]
fn a_multirotor_without_compass_stays_within_3_sigma_across_sensor_grades() {
    check("multirotor", true, FilterProfile::Eskf, &ALL);
}

#[test]
fn the_paper_profile_stays_within_3_sigma_across_sensor_grades() {
    check("paper-small-lever", false, FilterProfile::Paper, &ALL);
    check("multirotor", true, FilterProfile::Paper, &ALL);
}

/// The `paper` profile's video chain (eq. 34) starts from the alignment once it has settled, not
/// only once every attitude σ is below 0.5°, which a consumer IMU's process noise never allows:
/// with such an IMU on the fixed wing its camera was never used. Oracle vision here: before, no
/// rotation fused, roll / pitch / yaw RMSE 3.53 / 0.58 / 17.5°, 21.2 % drift through the outage,
/// 91.8 % within 3σ; now 2,291 fused, 0.24 / 0.25 / 0.31°, 2.9 %, 98.2 % (the real vision chain,
/// `paper_run`: 2.91 / 0.53 / 17.4° → 0.27 / 0.13 / 0.25°, 21.1 → 2.9 %).
#[test]
fn the_paper_profile_uses_the_camera_of_a_consumer_imu() {
    let mut s = scenario("paper-small-lever", None);
    apply(&mut s, Variant::ConsumerImu);
    let flight = Flight::new(&s).unwrap();
    let outs = run(
        &flight,
        &RunCfg::new(FilterProfile::Paper, true, Some(Oracle::default())),
    );
    let last = outs.last().unwrap();
    let r = AccuracyReport::compute(
        "consumer IMU, paper, video",
        &outs,
        flight.truth(),
        &outages_ns(&s),
    );
    eprintln!(
        "{} (rotations fused {})",
        r.markdown_row(),
        last.health.vision_rot.fused
    );
    assert!(last.health.vision_rot.fused > 1000, "{:?}", last.health);
    let drift = r.outages[0];
    assert!(drift.percent < 5.0, "{drift:?}");
    assert!(
        drift.horizontal_error_m <= 3.0 * drift.stated_sigma_h_m,
        "{drift:?}"
    );
    let att = r.att_rmse_deg.unwrap();
    assert!(att.iter().all(|a| *a < 1.0), "{att:?}");
    assert!(
        r.consistency.all_within_3sigma >= 0.95,
        "{:?}",
        r.consistency
    );
}
