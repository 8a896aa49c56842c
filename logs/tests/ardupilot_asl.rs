//! Cross-check of the DataFlash import against the project's shared ASL conversions of the same
//! three raw logs (`shared/data/real_flights`, made with pymavlink by the rules its README states).
//!
//! Compared: sample counts and every value of `imu0`, `gnss0`, `mag0`, `baro0` and the EKF1
//! reference, within the CSV print precision (IMU and references `%.9g`, GNSS `%.9f`/`%.4f`, MAG
//! `%.6e`, BARO `%.3f`/`%.2f`), and the time offset of `conversion.json`.
//!
//! Differences, on purpose:
//! * GNSS stamps: the ASL rows are stamped `T − EKF_POS_DELAY` (T − 220 ms in all three logs);
//!   the importer stamps fixes as logged (`T`) and reports `gnss_delay_s` = 0.22 (also in
//!   `config.gnss.delay_ns`, which the estimator subtracts), so `t_ns − delay` is compared.
//! * GNSS altitude: the ASL adds one `N`, at the EKF origin, to every fix; we add `N` at each fix
//!   (the geoid moves ~3 cm/km here, the flights span a few hundred metres), so altitudes are
//!   compared to 5 mm instead of the print precision, and `N` at the origin to 0.1 mm.
//! * 103 is cut in the ASL at 208.5 s after the first IMU sample (`conversion.json` `t_end_s`,
//!   before a crash): the test applies that cut, the importer does not.
//! * 103's time offset: the ASL took the median over the GPS rows before its cut (1130 rows), we
//!   take it over all kept rows (1147); on 103 GPS time minus autopilot time wanders by seconds
//!   over the flight, so the medians differ by 150 ms. The test compares stamps after adding that
//!   difference (every stamp shares the one offset, so the comparison is exact otherwise).
//! * plane_E ends inside a message (the logger stopped mid-write), so it is imported with
//!   `stop_at_damage` and a note says where it stopped.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use uavnav_logs::{FlightLog, ImportOptions, LogKind, TimeBase, VehicleKind};

/// Rows of a CSV file as numbers (empty cells NaN); the header line is skipped.
fn csv(path: &std::path::Path) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .map(|c| c.trim().parse::<f64>().unwrap_or(f64::NAN))
                .collect()
        })
        .collect()
}

/// The integer first column (ns) exactly.
fn stamps(path: &std::path::Path) -> Vec<i64> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .next()
                .and_then(|c| c.parse().ok())
                .expect("stamp")
        })
        .collect()
}

/// `%.9g`-printed value: 9 significant digits.
fn close_g9(a: f64, b: f64) -> bool {
    (a - b).abs() <= 6e-9 * a.abs().max(b.abs()) + 1e-300
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

fn json_f64(text: &str, key: &str) -> Option<f64> {
    let at = text.find(&format!("\"{key}\""))?;
    let rest = &text[at + key.len() + 2..];
    let rest = rest.trim_start().strip_prefix(':')?.trim_start();
    let end = rest.find([',', '\n', '}']).unwrap_or(rest.len());
    rest[..end].trim().parse().ok()
}

fn json_i64(text: &str, key: &str) -> Option<i64> {
    let at = text.find(&format!("\"{key}\""))?;
    let rest = text[at + key.len() + 2..]
        .trim_start()
        .strip_prefix(':')?
        .trim_start();
    let end = rest.find([',', '\n', '}']).unwrap_or(rest.len());
    rest[..end].trim().parse().ok()
}

fn check_flight(root: &std::path::Path, name: &str) {
    let raw = root.join("raw").join(format!("{name}.BIN"));
    let bytes = std::fs::read(&raw).expect("raw log");
    let opts = ImportOptions {
        stop_at_damage: name == "erle_plane_E",
        ..ImportOptions::default()
    };
    let log: FlightLog = uavnav_logs::import(&bytes, &opts).expect("import");
    let asl = root.join(name).join("mav0");
    let conv = std::fs::read_to_string(root.join(name).join("conversion.json")).expect("json");

    assert_eq!(log.source, LogKind::ArduPilot);
    assert_eq!(log.time_base, TimeBase::Unix);
    let want_kind = if name.contains("plane") {
        VehicleKind::Plane
    } else {
        VehicleKind::Copter
    };
    assert_eq!(log.vehicle, want_kind, "{name}");
    let shift = json_i64(&conv, "offset_ns").expect("offset_ns") - log.time_offset_ns;
    let want_shift = if name == "erle_copter_103" {
        -150_000_000
    } else {
        0
    };
    assert_eq!(shift, want_shift, "{name} time offset");
    assert!((log.gnss_delay_s - 0.22).abs() < 1e-12);
    let gnss_cfg = log.config.gnss.expect("GNSS config");
    assert_eq!(gnss_cfg.delay_ns, 220_000_000);
    assert_eq!(log.config.mag.is_some(), !log.mag.is_empty());
    // EKF_GYRO_PNOISE 0.015 rad/s at the IMU rate, as the ASL sensor.yaml (0.0021 at 50 Hz)
    let rate = log.config.imu.rate_hz;
    assert!((log.config.imu.gyro_noise_density - 0.015 / rate.sqrt()).abs() < 1e-6);

    // 103: the ASL stops t_end_s after the first IMU sample.
    let t0 = log.imu[0].t_ns;
    let t_end = json_f64(&conv, "t_end_s").map_or(i64::MAX, |s| t0 + (s * 1e9).round() as i64);
    let delay_ns = (log.gnss_delay_s * 1e9).round() as i64;

    // IMU: the ASL keeps the board frame the autopilot logs in; the import rotates it into the
    // vehicle frame by AHRS_TRIM_X/Y (103: roll 0.68°, pitch −0.22°; plane_E: −0.63°, −1.17°;
    // 218: pitch −0.06°), so it is rotated back to compare.
    let trim = uavnav_logs::trim::vehicle_from_board(
        log.params.get("AHRS_TRIM_X").copied(),
        log.params.get("AHRS_TRIM_Y").copied(),
    )
    .expect("every shared flight has a trim");
    let board_from_vehicle = trim.inverse();
    if let Some(m) = log.config.mag {
        assert!(
            m.body_from_mag
                .angle_to(&nalgebra::UnitQuaternion::from_rotation_matrix(&trim))
                < 1e-12
        );
    }
    let p = asl.join("imu0/data.csv");
    let (want, want_t) = (csv(&p), stamps(&p));
    let imu: Vec<_> = log.imu.iter().filter(|s| s.t_ns <= t_end).collect();
    assert_eq!(imu.len(), want.len(), "{name} IMU count");
    for ((s, w), wt) in imu.iter().zip(&want).zip(&want_t) {
        assert_eq!(s.t_ns + shift, *wt, "{name} IMU stamp");
        let s = uavnav_logs::trim::rotate_imu(&board_from_vehicle, s);
        let got = [
            s.gyro_radps.x,
            s.gyro_radps.y,
            s.gyro_radps.z,
            s.accel_mps2.x,
            s.accel_mps2.y,
            s.accel_mps2.z,
        ];
        for (g, w) in got.iter().zip(&w[1..]) {
            assert!(close_g9(*g, *w), "{name} IMU at {}: {g} vs {w}", s.t_ns);
        }
    }

    // GNSS
    let p = asl.join("gnss0/data.csv");
    let (want, want_t) = (csv(&p), stamps(&p));
    // the ASL cut GNSS rows on their logged stamp, before the delay shift
    let gnss: Vec<_> = log.gnss.iter().filter(|g| g.t_ns <= t_end).collect();
    assert_eq!(gnss.len(), want.len(), "{name} GNSS count");
    let mut worst_alt = 0.0f64;
    let mut sigma_mismatch = Vec::new();
    for ((g, w), wt) in gnss.iter().zip(&want).zip(&want_t) {
        assert_eq!(g.t_ns - delay_ns + shift, *wt, "{name} GNSS stamp");
        assert!(
            close(g.lat_deg, w[1], 6e-10) && close(g.lon_deg, w[2], 6e-10),
            "{name} lat/lon"
        );
        worst_alt = worst_alt.max((g.alt_m - w[3]).abs());
        let v = g.velocity.expect("velocity");
        let got = [
            v.north_mps,
            v.east_mps,
            v.down_mps.unwrap_or(f64::NAN),
            g.sigma_h_m,
            g.sigma_v_m,
            v.sigma_mps,
        ];
        for (k, (a, b)) in got.iter().zip(&w[4..10]).enumerate() {
            if k >= 3 && !close(*a, *b, 6e-5) {
                sigma_mismatch.push((*wt, k + 4, *a, *b));
                continue;
            }
            assert!(
                close(*a, *b, 6e-5),
                "{name} GNSS column {} at {wt}: {a} vs {b}",
                k + 4
            );
        }
    }
    assert!(
        worst_alt < 0.005,
        "{name} GNSS altitude differs by {worst_alt} m"
    );
    // 103's first kept fix: the autopilot logged a backlog of 11 UBX3 rows with one stamp; we
    // take the last (the receiver's latest), the ASL took another of them
    let allowed: &[usize] = if name == "erle_copter_103" {
        &[7, 8, 9]
    } else {
        &[]
    };
    assert!(
        sigma_mismatch
            .iter()
            .all(|m| m.0 == want_t[0] && allowed.contains(&m.1)),
        "{name} sigma mismatches {sigma_mismatch:?}"
    );

    // MAG, BARO (absent folders = nothing imported)
    let p = asl.join("mag0/data.csv");
    let mag: Vec<_> = log.mag.iter().filter(|m| m.t_ns <= t_end).collect();
    if p.exists() {
        let (want, want_t) = (csv(&p), stamps(&p));
        assert_eq!(mag.len(), want.len(), "{name} MAG count");
        for ((m, w), wt) in mag.iter().zip(&want).zip(&want_t) {
            assert_eq!(m.t_ns + shift, *wt);
            for (a, b) in m.field_t.iter().zip(&w[1..4]) {
                assert!(
                    (a - b).abs() <= 5e-7 * b.abs() + 1e-15,
                    "{name} MAG {a} vs {b}"
                );
            }
        }
    } else {
        assert!(mag.is_empty(), "{name}: MAG imported but the ASL has none");
    }
    let p = asl.join("baro0/data.csv");
    let baro: Vec<_> = log.baro.iter().filter(|m| m.t_ns <= t_end).collect();
    if p.exists() {
        let (want, want_t) = (csv(&p), stamps(&p));
        assert_eq!(baro.len(), want.len(), "{name} BARO count");
        for ((b, w), wt) in baro.iter().zip(&want).zip(&want_t) {
            assert_eq!(b.t_ns + shift, *wt);
            assert!(
                close(b.pressure_pa, w[1], 6e-4),
                "{name} pressure {} vs {}",
                b.pressure_pa,
                w[1]
            );
            assert!(
                close(b.temperature_degc.unwrap_or(f64::NAN), w[2], 6e-3),
                "{name} temperature"
            );
        }
    } else {
        assert!(
            baro.is_empty(),
            "{name}: BARO imported but the ASL has none"
        );
    }

    // EKF1 reference and its origin
    let p = asl.join("state_groundtruth_estimate0/data.csv");
    let (want, want_t) = (csv(&p), stamps(&p));
    let reference: Vec<_> = log.reference.iter().filter(|r| r.t_ns <= t_end).collect();
    assert_eq!(log.reference_name.as_deref(), Some("EKF1"));
    assert_eq!(reference.len(), want.len(), "{name} reference count");
    for ((r, w), wt) in reference.iter().zip(&want).zip(&want_t) {
        assert_eq!(r.t_ns + shift, *wt);
        let q = r.nav_from_body.quaternion();
        // the sign of a quaternion is free
        let s = if (q.w * w[4]) < 0.0 { -1.0 } else { 1.0 };
        let got = [
            r.pos_ned_m.x,
            r.pos_ned_m.y,
            r.pos_ned_m.z,
            s * q.w,
            s * q.i,
            s * q.j,
            s * q.k,
            r.vel_ned_mps.x,
            r.vel_ned_mps.y,
            r.vel_ned_mps.z,
        ];
        for (a, b) in got.iter().zip(&w[1..11]) {
            assert!(
                (a - b).abs() <= 6e-9 * b.abs() + 1e-9,
                "{name} reference at {wt}: {a} vs {b}"
            );
        }
    }
    let o = log.reference_origin.expect("origin");
    let conv_origin = conv
        .find("\"origin\"")
        .map(|i| &conv[i..])
        .expect("origin in json");
    let nums: Vec<f64> = conv_origin
        .split(['[', ']'])
        .nth(1)
        .expect("origin list")
        .split(',')
        .map(|c| c.trim().parse().expect("number"))
        .collect();
    // the origin is a median of AHR2 − NED over thousands of rows (lat/lon in 1e-7° steps):
    // agree to 2e-7° (2 cm) and 1 cm
    let d_origin = [
        o.lat_deg() - nums[0],
        o.lon_deg() - nums[1],
        o.alt_m - nums[2],
    ];
    assert!(
        close(o.lat_deg(), nums[0], 2e-7) && close(o.lon_deg(), nums[1], 2e-7),
        "{name} origin {d_origin:?}"
    );
    assert!(close(o.alt_m, nums[2], 0.01), "{name} origin {d_origin:?}");
    let n = uavnav_core::geoid::egm96_undulation_m(nums[0], nums[1]);
    assert!(
        close(n, json_f64(&conv, "geoid_n_m").expect("geoid_n_m"), 1e-4),
        "{name} N {n}"
    );
    eprintln!(
        "{name}: IMU {} GNSS {} MAG {} BARO {} reference {} (worst altitude diff {:.4} m, origin diff {:?}), notes {:?}",
        imu.len(),
        gnss.len(),
        mag.len(),
        baro.len(),
        reference.len(),
        worst_alt,
        d_origin,
        log.notes
    );
}

#[test]
fn ardupilot_logs_match_shared_asl_conversions() {
    let Some(root) = uavnav_testdata::shared_data("real_flights") else {
        return;
    };
    for name in ["erle_copter_218", "erle_copter_103", "erle_plane_E"] {
        check_flight(&root, name);
    }
}
