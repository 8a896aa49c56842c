//! Flight logs where a dataset goes, through the `uavnav` binary: `convert` of a real ArduPilot
//! log to ASL and MCAP checked against the shared ASL conversion of the same log, `estimate` of a
//! real log end to end with a report scored against the autopilot's estimate (named as a
//! reference, never truth), and a cut log refused with its byte offset and exit code 2.
//! Skips with a message when `../shared/data` is absent.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::path::Path;
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_uavnav");

fn run(args: &[&str]) -> Output {
    let out = Command::new(BIN).args(args).output().expect("uavnav runs");
    eprintln!(
        "$ uavnav {}\n-> {:?}\nstdout: {}\nstderr: {}",
        args.join(" "),
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The data rows of a `data.csv` (header and comments skipped).
fn rows(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(str::to_owned)
        .collect()
}

fn stamp(row: &str) -> i64 {
    row.split(',')
        .next()
        .and_then(|c| c.parse().ok())
        .expect("stamp")
}

fn values(row: &str) -> Vec<f64> {
    row.split(',')
        .skip(1)
        .map(|c| c.trim().parse().unwrap_or(f64::NAN))
        .collect()
}

/// Within the shared CSVs' print precision (their README: `%.9g` IMU and references, `%.9f` /
/// `%.4f` GNSS, `%.6e` MAG, `%.3f` / `%.2f` BARO); GNSS altitude to 5 mm, as the shared ASL adds
/// the geoid height at the EKF origin to every fix where the importer adds it at each fix.
fn close(folder: &str, col: usize, u: f64, v: f64) -> bool {
    let tol = match (folder, col) {
        ("gnss0", 0 | 1) => 1e-9,
        ("gnss0", 2) => 5e-3,
        ("gnss0", _) => 6e-5,
        ("baro0", _) => 6e-3,
        ("mag0", _) => 5e-7 * v.abs() + 1e-15,
        _ => 6e-9 * v.abs() + 1e-9,
    };
    (u - v).abs() <= tol
}

#[test]
fn convert_ardupilot_log_matches_the_shared_asl_folder() {
    let Some(root) = uavnav_tests::shared_data("real_flights") else {
        return;
    };
    let raw = root.join("raw/erle_copter_218.BIN");
    let shared = root.join("erle_copter_218/mav0");
    let dir = tempfile::tempdir().expect("tempdir");
    let asl = dir.path().join("asl");
    let out = run(&[
        "convert",
        raw.to_str().expect("path"),
        "--out",
        asl.to_str().expect("path"),
    ]);
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("16750 IMU, 1692 GNSS, 3350 mag, 3350 baro, 0 frames, 0 truth, 3022 reference (autopilot estimate, EKF1)"),
        "{text}"
    );
    let ours = asl.join("mav0");
    // The shared folder keeps the board frame the autopilot logs in and records AHRS_TRIM_X/Y in
    // its conversion.json; ours is in the vehicle frame (218: a pitch trim of −0.06°), so our IMU
    // is rotated back to compare, and our compass's T_BS is that rotation.
    let trim = uavnav_dataset::asl::conversion::vehicle_from_board(&root.join("erle_copter_218"))
        .expect("conversion.json")
        .expect("a trim");
    let mag_yaml = std::fs::read_to_string(ours.join("mag0/sensor.yaml")).expect("yaml");
    assert!(
        mag_yaml.contains("data: [0.999999403953594, 0.0, -0.00109182986624"),
        "{mag_yaml}"
    );
    for folder in [
        "imu0",
        "gnss0",
        "mag0",
        "baro0",
        "state_groundtruth_estimate0",
    ] {
        let (a, b) = (
            rows(&ours.join(folder).join("data.csv")),
            rows(&shared.join(folder).join("data.csv")),
        );
        assert_eq!(a.len(), b.len(), "{folder} rows");
        for (x, y) in a.iter().zip(&b) {
            // The shared ASL stamps fixes at T − 220 ms (EKF_POS_DELAY); ours keep the logged T
            // and carry the delay in gnss0/sensor.yaml.
            let shift = if folder == "gnss0" { 220_000_000 } else { 0 };
            assert_eq!(stamp(x) - shift, stamp(y), "{folder} stamp");
            let (mut u, v) = (values(x), values(y));
            if folder == "imu0" {
                let board = trim.inverse();
                let w = board * nalgebra::Vector3::new(u[0], u[1], u[2]);
                let a = board * nalgebra::Vector3::new(u[3], u[4], u[5]);
                u[..6].copy_from_slice(&[w.x, w.y, w.z, a.x, a.y, a.z]);
            }
            if folder == "state_groundtruth_estimate0" && u[3] * v[3] < 0.0 {
                // q and −q are the same rotation (the converters' Euler formulas differ in sign)
                u[3..7].iter_mut().for_each(|c| *c = -*c);
            }
            for (col, (u, v)) in u.iter().zip(v).enumerate() {
                assert!(close(folder, col, *u, v), "{folder}: {x} vs {y}");
            }
        }
    }
    let gnss_yaml = std::fs::read_to_string(ours.join("gnss0/sensor.yaml")).expect("yaml");
    assert!(gnss_yaml.contains("delay_s: 0.22"), "{gnss_yaml}");
    let ref_yaml = std::fs::read_to_string(ours.join("state_groundtruth_estimate0/sensor.yaml"))
        .expect("yaml");
    assert!(ref_yaml.contains("NOT ground truth"), "{ref_yaml}");

    let mcap = dir.path().join("x.mcap");
    let out = run(&[
        "convert",
        raw.to_str().expect("path"),
        "--out",
        mcap.to_str().expect("path"),
        "--gnss-delay-s",
        "0.2",
    ]);
    assert_eq!(out.status.code(), Some(0));
    let ds = uavnav_dataset::Dataset::open(&mcap).expect("MCAP");
    assert!(ds.truth().is_none());
    assert_eq!(ds.reference().map(|r| r.samples.len()), Some(3022));
    assert_eq!(ds.config().gnss.map(|g| g.delay_ns), Some(200_000_000));
    let mut counts = [0usize; 4];
    for e in ds.events().expect("events") {
        match e.expect("event") {
            uavnav_core::SensorEvent::Imu(_) => counts[0] += 1,
            uavnav_core::SensorEvent::Gnss(_) => counts[1] += 1,
            uavnav_core::SensorEvent::Mag(_) => counts[2] += 1,
            uavnav_core::SensorEvent::Baro(_) => counts[3] += 1,
            uavnav_core::SensorEvent::Camera(_) => panic!("no camera in the log"),
        }
    }
    let shared_counts =
        ["imu0", "gnss0", "mag0", "baro0"].map(|f| rows(&shared.join(f).join("data.csv")).len());
    assert_eq!(counts, shared_counts);
}

#[test]
fn estimate_a_real_log_with_a_report_against_the_autopilot_reference() {
    let Some(root) = uavnav_tests::shared_data("real_flights") else {
        return;
    };
    let raw = root.join("raw/erle_plane_E.BIN");
    let raw = raw.to_str().expect("path");
    let dir = tempfile::tempdir().expect("tempdir");
    let poses = dir.path().join("poses.csv");
    let report = dir.path().join("report");
    let (poses_s, report_s) = (
        poses.to_str().expect("path"),
        report.to_str().expect("path"),
    );

    // plane_E's logger stopped inside its last message: read up to it by default, with a note
    // naming the offset (corruption inside the log is still refused unless --stop-at-damage)
    let out = run(&["estimate", raw, "--out", poses_s, "--report", report_s]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("erle_plane_E.BIN") && err.contains("truncated at byte 1794025"),
        "{err}"
    );
    assert_eq!(out.status.code(), Some(0));
    // The IMU's measured noise over the run: a 10 Hz log of a manoeuvring plane is far noisier
    // than any IMU's datasheet says.
    assert!(err.contains("IMU noise against its configuration"), "{err}");
    let rows = rows(&poses);
    assert!(rows.len() > 5000, "{} poses", rows.len());
    for r in &rows {
        assert!(!r.contains("NaN") && !r.contains("inf"), "{r}");
    }
    for f in [
        "accuracy.json",
        "accuracy.md",
        "attitude.png",
        "attitude_error.png",
        "velocity_ned.png",
        "position_down.png",
        "horizontal_error.png",
    ] {
        assert!(report.join(f).is_file(), "{f} missing");
    }
    let md = std::fs::read_to_string(report.join("accuracy.md")).expect("md");
    assert!(
        md.contains("Scored against: **reference (autopilot estimate, EKF1)**"),
        "{md}"
    );
    assert!(md.contains("not ground truth"));
    assert!(!md.contains("against truth"), "{md}");
    // the plane logged no camera, magnetometer or barometer
    assert!(md.contains("eskf, IMU+GNSS |"), "{md}");
    assert!(!md.contains("video"), "{md}");
    let json = std::fs::read_to_string(report.join("accuracy.json")).expect("json");
    assert!(json.contains("\"scored_against\": \"reference (autopilot estimate, EKF1)\""));
}

/// copter_103's EKF1 fails in the crash that ends the log (the shared conversion stops its
/// reference at 163 s for that reason): the report leaves those samples out and says so, instead
/// of scoring the estimate against them.
#[test]
fn a_reference_that_leaves_the_gnss_fixes_is_screened_out_and_said() {
    let Some(root) = uavnav_tests::shared_data("real_flights") else {
        return;
    };
    let raw = root.join("raw/erle_copter_103.BIN");
    let dir = tempfile::tempdir().expect("tempdir");
    let (poses, report) = (dir.path().join("poses.csv"), dir.path().join("report"));
    let out = run(&[
        "estimate",
        raw.to_str().expect("path"),
        "--out",
        poses.to_str().expect("path"),
        "--report",
        report.to_str().expect("path"),
    ]);
    assert_eq!(out.status.code(), Some(0));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout
        .lines()
        .find(|l| l.starts_with("Scored against: reference (autopilot estimate, EKF1); "))
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(
        line.contains("samples left out as implausibly far from the GNSS fixes"),
        "{line}"
    );
    let json = std::fs::read_to_string(report.join("accuracy.json")).expect("json");
    assert!(json.contains("left out as implausibly far"), "{json}");
}

#[test]
fn a_cut_log_imports_with_a_note_and_a_corrupt_one_is_refused_with_its_byte_offset() {
    let Some(root) = uavnav_tests::shared_data("real_flights") else {
        return;
    };
    let data = std::fs::read(root.join("raw/erle_copter_218.BIN")).expect("log");
    let dir = tempfile::tempdir().expect("tempdir");
    // cut mid-message (the logger lost power): what came before is imported, with a note
    let cut = dir.path().join("cut.BIN");
    std::fs::write(&cut, &data[..1_000_003]).expect("write");
    let out = run(&[
        "convert",
        cut.to_str().expect("path"),
        "--out",
        dir.path().join("x").to_str().expect("path"),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(
        err.contains("cut.BIN") && err.contains("ends inside a message") && err.contains("at byte"),
        "{err}"
    );
    assert!(dir.path().join("x/mav0/imu0/data.csv").is_file());
    // a message header destroyed in the middle: refused, one line naming the byte offset
    let mut bad = data.clone();
    let at = 1_000_000
        + bad[1_000_000..]
            .windows(2)
            .position(|w| w == [0xA3, 0x95])
            .expect("a message header");
    bad[at] = 0;
    let corrupt = dir.path().join("corrupt.BIN");
    std::fs::write(&corrupt, &bad).expect("write");
    let out = run(&[
        "convert",
        corrupt.to_str().expect("path"),
        "--out",
        dir.path().join("y").to_str().expect("path"),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("corrupt.BIN") && err.contains(&format!("at byte {at}")),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
}

/// A ground station's MAVLink telemetry (`.tlog`, ArduPlane VTOL SITL at ~4 Hz): estimated end to
/// end from horizontal GNSS velocity (`GPS_RAW_INT` has no vertical one), with the slow IMU and
/// the assumed GNSS delay said on stderr and each refused input named by its stream.
#[test]
fn estimate_a_mavlink_telemetry_log() {
    let Some(root) = uavnav_tests::shared_data("public_flight_logs") else {
        return;
    };
    let tlog = root.join("ardupilot_vtol_sitl.tlog");
    let dir = tempfile::tempdir().expect("tempdir");
    let poses = dir.path().join("poses.csv");
    let out = run(&[
        "estimate",
        tlog.to_str().unwrap(),
        "--out",
        poses.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(0));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("IMU at 4.2 Hz (a telemetry stream)"), "{err}");
    assert!(err.contains("GNSS delay not known"), "{err}");
    // 4 Hz telemetry drops samples: gaps beyond the IMU limit are refused, by name.
    assert!(err.contains("IMU sample at "), "{err}");
    assert!(err.contains("fused IMU+GNSS"), "{err}");
    let rows = rows(&poses);
    assert!(rows.len() > 500, "{} poses", rows.len());
    for r in &rows {
        assert!(!r.contains("NaN") && !r.contains("inf"), "{r}");
    }
}

#[test]
fn estimate_leaves_out_the_sources_asked() {
    let Some(root) = uavnav_tests::shared_data("real_flights") else {
        return;
    };
    let raw = root.join("raw/erle_copter_218.BIN");
    let raw = raw.to_str().expect("path");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = |name: &str| dir.path().join(name).to_str().expect("path").to_owned();
    let (all, no_mag, report) = (path("all.csv"), path("no_mag.csv"), path("report"));
    let out = run(&["estimate", raw, "--out", &all]);
    assert_eq!(out.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&out.stderr).contains("IMU+GNSS+mag"));
    let out = run(&[
        "estimate",
        raw,
        "--no-mag",
        "--no-baro",
        "--out",
        &no_mag,
        "--report",
        &report,
    ]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Neither fused nor listed as read, and the heading comes from elsewhere.
    let md = std::fs::read_to_string(dir.path().join("report/accuracy.md")).expect("md");
    assert!(md.contains("eskf, IMU+GNSS |"), "{md}");
    let (a, b) = (
        rows(dir.path().join("all.csv").as_path()),
        rows(dir.path().join("no_mag.csv").as_path()),
    );
    assert!(a.len() > 10_000 && b.len() > 10_000);
    assert_ne!(a, b);
}
