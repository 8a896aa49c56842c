//! Behaviour tests: a static vehicle, bad inputs rejected with the filter unharmed, out-of-order
//! and late measurements, GNSS glitches, in-flight initialisation, and the motion prior.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

mod common;

use common::{Oracle, RunCfg, run, scenario, synth_egomotion};
use nalgebra::{UnitQuaternion, Vector3};
use uavnav_core::rng::Rng;
use uavnav_core::rotation::euler_error;
use uavnav_core::truth::truth_at;
use uavnav_core::{
    FilterProfile, FixType, GnssConfig, GnssFix, ImuSample, Lla, LocalFrame, VehicleConfig,
};
use uavnav_estimator::{Estimator, EstimatorParams, InputError, Mode};
use uavnav_sim::Flight;

const T0: i64 = 5_000_000_000;
const DT: i64 = 5_000_000;

/// A vehicle sitting still, level-ish, heading 30°, with noisy sensors.
fn static_data(
    seconds: f64,
    seed: u64,
) -> (
    VehicleConfig,
    Lla,
    Vec<ImuSample>,
    Vec<GnssFix>,
    UnitQuaternion<f64>,
) {
    let origin = Lla::from_deg(45.0, 7.0, 300.0);
    let frame = LocalFrame::new(origin);
    let q = UnitQuaternion::from_euler_angles(0.02, -0.01, 30f64.to_radians());
    let g = frame.gravity_ned(&Vector3::zeros());
    let w_ie = uavnav_estimator::prediction::earth_rate_ned(origin.lat_rad);
    let cfg = VehicleConfig {
        gnss: Some(GnssConfig {
            rate_hz: 5.0,
            lever_arm_body_m: Vector3::new(0.2, 0.0, -0.1),
            delay_ns: 0,
            ..GnssConfig::default()
        }),
        ..Default::default()
    };
    let mut rng = Rng::new(seed);
    let n = (seconds * 200.0) as usize;
    let mut imu = Vec::with_capacity(n);
    let mut gnss = Vec::new();
    let offset = Rng::new(seed + 100).gaussian3(0.4);
    let sg = cfg.imu.gyro_noise_density * 200f64.sqrt();
    let sa = cfg.imu.accel_noise_density * 200f64.sqrt();
    for k in 0..n {
        let t = T0 + k as i64 * DT;
        imu.push(ImuSample {
            t_ns: t,
            gyro_radps: q.inverse() * w_ie + rng.gaussian3(sg),
            accel_mps2: q.inverse() * (-g) + rng.gaussian3(sa),
        });
        if k % 40 == 0 {
            // Receiver-like error: a slowly varying offset (reported σ 0.5 m) plus small white noise.
            let ant = q * Vector3::new(0.2, 0.0, -0.1) + offset + rng.gaussian3(0.1);
            let lla = frame.ned_to_lla(&ant);
            gnss.push(GnssFix {
                t_ns: t,
                lat_deg: lla.lat_deg(),
                lon_deg: lla.lon_deg(),
                alt_m: lla.alt_m,
                velocity: Some(uavnav_core::GnssVelocity::ned(rng.gaussian3(0.05), 0.05)),
                sigma_h_m: 0.5,
                sigma_v_m: 0.8,
                fix_type: FixType::Fix3d,
                num_sats: 10,
            });
        }
    }
    (cfg, origin, imu, gnss, q)
}

fn feed(
    est: &mut Estimator,
    imu: &[ImuSample],
    gnss: &[GnssFix],
) -> Vec<uavnav_estimator::PoseOutput> {
    let mut gi = 0;
    let mut out = vec![];
    for s in imu {
        while gi < gnss.len() && gnss[gi].t_ns <= s.t_ns {
            est.push_gnss(&gnss[gi]).unwrap();
            gi += 1;
        }
        out.extend(est.push_imu(s).unwrap());
    }
    out
}

#[test]
fn static_vehicle_stays_put_and_level() {
    for profile in [FilterProfile::Eskf, FilterProfile::Paper] {
        let (mut cfg, origin, imu, gnss, q) = static_data(30.0, 1);
        cfg.profile = profile;
        let mut est = Estimator::new(&cfg, EstimatorParams::default(), Some(origin));
        let out = feed(&mut est, &imu, &gnss);
        assert!(!out.is_empty(), "{profile:?}: never initialised");
        let last = out.last().unwrap();
        assert!(
            last.pos_ned_m.norm() < 2.0,
            "{profile:?}: drifted to {:?}",
            last.pos_ned_m
        );
        assert!(
            last.vel_ned_mps.norm() < 0.1,
            "{profile:?}: moving {:?}",
            last.vel_ned_mps
        );
        let e = euler_error(&last.nav_from_body, &q);
        // Heading is unobservable at rest (no course, no magnetometer): only roll and pitch are
        // checked. At rest tilt and accelerometer bias are inseparable (0.05 m/s² prior ≈ 0.3°), so
        // the bound is the stated σ, plus an absolute sanity bound.
        for k in 0..2 {
            assert!(
                e[k].abs() < 0.5f64.to_radians(),
                "{profile:?}: tilt error {e:?}"
            );
            assert!(
                e[k].abs() < 3.0 * last.sigma_att_rad[k],
                "{profile:?}: tilt error {e:?} vs σ {:?}",
                last.sigma_att_rad
            );
        }
        assert_eq!(last.health.mode, Mode::Nominal);
        assert!(
            last.health.gnss_pos.rejected <= 2,
            "{profile:?}: {:?}",
            last.health.gnss_pos
        );
    }
}

#[test]
fn bad_inputs_are_rejected_and_the_filter_is_unharmed() {
    let (cfg, origin, imu, gnss, _) = static_data(3.0, 2);
    let mut est = Estimator::new(&cfg, EstimatorParams::default(), Some(origin));
    let half = imu.len() / 2;
    feed(
        &mut est,
        &imu[..half],
        &gnss[..gnss.partition_point(|g| g.t_ns <= imu[half - 1].t_ns)],
    );
    let twin = est.clone();
    let last = imu[half - 1];
    let next = imu[half];
    let mut nan = next;
    nan.gyro_radps.x = f64::NAN;
    assert!(matches!(
        est.push_imu(&nan),
        Err(InputError::NonFinite { .. })
    ));
    let mut inf = next;
    inf.accel_mps2.z = f64::INFINITY;
    assert!(matches!(
        est.push_imu(&inf),
        Err(InputError::NonFinite { .. })
    ));
    assert!(matches!(
        est.push_imu(&last),
        Err(InputError::Duplicate { .. })
    ));
    let mut back = next;
    back.t_ns = last.t_ns - 1;
    assert!(matches!(
        est.push_imu(&back),
        Err(InputError::TimeBackwards { .. })
    ));
    let mut jump = next;
    jump.t_ns = last.t_ns + 10_000_000_000;
    assert!(matches!(
        est.push_imu(&jump),
        Err(InputError::TimeJump { .. })
    ));
    let mut absurd = next;
    absurd.accel_mps2.x = 1e4;
    assert!(matches!(
        est.push_imu(&absurd),
        Err(InputError::Absurd { .. })
    ));
    let mut g = gnss[0];
    g.t_ns = next.t_ns;
    g.lat_deg = f64::NAN;
    assert!(matches!(
        est.push_gnss(&g),
        Err(InputError::NonFinite { .. })
    ));
    g.lat_deg = 95.0;
    assert!(matches!(est.push_gnss(&g), Err(InputError::Absurd { .. })));
    g.lat_deg = 45.0;
    g.fix_type = FixType::None;
    assert!(matches!(est.push_gnss(&g), Err(InputError::NoFix)));
    let ego = common_ego(next.t_ns);
    assert!(matches!(
        est.push_egomotion(&ego),
        Err(InputError::NoCamera)
    ));
    // Every error is displayable with a reason.
    assert!(
        InputError::TimeJump {
            gap_ns: 1,
            max_ns: 0
        }
        .to_string()
        .contains("jump")
    );
    // Unharmed: the same continuation gives bit-identical poses to a twin that never saw them.
    let mut a = est;
    let mut b = twin;
    for s in &imu[half..] {
        let (oa, ob) = (a.push_imu(s).unwrap(), b.push_imu(s).unwrap());
        assert_eq!(
            oa.map(|o| (o.pos_ned_m, o.nav_from_body)),
            ob.map(|o| (o.pos_ned_m, o.nav_from_body))
        );
    }
    assert_eq!(a.health().inputs_rejected, 10);
}

fn common_ego(t_ns: i64) -> uavnav_core::Egomotion {
    uavnav_core::Egomotion {
        t0_ns: t_ns - 100_000_000,
        t1_ns: t_ns,
        cam1_from_cam0: UnitQuaternion::identity(),
        t_dir_cam1: None,
        t_cam1_m: None,
        scale_distance_m: None,
        rot_cov: nalgebra::Matrix3::identity() * 1e-8,
        t_cov: nalgebra::Matrix3::identity() * 1e-4,
        joint_cov: nalgebra::Matrix6::identity() * 1e-8,
        tracked: 10,
        inliers: 10,
        quality: 1.0,
        solver: uavnav_core::EgomotionSolver::RotationOnly,
    }
}

#[test]
fn a_long_time_jump_restarts_once_the_stream_is_continuous() {
    let (cfg, origin, imu, gnss, _) = static_data(3.0, 3);
    let mut est = Estimator::new(&cfg, EstimatorParams::default(), Some(origin));
    feed(&mut est, &imu, &gnss);
    let mut later: Vec<ImuSample> = imu.clone();
    for s in later.iter_mut() {
        s.t_ns += 60_000_000_000;
    }
    let results: Vec<bool> = later[..6].iter().map(|s| est.push_imu(s).is_ok()).collect();
    assert_eq!(results, vec![false, false, false, false, true, true]);
}

#[test]
fn out_of_order_vision_gives_the_same_answer() {
    let s = scenario("smoke", Some(12.0));
    let flight = Flight::new(&s).unwrap();
    let mut vc = flight.vehicle_config();
    vc.profile = FilterProfile::Eskf;
    let mut rng = Rng::new(3);
    let o = Oracle::default();
    let egos: Vec<_> = (1..flight.camera_times_ns().len())
        .map(|k| {
            synth_egomotion(
                &flight,
                flight.camera_truth(k - 1).unwrap(),
                flight.camera_truth(k).unwrap(),
                &o,
                &mut rng,
            )
        })
        .collect();
    let mut outs = vec![];
    for swap in [false, true] {
        let mut est = Estimator::new(&vc, EstimatorParams::default(), Some(flight.origin()));
        let mut order: Vec<usize> = (0..egos.len()).collect();
        if swap {
            for pair in order.chunks_mut(2) {
                pair.reverse();
            }
        }
        // Deliver each pair together, 60 ms after the later frame.
        let mut deliveries: Vec<(i64, usize)> = order
            .iter()
            .map(|&i| (egos[i | 1].t1_ns.max(egos[i].t1_ns) + 60_000_000, i))
            .collect();
        deliveries.sort_by_key(|d| d.0);
        if swap {
            for pair in deliveries.chunks_mut(2) {
                pair.reverse();
            }
        }
        let (mut gi, mut ei) = (0, 0);
        let mut last = None;
        for smp in flight.imu() {
            while gi < flight.gnss().len() && flight.gnss()[gi].t_ns <= smp.t_ns {
                est.push_gnss(&flight.gnss()[gi]).unwrap();
                gi += 1;
            }
            while ei < deliveries.len() && deliveries[ei].0 <= smp.t_ns {
                est.push_egomotion(&egos[deliveries[ei].1]).unwrap();
                ei += 1;
            }
            last = est.push_imu(smp).unwrap().or(last);
        }
        let l = last.unwrap();
        assert!(
            l.health.vision_trans.fused > 50,
            "{:?}",
            l.health.vision_trans
        );
        outs.push(l);
    }
    assert!((outs[0].pos_ned_m - outs[1].pos_ned_m).norm() < 1e-9);
    assert!(outs[0].nav_from_body.angle_to(&outs[1].nav_from_body) < 1e-12);
}

#[test]
fn smoke_glitch_rejected_and_outage_bridged() {
    let s = scenario("smoke", None);
    let flight = Flight::new(&s).unwrap();
    let outs = run(
        &flight,
        &RunCfg::new(FilterProfile::Eskf, true, Some(Oracle::default())),
    );
    let last = outs.last().unwrap();
    // Modes: GNSS-denied on vision inside the 12–15 s outage (after the aid timeout), else nominal.
    let at = |t_s: f64| {
        outs.iter()
            .find(|o| o.t_ns >= s.t0_ns + (t_s * 1e9) as i64)
            .unwrap()
            .health
            .mode
    };
    assert_eq!(at(10.0), uavnav_estimator::Mode::Nominal);
    assert_eq!(at(14.8), uavnav_estimator::Mode::GnssDeniedVision);
    // The 8 m glitch at 17–18 s: rejected by the gate, the solution stays within a metre or two.
    assert!(
        last.health.gnss_pos.rejected >= 3,
        "{:?}",
        last.health.gnss_pos
    );
    for o in &outs {
        let t = truth_at(flight.truth(), o.t_ns).unwrap();
        let e = (o.pos_ned_m - t.pos_ned_m).norm();
        assert!(e < 5.0, "position error {e} at {}", o.t_ns);
    }
}

#[test]
fn initialises_in_flight_during_a_turn() {
    let s = scenario("paper-small-lever", Some(60.0));
    let flight = Flight::new(&s).unwrap();
    let mut vc = flight.vehicle_config();
    vc.camera = None;
    let mut est = Estimator::new(&vc, EstimatorParams::default(), None);
    // Start in the first turn (bank ≈ 28° at 25 s).
    let start = s.t0_ns + 25_000_000_000;
    let mut gi = flight.gnss().partition_point(|g| g.t_ns < start);
    let mut first = None;
    let mut last = None;
    for smp in flight.imu().iter().filter(|x| x.t_ns >= start) {
        while gi < flight.gnss().len() && flight.gnss()[gi].t_ns <= smp.t_ns {
            est.push_gnss(&flight.gnss()[gi]).unwrap();
            gi += 1;
        }
        if let Some(o) = est.push_imu(smp).unwrap() {
            first.get_or_insert(o);
            last = Some(o);
        }
    }
    let (first, last) = (first.unwrap(), last.unwrap());
    assert!(first.t_ns - start < 2_000_000_000, "initialised late");
    // Truth is in the scenario origin's frame; the estimator's origin is the first fix: compare
    // attitude (frame-independent up to µrad) and velocity.
    let t = truth_at(flight.truth(), first.t_ns).unwrap();
    let e0 = euler_error(&first.nav_from_body, &t.nav_from_body);
    assert!(
        e0.x.abs() < 3f64.to_radians() && e0.y.abs() < 3f64.to_radians(),
        "initial tilt error {e0:?}"
    );
    let t = truth_at(flight.truth(), last.t_ns).unwrap();
    let e = euler_error(&last.nav_from_body, &t.nav_from_body);
    // Roll and pitch converge within the turn; the yaw (GNSS only, 2 m lever, straight flight after
    // 34 s) only as far as observable: it must be consistent with its stated σ.
    let sa = last.sigma_att_rad;
    assert!(
        e.x.abs() < 0.3f64.to_radians() && e.y.abs() < 0.3f64.to_radians(),
        "tilt error after 35 s {e:?}"
    );
    assert!(
        e.x.abs() < 3.0 * sa.x && e.y.abs() < 3.0 * sa.y,
        "tilt error {e:?} vs σ {sa:?}"
    );
    assert!(
        e.z.abs() < 3.0 * last.sigma_att_rad.z && last.sigma_att_rad.z < 2f64.to_radians(),
        "yaw {e:?} σ {:?}",
        last.sigma_att_rad
    );
    assert!((last.vel_ned_mps - t.vel_ned_mps).norm() < 0.1);
}

/// The IMU's turn-on bias σ (`ImuConfig::gyro_bias_sigma_radps`) widens the filter's initial
/// bias prior where it is larger than the default, which stays a floor. Seen through the motion
/// prior the filter gives the vision front end before it is initialised: rotation σ =
/// gyro noise × √dt + bias σ × dt.
#[test]
fn the_imu_turn_on_bias_sigma_widens_the_initial_bias_prior() {
    let s = scenario("smoke", Some(3.0));
    let flight = Flight::new(&s).unwrap();
    let rot_sigma = |gyro_bias_sigma_radps: f64| {
        let mut vc = flight.vehicle_config();
        vc.profile = FilterProfile::Eskf;
        vc.imu.gyro_bias_sigma_radps = gyro_bias_sigma_radps;
        let mut est = Estimator::new(&vc, EstimatorParams::default(), Some(flight.origin()));
        for smp in flight.imu().iter().take(400) {
            est.push_imu(smp).unwrap();
        }
        let t = flight.imu()[399].t_ns;
        est.motion_prior(t - 100_000_000, t).rot_sigma_rad
    };
    let floor = EstimatorParams::default().init_gyro_bias_sigma_radps;
    let base = rot_sigma(0.0);
    assert!(base > 0.0);
    assert_eq!(
        rot_sigma(floor / 10.0),
        base,
        "below the default: the default"
    );
    let wide = rot_sigma(10.0 * floor);
    assert!(
        ((wide - base) - 9.0 * floor * 0.1).abs() < 1e-12,
        "{wide} vs {base}"
    );
}

#[test]
fn motion_prior_matches_truth() {
    let s = scenario("smoke", Some(10.0));
    let flight = Flight::new(&s).unwrap();
    let mut vc = flight.vehicle_config();
    vc.profile = FilterProfile::Eskf;
    let mut est = Estimator::new(&vc, EstimatorParams::default(), Some(flight.origin()));
    let mut gi = 0;
    for smp in flight.imu() {
        while gi < flight.gnss().len() && flight.gnss()[gi].t_ns <= smp.t_ns {
            est.push_gnss(&flight.gnss()[gi]).unwrap();
            gi += 1;
        }
        est.push_imu(smp).unwrap();
    }
    let times = flight.camera_times_ns();
    let k = times.len() - 2;
    let (a, b) = (
        flight.camera_truth(k - 1).unwrap(),
        flight.camera_truth(k).unwrap(),
    );
    let prior = est.motion_prior(a.t_ns, b.t_ns);
    let truth = synth_egomotion(
        &flight,
        a,
        b,
        &Oracle {
            rot_sigma_rad: 0.0,
            dir_sigma_rad: 0.0,
            ..Oracle::default()
        },
        &mut Rng::new(0),
    );
    let r = prior.cam1_from_cam0.unwrap();
    assert!(r.angle_to(&truth.cam1_from_cam0) < 0.05f64.to_radians());
    let t = prior.t_cam1_m.unwrap();
    assert!((t.normalize() - truth.t_dir_cam1.unwrap().into_inner()).norm() < 0.02);
    let d = prior.ground_distance_m.unwrap();
    let agl = flight.local_frame().ned_to_lla(&a.pos_ned_m).alt_m - s.terrain.elevation_m;
    assert!((d - agl).abs() < 3.0, "{d} vs {agl}");
    let n = prior.ground_normal_cam0.unwrap();
    let n_true = (a.nav_from_body * flight.body_from_cam().rotation).inverse() * Vector3::z();
    assert!((n.into_inner() - n_true).norm() < 0.01);
}

#[test]
fn msl_altitudes_are_made_ellipsoidal_with_the_geoid() {
    // The same flight with its fixes given above mean sea level and the configuration saying so
    // gives the same poses as with ellipsoidal fixes.
    let s = scenario("smoke", Some(8.0));
    let flight = Flight::new(&s).unwrap();
    let mut vc = flight.vehicle_config();
    vc.camera = None;
    let run = |vc: &uavnav_core::VehicleConfig, to_msl: bool| {
        let mut est = Estimator::new(vc, EstimatorParams::default(), Some(flight.origin()));
        let mut gi = 0;
        let mut last = None;
        for smp in flight.imu() {
            while gi < flight.gnss().len() && flight.gnss()[gi].t_ns <= smp.t_ns {
                let mut f = flight.gnss()[gi];
                if to_msl {
                    f.alt_m -= uavnav_core::geoid::egm96_undulation_m(f.lat_deg, f.lon_deg);
                }
                est.push_gnss(&f).unwrap();
                gi += 1;
            }
            last = est.push_imu(smp).unwrap().or(last);
        }
        last.unwrap()
    };
    let ellipsoidal = run(&vc, false);
    let mut msl_cfg = vc.clone();
    if let Some(g) = msl_cfg.gnss.as_mut() {
        g.altitude_reference = uavnav_core::AltitudeReference::Msl;
    }
    let msl = run(&msl_cfg, true);
    let n = uavnav_core::geoid::egm96_undulation_m(
        flight.origin().lat_rad.to_degrees(),
        flight.origin().lon_rad.to_degrees(),
    );
    assert!(n.abs() > 1.0, "a place with a geoid undulation: {n}");
    assert!(
        (msl.lla.alt_m - ellipsoidal.lla.alt_m).abs() < 1e-3,
        "{} vs {}",
        msl.lla.alt_m,
        ellipsoidal.lla.alt_m
    );
    // Read as ellipsoidal, the same MSL fixes would sit N lower.
    let wrong = run(&vc, true);
    assert!((wrong.lla.alt_m - ellipsoidal.lla.alt_m + n).abs() < 0.5);
}

/// A hard landing on a ±16 g accelerometer: 0.1 s of samples with one axis saturated (and two
/// axes at full scale, |a| ≈ 22 g). They are taken, not refused as absurd, counted as clipped in
/// health, and the velocity σ grows to cover what the saturated axis missed.
#[test]
fn clipped_imu_samples_are_taken_counted_and_widen_the_velocity_sigma() {
    let (cfg, origin, mut imu, gnss, _) = static_data(30.0, 3);
    let full_scale = 16.0 * 9.80665;
    let burst = 20 * 200..20 * 200 + 20; // 0.1 s at 200 Hz, 20 s in
    let mut clean = Estimator::new(&cfg, EstimatorParams::default(), Some(origin));
    let clean_out = feed(&mut clean, &imu[..burst.end + 100], &gnss);
    for s in &mut imu[burst.clone()] {
        s.accel_mps2 = Vector3::new(full_scale, -full_scale, s.accel_mps2.z);
    }
    let mut est = Estimator::new(&cfg, EstimatorParams::default(), Some(origin));
    let out = feed(&mut est, &imu[..burst.end + 100], &gnss);
    let h = est.health();
    assert_eq!(h.inputs_rejected, 0, "{h:?}");
    assert!(h.imu_clipped >= 19, "{}", h.imu_clipped);
    let (a, b) = (clean_out.last().unwrap(), out.last().unwrap());
    assert!(
        b.sigma_vel_mps.xy().norm() > 2.0 * a.sigma_vel_mps.xy().norm(),
        "clipped σ {:?} vs clean {:?}",
        b.sigma_vel_mps,
        a.sigma_vel_mps
    );
}

/// A receiver whose fixes are valid `delay` before their stamps (ArduPilot's default
/// `EK3_GPS_DELAY` is 220 ms) and reach the filter in stamp order with the IMU: every fix valid
/// after the first IMU sample is fused at its validity time, none dropped as late, and the
/// vehicle stays put.
#[test]
fn gnss_delayed_beyond_the_fusion_delay_is_fused_not_dropped() {
    for delay_ns in [0, 220_000_000, 450_000_000] {
        let (mut cfg, origin, imu, gnss, _) = static_data(30.0, 3);
        if let Some(g) = cfg.gnss.as_mut() {
            g.delay_ns = delay_ns;
        }
        let mut est = Estimator::new(&cfg, EstimatorParams::default(), Some(origin));
        let out = feed(&mut est, &imu, &gnss);
        let last = out.last().expect("initialised");
        // Only fixes valid before the first IMU sample have no place in the filter's history.
        let before_imu = gnss
            .iter()
            .filter(|g| g.t_ns - delay_ns < imu[0].t_ns)
            .count() as u64;
        assert!(
            last.health.late_dropped <= before_imu,
            "delay {delay_ns} ns: {} fixes dropped as late",
            last.health.late_dropped
        );
        assert!(
            last.pos_ned_m.norm() < 2.0,
            "delay {delay_ns} ns: drifted to {:?}",
            last.pos_ned_m
        );
    }
}

#[test]
fn crowded_stamps_and_floods_stay_within_the_buffer_bound() {
    use uavnav_estimator::buffer::MAX_BUFFERED_BYTES;
    for profile in [FilterProfile::Eskf, FilterProfile::Paper] {
        let (mut cfg, origin, imu, gnss, _) = static_data(10.0, 5);
        cfg.profile = profile;
        let mut est = Estimator::new(&cfg, EstimatorParams::default(), Some(origin));
        feed(&mut est, &imu, &gnss);
        let t_end = imu.last().unwrap().t_ns;
        // 20,000 IMU samples 1 µs apart (20 ms of stamps, far denser than the configured rate),
        // and GNSS fixes stamped ahead of the IMU, faster than the horizon can fuse them.
        let last = *imu.last().unwrap();
        for i in 1..=20_000_i64 {
            let s = ImuSample {
                t_ns: t_end + i * 1_000,
                ..last
            };
            est.push_imu(&s).unwrap();
        }
        let fix = *gnss.last().unwrap();
        for i in 1..=10_000_i64 {
            let f = GnssFix {
                t_ns: t_end + 20_000_000 + i * 1_000,
                ..fix
            };
            est.push_gnss(&f).unwrap();
        }
        assert!(
            est.buffered_bytes() <= MAX_BUFFERED_BYTES,
            "{profile:?}: {} bytes buffered, bound {MAX_BUFFERED_BYTES}",
            est.buffered_bytes()
        );
        // The filter is still usable: time moves on and poses come out.
        let t = t_end + 100_000_000;
        let out = est
            .push_imu(&ImuSample { t_ns: t, ..last })
            .unwrap()
            .expect("a pose after the flood");
        assert!(out.pos_ned_m.iter().all(|v| v.is_finite()));
    }
}

/// The `paper` profile's GNSS-acceleration tilt source reports itself in every output's health
/// (fused and rejected windows, the latest test ratio); `eskf` has no such source and says so.
#[test]
fn the_gnss_tilt_source_is_in_the_health_of_the_profile_that_has_it() {
    let flight = Flight::new(&scenario("smoke", None)).unwrap();
    let paper = run(&flight, &RunCfg::new(FilterProfile::Paper, true, None));
    let last = paper.last().unwrap().health.gnss_tilt;
    // About one window a second over the 20 s flight, once the filters are up.
    assert!(last.fused >= 5, "{last:?}");
    assert!(last.fused + last.rejected <= 25, "{last:?}");
    assert!(
        last.test_ratio.is_finite() && last.test_ratio >= 0.0,
        "{last:?}"
    );
    // The count only grows, output by output.
    assert!(
        paper
            .windows(2)
            .all(|w| w[1].health.gnss_tilt.fused >= w[0].health.gnss_tilt.fused)
    );
    let eskf = run(&flight, &RunCfg::new(FilterProfile::Eskf, true, None));
    assert!(
        eskf.iter()
            .all(|o| o.health.gnss_tilt == Default::default())
    );
}

/// A receiver that gives ground speed and course but no vertical velocity (MAVLink's
/// `GPS_RAW_INT`, NMEA's RMC): the `paper` profile aligns and fuses it (before, it left every
/// such fix out and never started), with the attitude close to what the 3-D velocity gives.
#[test]
fn the_paper_profile_fuses_fixes_without_a_vertical_velocity() {
    let flight = Flight::new(&scenario("smoke", None)).unwrap();
    let mut vc = flight.vehicle_config();
    vc.profile = FilterProfile::Paper;
    vc.camera = None;
    let fly = |drop_vertical: bool| {
        let mut est = Estimator::new(&vc, EstimatorParams::default(), Some(flight.origin()));
        let mut fixes = flight.gnss().iter().peekable();
        let mut outs = Vec::new();
        for s in flight.imu() {
            while let Some(f) = fixes.next_if(|f| f.t_ns <= s.t_ns) {
                let mut f = *f;
                if drop_vertical && let Some(v) = f.velocity.as_mut() {
                    v.down_mps = None;
                }
                est.push_gnss(&f).unwrap();
            }
            if let Some(o) = est.push_imu(s).unwrap() {
                outs.push(o);
            }
        }
        outs
    };
    let tilt_rms_deg = |outs: &[uavnav_estimator::PoseOutput]| {
        let t_from = flight.imu()[0].t_ns + 5_000_000_000;
        let (mut sq, mut n) = (0.0, 0);
        for o in outs.iter().filter(|o| o.t_ns >= t_from) {
            let t = truth_at(flight.truth(), o.t_ns).unwrap();
            let e = euler_error(&o.nav_from_body, &t.nav_from_body);
            sq += e.x * e.x + e.y * e.y;
            n += 2;
        }
        (sq / n as f64).sqrt().to_degrees()
    };
    let full = fly(false);
    let horizontal = fly(true);
    let last = horizontal.last().unwrap();
    assert_eq!(last.health.mode, Mode::Nominal);
    assert!(
        last.health.gnss_vel.fused > 20,
        "{:?}",
        last.health.gnss_vel
    );
    let (a, b) = (tilt_rms_deg(&full), tilt_rms_deg(&horizontal));
    eprintln!("paper tilt RMS: 3-D velocity {a:.3} deg, horizontal only {b:.3} deg");
    assert!(b <= 2.0 * a + 0.2, "{a} {b}");
}
