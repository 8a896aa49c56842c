//! Writes a report for a synthetic flight (a turn through north, a GNSS outage, two runs with
//! known errors) and checks the files, the figures in the JSON, and that the PNGs decode.

#![allow(clippy::unwrap_used)]

use std::path::Path;

use nalgebra::Vector3;
use uavnav_core::rotation::{euler_zyx, from_euler_zyx};
use uavnav_core::{Lla, TruthSample};
use uavnav_core::{Mode, PoseHealth, PoseOutput};
use uavnav_report::{DEFAULT_MIN_GAP_NS, ReportError, Run, gnss_outages, write_report};

const S: i64 = 1_000_000_000;
const EPOCH_NS: i64 = 1_700_000_000 * S;
const SPEED_MPS: f64 = 20.0;
const TURN_RADPS: f64 = 0.035; // ≈ 2°/s
const YAW0_RAD: f64 = 2.9; // ≈ 166°: the heading crosses ±180° after ~7 s
const OUTAGE_S: (i64, i64) = (35, 45);

/// A coordinated circle at constant speed, 100 Hz, 60 s.
fn truth() -> Vec<TruthSample> {
    (0..=6000)
        .map(|k| {
            let t = k as f64 * 0.01;
            let yaw = YAW0_RAD + TURN_RADPS * t;
            let r = SPEED_MPS / TURN_RADPS;
            TruthSample {
                t_ns: EPOCH_NS + k * S / 100,
                pos_ned_m: Vector3::new(
                    r * (yaw.sin() - YAW0_RAD.sin()),
                    -r * (yaw.cos() - YAW0_RAD.cos()),
                    -100.0 + 2.0 * (0.2 * t).sin(),
                ),
                vel_ned_mps: Vector3::new(
                    SPEED_MPS * yaw.cos(),
                    SPEED_MPS * yaw.sin(),
                    0.4 * (0.2 * t).cos(),
                ),
                nav_from_body: from_euler_zyx((10.0f64).to_radians() * (0.3 * t).sin(), 0.05, yaw),
                gyro_bias_radps: Vector3::zeros(),
                accel_bias_mps2: Vector3::zeros(),
            }
        })
        .collect()
}

/// Outputs at 50 Hz with a constant attitude error (rad) and a north error growing linearly
/// to `drift_end_m` over the outage.
fn outputs(truth: &[TruthSample], att_err: Vector3<f64>, drift_end_m: f64) -> Vec<PoseOutput> {
    truth
        .iter()
        .skip(1)
        .step_by(2)
        .map(|tr| {
            let t_s = (tr.t_ns - EPOCH_NS) as f64 * 1e-9;
            let e = euler_zyx(&tr.nav_from_body) + att_err;
            let q = from_euler_zyx(e.x, e.y, e.z);
            let (a, b) = (OUTAGE_S.0 as f64, OUTAGE_S.1 as f64);
            let drift = if t_s >= a && t_s < b {
                drift_end_m * (t_s - a) / (b - a)
            } else {
                0.0
            };
            let health = PoseHealth {
                mode: if t_s < 1.0 {
                    Mode::Initialising
                } else {
                    Mode::Nominal
                },
                ..PoseHealth::default()
            };
            PoseOutput {
                t_ns: tr.t_ns,
                lla: Lla {
                    lat_rad: 0.8,
                    lon_rad: 0.2,
                    alt_m: -tr.pos_ned_m.z,
                },
                pos_ned_m: tr.pos_ned_m + Vector3::new(drift, 0.0, 0.3),
                vel_ned_mps: tr.vel_ned_mps + Vector3::new(0.05, -0.05, 0.02),
                nav_from_body: q,
                euler_rad: euler_zyx(&q),
                sigma_pos_ned_m: Vector3::new(1.0, 1.0, 1.5),
                sigma_vel_mps: Vector3::repeat(0.1),
                sigma_att_rad: Vector3::repeat(0.2f64.to_radians()),
                gyro_bias_radps: Vector3::zeros(),
                accel_bias_mps2: Vector3::zeros(),
                health,
                aiding: Default::default(),
            }
        })
        .collect()
}

fn gnss_times() -> Vec<i64> {
    (0..=300)
        .map(|k| EPOCH_NS + k * S / 5)
        .filter(|&t| t <= EPOCH_NS + OUTAGE_S.0 * S || t >= EPOCH_NS + OUTAGE_S.1 * S)
        .collect()
}

fn assert_png(path: &Path) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}", path.display());
    let img = image::load_from_memory(&bytes).unwrap().to_rgb8();
    assert!(
        img.width() >= 800 && img.height() >= 300,
        "{}",
        path.display()
    );
    let inked = img.pixels().filter(|p| p.0 != [255, 255, 255]).count();
    let share = inked as f64 / (img.width() * img.height()) as f64;
    assert!(
        share > 0.01,
        "{}: only {share} of pixels drawn",
        path.display()
    );
    // the first run's colour (blue) must appear: its lines were drawn
    let blue = img.pixels().filter(|p| p.0 == [20, 80, 220]).count();
    assert!(blue > 200, "{}: {blue} run-colour pixels", path.display());
}

fn deg3(r: f64, p: f64, y: f64) -> Vector3<f64> {
    Vector3::new(r, p, y).map(f64::to_radians)
}

#[test]
fn writes_tables_and_figures() {
    let truth = truth();
    let video = outputs(&truth, deg3(0.05, -0.02, 0.1), 2.0);
    let gnss_only = outputs(&truth, deg3(0.06, 0.04, 0.5), 6.0);
    let runs = [
        Run {
            label: "eskf, IMU+GNSS+video".into(),
            outputs: &video,
        },
        Run {
            label: "eskf, IMU+GNSS".into(),
            outputs: &gnss_only,
        },
    ];
    let outages = gnss_outages(&gnss_times(), DEFAULT_MIN_GAP_NS);
    assert_eq!(
        outages,
        vec![(EPOCH_NS + OUTAGE_S.0 * S, EPOCH_NS + OUTAGE_S.1 * S)]
    );

    // UAVNAV_REPORT_DIR keeps the report for a look at the figures
    let dir = tempfile::tempdir().unwrap();
    let out = std::env::var_os("UAVNAV_REPORT_DIR")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| dir.path().join("report"));
    let summary = write_report(&out, &runs, &truth, &outages).unwrap();
    assert_eq!(summary.files.len(), 7);
    for f in &summary.files {
        assert!(f.exists(), "{}", f.display());
    }

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("accuracy.json")).unwrap()).unwrap();
    let arr = json.as_array().unwrap();
    assert_eq!(arr.len(), 2);
    let v = &arr[0];
    assert_eq!(v["label"], "eskf, IMU+GNSS+video");
    let att = &v["attitude_rmse_deg"];
    assert!((att["roll"].as_f64().unwrap() - 0.05).abs() < 1e-3, "{att}");
    assert!(
        (att["pitch"].as_f64().unwrap() - 0.02).abs() < 1e-3,
        "{att}"
    );
    assert!((att["yaw"].as_f64().unwrap() - 0.1).abs() < 1e-3, "{att}");
    // 2 m after 200 m flown (the ratio is exact: both grow linearly to the last output)
    let pct = v["outages"][0]["percent"].as_f64().unwrap();
    assert!((pct - 1.0).abs() < 0.01, "{pct}");
    assert!((arr[1]["outages"][0]["percent"].as_f64().unwrap() - 3.0).abs() < 0.03);
    assert!((arr[1]["attitude_rmse_deg"]["yaw"].as_f64().unwrap() - 0.5).abs() < 1e-3);
    assert_eq!(v["run"]["outputs"], 3000);
    assert_eq!(v["run"]["final_mode"], "nominal");
    let init = v["run"]["mode_fraction"]["initialising"].as_f64().unwrap();
    assert!((init - 50.0 / 3000.0).abs() < 1e-9, "{init}");
    assert_eq!(v["outage_windows_ns"][0][1], EPOCH_NS + OUTAGE_S.1 * S);

    let md = std::fs::read_to_string(out.join("accuracy.md")).unwrap();
    assert!(md.contains("| run | roll RMSE"));
    assert!(
        md.contains("| eskf, IMU+GNSS+video | 0.050 | 0.020 | 0.100 | 1.00 %"),
        "{md}"
    );
    // outputs start 10 ms after the truth: times are seconds since the first output
    assert!(md.contains("34.99 s – 44.99 s"), "{md}");
    assert!(md.contains("(position_down.png)"));

    for f in [
        "attitude.png",
        "attitude_error.png",
        "velocity_ned.png",
        "position_down.png",
        "horizontal_error.png",
    ] {
        assert_png(&out.join(f));
    }
    // the down-position figure has the zoom panel: two panels tall
    let (_, h) = image::image_dimensions(out.join("position_down.png")).unwrap();
    let (_, h1) = image::image_dimensions(out.join("horizontal_error.png")).unwrap();
    assert_eq!(h, 2 * h1);
}

#[test]
fn tables_are_deterministic() {
    let truth = truth();
    let o = outputs(&truth, deg3(0.05, 0.0, 0.0), 1.0);
    let runs = [Run {
        label: "a".into(),
        outputs: &o,
    }];
    let outages = [(EPOCH_NS + OUTAGE_S.0 * S, EPOCH_NS + OUTAGE_S.1 * S)];
    let params = uavnav_report::PlotParams {
        width_px: 400,
        panel_height_px: 150,
        max_points: 500,
    };
    let dirs = [tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap()];
    for d in &dirs {
        uavnav_report::write_report_with(d.path(), &runs, &truth, &outages, &params).unwrap();
    }
    for f in ["accuracy.json", "accuracy.md", "attitude.png"] {
        let a = std::fs::read(dirs[0].path().join(f)).unwrap();
        let b = std::fs::read(dirs[1].path().join(f)).unwrap();
        assert!(a == b, "{f} differs between two identical runs");
    }
}

#[test]
fn empty_inputs_are_errors() {
    let truth = truth();
    let dir = tempfile::tempdir().unwrap();
    let none: [Run; 0] = [];
    assert!(matches!(
        write_report(dir.path(), &none, &truth, &[]),
        Err(ReportError::Empty(_))
    ));
    let o = outputs(&truth, Vector3::zeros(), 0.0);
    let runs = [Run {
        label: "x".into(),
        outputs: &o,
    }];
    assert!(matches!(
        write_report(dir.path(), &runs, &[], &[]),
        Err(ReportError::Empty(_))
    ));
}
