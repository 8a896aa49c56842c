//! Magnetometer and barometer: physics against the WMM and the ISA, determinism, the merged
//! stream, opt-in (the shipped scenarios without the tables have neither) and scenario errors.
#![allow(clippy::unwrap_used)]

use nalgebra::{UnitQuaternion, Vector3};
use uavnav_core::SensorEvent;
use uavnav_core::geoid::egm96_undulation_m;
use uavnav_core::magnetic::MagneticModel;
use uavnav_sim::scenario::{MagDisturbanceSpec, WindowSpec};
use uavnav_sim::sensors::isa_height_m;
use uavnav_sim::{Flight, Scenario};

const MAG_BARO: &str = include_str!("../../scenarios/mag-baro.toml");
const SMOKE: &str = include_str!("../../scenarios/smoke.toml");
const PAPER_SMALL: &str = include_str!("../../scenarios/paper-small-lever.toml");
const PAPER_BIG: &str = include_str!("../../scenarios/paper-big-lever.toml");

fn mag_baro() -> Scenario {
    Scenario::from_toml_str(MAG_BARO).unwrap()
}

/// Index into the truth grid of a time stamp.
fn truth_index(flight: &Flight, t_ns: i64) -> usize {
    let t = flight.truth();
    let dt = t[1].t_ns - t[0].t_ns;
    let k = ((t_ns - t[0].t_ns) / dt) as usize;
    assert_eq!(t[k].t_ns, t_ns, "sample off the IMU grid");
    k
}

/// The mean of the samples taken back into NED through the truth attitude and mount, after the
/// known hard-iron residual is removed.
fn mean_field_ned(flight: &Flight, body_from_mag: &UnitQuaternion<f64>) -> Vector3<f64> {
    let bias = flight.mag_bias_t();
    let sum: Vector3<f64> = flight
        .mag()
        .iter()
        .map(|m| {
            let t = &flight.truth()[truth_index(flight, m.t_ns)];
            t.nav_from_body * (body_from_mag * (m.field_t - bias))
        })
        .sum();
    sum / flight.mag().len() as f64
}

#[test]
fn mag_mean_field_matches_wmm_direction_and_scaled_strength() {
    for rpy_deg in [[0.0, 0.0, 0.0], [180.0, 0.0, 90.0], [10.0, -20.0, 135.0]] {
        let mut sc = mag_baro();
        sc.mag.as_mut().unwrap().body_from_mag_rpy_deg = rpy_deg;
        let flight = Flight::new(&sc).unwrap();
        let spec = sc.mag.as_ref().unwrap();
        // 20 s at 10 Hz, both ends included.
        assert_eq!(flight.mag().len(), 201);
        let body_from_mag = flight.vehicle_config().mag.unwrap().body_from_mag;
        let [r, p, y] = rpy_deg.map(f64::to_radians);
        assert!(body_from_mag.angle_to(&UnitQuaternion::from_euler_angles(r, p, y)) < 1e-12);
        let wmm = MagneticModel::field(&flight.origin(), sc.date_year);
        assert_eq!(flight.mag_field_ned_t(), wmm.ned_t);
        // Near Capua: ~46 µT, declination ~ +4°, inclination ~ +57°.
        assert!((40e-6..52e-6).contains(&wmm.strength_t()), "{wmm:?}");
        let mean = uavnav_core::magnetic::MagneticField {
            ned_t: mean_field_ned(&flight, &body_from_mag),
        };
        let ddec = (mean.declination_rad() - wmm.declination_rad()).to_degrees();
        let dinc = (mean.inclination_rad() - wmm.inclination_rad()).to_degrees();
        let ratio = mean.strength_t() / wmm.strength_t();
        eprintln!(
            "mount {rpy_deg:?}: declination {:+.4}° inclination {:+.4}° strength ratio {ratio:.5}",
            ddec, dinc
        );
        assert!(
            ddec.abs() < 0.05 && dinc.abs() < 0.05,
            "{rpy_deg:?}: {ddec} {dinc}"
        );
        assert!((ratio - spec.scale).abs() < 1e-3, "{rpy_deg:?}: {ratio}");
        // Each sample: within 5σ per axis of the model once bias and mount are removed.
        for m in flight.mag() {
            let t = &flight.truth()[truth_index(&flight, m.t_ns)];
            let model = body_from_mag.inverse_transform_vector(
                &(spec.scale * t.nav_from_body.inverse_transform_vector(&wmm.ned_t)),
            );
            let err = m.field_t - flight.mag_bias_t() - model;
            assert!(err.amax() < 5.0 * spec.sigma_t, "{err:?}");
        }
        // The residual is the drawn one: of the order of its σ, not zero.
        let b = flight.mag_bias_t();
        assert!(
            b.norm() > 0.0 && b.amax() < 5.0 * spec.bias_sigma_t,
            "{b:?}"
        );
    }
}

#[test]
fn mag_disturbance_adds_its_body_field_inside_its_window_only() {
    let mut sc = mag_baro();
    let quiet = Flight::new(&sc).unwrap();
    let d = Vector3::new(2.0e-5, -1.0e-5, 5.0e-6);
    let mag = sc.mag.as_mut().unwrap();
    mag.body_from_mag_rpy_deg = [0.0, 0.0, 90.0];
    let quiet_mounted = Flight::new(&sc).unwrap();
    // As a file writes it.
    let parsed = Scenario::from_toml_str(&format!(
        "seed = 1\nduration_s = 1\n[mag]\ndisturbances = [{{ start_s = 5.0, end_s = 7.0, field_body_t = [{}, {}, {}] }}]\n",
        d.x, d.y, d.z
    ))
    .unwrap();
    let disturbances = parsed.mag.unwrap().disturbances;
    assert_eq!(
        disturbances,
        vec![MagDisturbanceSpec {
            window: WindowSpec {
                start_s: 5.0,
                end_s: 7.0
            },
            field_body_t: [d.x, d.y, d.z],
        }]
    );
    sc.mag.as_mut().unwrap().disturbances = disturbances;
    let disturbed = Flight::new(&sc).unwrap();
    let body_from_mag = disturbed.vehicle_config().mag.unwrap().body_from_mag;
    let t0 = disturbed.truth()[0].t_ns;
    let mut inside = 0;
    for (a, b) in quiet_mounted.mag().iter().zip(disturbed.mag()) {
        let t_s = (a.t_ns - t0) as f64 * 1e-9;
        let diff = body_from_mag * (b.field_t - a.field_t);
        if (5.0..7.0).contains(&t_s) {
            inside += 1;
            assert!((diff - d).norm() < 1e-15, "{t_s}: {diff:?}");
        } else {
            assert_eq!(diff, Vector3::zeros(), "{t_s}");
        }
    }
    assert_eq!(inside, 20);
    // The mount changes the readings, never the noise or the residual drawn.
    assert_eq!(quiet.mag_bias_t(), quiet_mounted.mag_bias_t());
}

#[test]
fn baro_pressure_maps_back_to_true_altitude_within_its_noise() {
    let sc = mag_baro();
    let spec = sc.baro.clone().unwrap();
    let flight = Flight::new(&sc).unwrap();
    assert_eq!(flight.baro().len(), 201);
    assert_eq!(flight.baro_offsets_pa().len(), 201);
    let frame = flight.local_frame();
    let (mut sum_sq, mut sum) = (0.0, 0.0);
    for (b, offset) in flight.baro().iter().zip(flight.baro_offsets_pa()) {
        let truth = &flight.truth()[truth_index(&flight, b.t_ns)];
        let lla = frame.ned_to_lla(&truth.pos_ned_m);
        let h_msl = isa_height_m(b.pressure_pa - offset, spec.sea_level_pa);
        let alt = h_msl + egm96_undulation_m(lla.lat_deg(), lla.lon_deg());
        let err = alt - lla.alt_m;
        // σ_p = 1 Pa is ~8.5 cm at 200 m.
        assert!(err.abs() < 5.0 * 0.085, "{}: {err}", b.t_ns);
        sum_sq += err * err;
        sum += err;
        let temp = b.temperature_degc.unwrap();
        assert!((temp - (15.0 - 6.5e-3 * h_msl)).abs() < 0.01, "{temp}");
    }
    let n = flight.baro().len() as f64;
    let rms = (sum_sq / n).sqrt();
    eprintln!("baro height error: rms {rms:.4} m, mean {:+.4} m", sum / n);
    assert!((0.06..0.11).contains(&rms), "rms {rms} m");
    assert!((sum / n).abs() < 0.03, "mean {} m", sum / n);
    // The offset starts at zero and follows the drift plus a small walk.
    let offsets = flight.baro_offsets_pa();
    assert_eq!(offsets[0], 0.0);
    let last = offsets[offsets.len() - 1];
    assert!((last - spec.drift_pa_per_s * 20.0).abs() < 0.5, "{last}");
    // Without the offset removed, the day's high sea-level pressure makes an ISA altimeter read
    // ~23 m low: what only a reference (GNSS) can remove.
    let b0 = &flight.baro()[0];
    let isa = isa_height_m(b0.pressure_pa, 101_325.0)
        + egm96_undulation_m(sc.origin.lat_deg, sc.origin.lon_deg);
    assert!((isa - sc.origin.alt_m + 22.9).abs() < 1.0, "{isa}");
}

#[test]
fn same_seed_same_samples_and_other_streams_unshifted() {
    let a = Flight::new(&mag_baro()).unwrap();
    let b = Flight::new(&mag_baro()).unwrap();
    assert_eq!(a.mag(), b.mag());
    assert_eq!(a.baro(), b.baro());
    assert_eq!(a.baro_offsets_pa(), b.baro_offsets_pa());
    // Same seed as smoke: fitting the sensors changes nothing else, bit for bit.
    let smoke = Flight::new(&Scenario::from_toml_str(SMOKE).unwrap()).unwrap();
    assert_eq!(a.truth(), smoke.truth());
    assert_eq!(a.imu(), smoke.imu());
    assert_eq!(a.gnss(), smoke.gnss());
    assert_eq!(a.camera_times_ns(), smoke.camera_times_ns());
    assert_eq!(
        a.render_frame(3).unwrap().data,
        smoke.render_frame(3).unwrap().data
    );
    // Another seed: other noise.
    let mut sc = mag_baro();
    sc.seed += 1;
    let c = Flight::new(&sc).unwrap();
    assert_ne!(a.mag()[5].field_t, c.mag()[5].field_t);
    assert_ne!(a.baro()[5].pressure_pa, c.baro()[5].pressure_pa);
    assert_ne!(a.mag_bias_t(), c.mag_bias_t());
}

#[test]
fn shipped_scenarios_without_the_tables_have_neither_sensor() {
    for text in [SMOKE, PAPER_SMALL, PAPER_BIG] {
        let sc = Scenario::from_toml_str(text).unwrap();
        assert!(sc.mag.is_none() && sc.baro.is_none());
        let flight = Flight::new(&sc).unwrap();
        assert!(flight.mag().is_empty() && flight.baro().is_empty());
        assert!(flight.baro_offsets_pa().is_empty());
        assert_eq!(flight.mag_bias_t(), Vector3::zeros());
        let vc = flight.vehicle_config();
        assert!(vc.mag.is_none() && vc.baro.is_none());
    }
    // The event stream of a camera-less smoke flight: IMU and GNSS only.
    let mut sc = Scenario::from_toml_str(SMOKE).unwrap();
    sc.camera.enabled = false;
    let flight = Flight::new(&sc).unwrap();
    let events: Vec<SensorEvent> = flight.events().map(Result::unwrap).collect();
    assert_eq!(events.len(), flight.imu().len() + flight.gnss().len());
    assert!(
        events
            .iter()
            .all(|e| matches!(e, SensorEvent::Imu(_) | SensorEvent::Gnss(_)))
    );
}

#[test]
fn vehicle_config_describes_the_fitted_sensors() {
    let flight = Flight::new(&mag_baro()).unwrap();
    let vc = flight.vehicle_config();
    let mag = vc.mag.unwrap();
    assert_eq!((mag.rate_hz, mag.sigma_t), (10.0, 1.0e-7));
    assert_eq!(mag.body_from_mag, UnitQuaternion::identity());
    let baro = vc.baro.unwrap();
    assert_eq!((baro.rate_hz, baro.sigma_pressure_pa), (10.0, 1.0));
    assert_eq!(vc.airframe, uavnav_core::Airframe::FixedWing);
}

#[test]
fn events_merge_mag_and_baro_in_time_then_rank_order() {
    let mut sc = mag_baro();
    sc.camera.enabled = false;
    let flight = Flight::new(&sc).unwrap();
    let events: Vec<SensorEvent> = flight.events().map(Result::unwrap).collect();
    let count = |f: fn(&SensorEvent) -> bool| events.iter().filter(|e| f(e)).count();
    assert_eq!(
        count(|e| matches!(e, SensorEvent::Mag(_))),
        flight.mag().len()
    );
    assert_eq!(
        count(|e| matches!(e, SensorEvent::Baro(_))),
        flight.baro().len()
    );
    assert_eq!(
        events.len(),
        flight.imu().len() + flight.gnss().len() + flight.mag().len() + flight.baro().len()
    );
    for w in events.windows(2) {
        assert!(
            (w[0].t_ns(), w[0].rank()) < (w[1].t_ns(), w[1].rank()),
            "{:?} then {:?}",
            (w[0].t_ns(), w[0].rank()),
            (w[1].t_ns(), w[1].rank())
        );
    }
    // At t0 all four sensors sample: IMU, GNSS, magnetometer, barometer.
    let ranks: Vec<u8> = events[..4].iter().map(SensorEvent::rank).collect();
    assert_eq!(ranks, vec![0, 1, 2, 3]);
    assert!(events[..4].iter().all(|e| e.t_ns() == sc.t0_ns));
}

/// The mag-baro scenario with one line replaced; returns the error and the replaced line's number.
fn broken(find: &str, replace: &str) -> (uavnav_sim::ScenarioError, usize) {
    let line = MAG_BARO.lines().position(|l| l.starts_with(find)).unwrap() + 1;
    let text: String = MAG_BARO
        .lines()
        .map(|l| {
            if l.starts_with(find) {
                replace.to_string()
            } else {
                l.to_string()
            }
        })
        .map(|l| l + "\n")
        .collect();
    (Scenario::from_toml_str(&text).unwrap_err(), line)
}

#[test]
fn bad_mag_and_baro_tables_are_refused_at_their_line() {
    let (e, line) = broken("scale = 0.7", "scael = 0.7");
    assert_eq!(e.line, line, "{e}");
    assert!(
        e.message.contains("unknown field") && e.message.contains("scael"),
        "{e}"
    );
    let (e, line) = broken("scale = 0.7", "scale = -0.7");
    assert_eq!(e.line, line, "{e}");
    assert!(e.message.contains("> 0"), "{e}");
    let (e, line) = broken("sigma_pressure_pa", "sigma_pressure_pa = -1.0");
    assert_eq!(e.line, line, "{e}");
    assert!(e.message.contains("≥ 0"), "{e}");
    let (e, line) = broken("drift_pa_per_s", "drift_pa_per_s = nan");
    assert_eq!(e.line, line, "{e}");
    assert!(e.message.contains("finite"), "{e}");
    let (e, line) = broken("date_year", "date_year = 1066.0");
    assert_eq!(e.line, line, "{e}");
    assert!(e.message.contains("decimal year"), "{e}");
    let (e, line) = broken(
        "disturbances",
        "disturbances = [{ start_s = 9.0, end_s = 8.0, field_body_t = [0.0, 0.0, 0.0] }]",
    );
    assert_eq!(e.line, line, "{e}");
    assert!(e.message.contains("start_s"), "{e}");
    let (e, _) = broken(
        "disturbances",
        "disturbances = [{ start_s = 1.0, end_s = 2.0 }]",
    );
    assert!(e.message.contains("field_body_t"), "{e}");
}

#[test]
fn empty_tables_fit_the_sensors_with_their_defaults() {
    let sc = Scenario::from_toml_str("seed = 1\nduration_s = 2\n[mag]\n[baro]\n").unwrap();
    assert_eq!(sc.date_year, uavnav_sim::scenario::DEFAULT_DATE_YEAR);
    let mag = sc.mag.clone().unwrap();
    assert_eq!(
        (mag.rate_hz, mag.sigma_t, mag.bias_sigma_t, mag.scale),
        (10.0, 1.0e-7, 5.0e-7, 1.0)
    );
    let baro = sc.baro.clone().unwrap();
    assert_eq!(
        (baro.rate_hz, baro.sigma_pressure_pa, baro.sea_level_pa),
        (10.0, 1.0, 101_325.0)
    );
    assert_eq!(
        (baro.drift_pa_per_s, baro.random_walk_pa_per_sqrt_s),
        (0.0, 0.0)
    );
    let flight = Flight::new(&sc).unwrap();
    assert_eq!((flight.mag().len(), flight.baro().len()), (21, 21));
}
