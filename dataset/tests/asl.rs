//! ASL folders: write/read round trip, the real EuRoC subset, and one test per kind of bad input.

#![allow(clippy::unwrap_used)] // tests may unwrap

mod common;

use std::fs;
use std::path::Path;

use uavnav_core::SensorEvent;
use uavnav_dataset::{Dataset, DatasetError, MissingImages, ReadOptions};

fn read_all(ds: &Dataset) -> Result<Vec<SensorEvent>, DatasetError> {
    ds.events()?.collect()
}

#[test]
fn write_then_read_gives_the_same_flight() {
    let dir = tempfile::tempdir().unwrap();
    let (events, truth) = common::write_asl(dir.path(), 3);
    let ds = Dataset::open(dir.path()).unwrap();
    assert_eq!(ds.vehicle_id(), "uav-test");
    assert_eq!(read_all(&ds).unwrap(), events);
    assert_eq!(ds.truth().unwrap(), truth.as_slice());
    let o = ds.origin().unwrap();
    assert!((o.lat_deg() - 40.85).abs() < 1e-12 && o.alt_m == 150.0);
    let (c, want) = (ds.config(), common::config());
    assert_eq!(c.imu, want.imu);
    assert_eq!(c.gnss, want.gnss);
    assert_eq!(
        (c.terrain_elevation_m, c.profile),
        (want.terrain_elevation_m, want.profile)
    );
    let (cam, want_cam) = (c.camera.as_ref().unwrap(), want.camera.as_ref().unwrap());
    assert_eq!(cam.model, want_cam.model);
    assert!(
        (cam.body_from_cam.to_homogeneous() - want_cam.body_from_cam.to_homogeneous())
            .abs()
            .max()
            < 1e-12
    );
    // Also opens from the mav0 folder itself.
    assert_eq!(
        Dataset::open(dir.path().join("mav0")).unwrap().vehicle_id(),
        "uav-test"
    );
}

#[test]
fn writer_files_have_the_documented_headers() {
    let dir = tempfile::tempdir().unwrap();
    common::write_asl(dir.path(), 1);
    let first_line = |p: &str| {
        fs::read_to_string(dir.path().join("mav0").join(p))
            .unwrap()
            .lines()
            .next()
            .unwrap()
            .to_owned()
    };
    assert_eq!(
        first_line("imu0/data.csv"),
        uavnav_dataset::asl::layout::IMU_HEADER
    );
    assert_eq!(
        first_line("gnss0/data.csv"),
        uavnav_dataset::asl::layout::GNSS_HEADER
    );
    assert_eq!(first_line("cam0/data.csv"), "#timestamp [ns],filename");
    assert!(
        first_line("state_groundtruth_estimate0/data.csv")
            .starts_with("#timestamp, p_RS_R_x [m], ")
    );
    let cam = fs::read_to_string(dir.path().join("mav0/cam0/data.csv")).unwrap();
    let row = cam.lines().nth(1).unwrap();
    assert_eq!(row, "1050000000,1050000000.jpg");
    assert!(dir.path().join("mav0/cam0/data/1050000000.jpg").is_file());
    assert!(dir.path().join("mav0/cam0/data/1150000000.png").is_file());
}

#[test]
fn reads_the_real_euroc_folder() {
    let Some(path) = common::euroc() else { return };
    let ds = Dataset::open(&path).unwrap();
    let c = ds.config();
    let cam = c.camera.as_ref().unwrap();
    assert_eq!((cam.model.width, cam.model.height), (752, 480));
    assert_eq!(cam.model.fx, 458.654);
    assert!((cam.body_from_cam.translation.vector.x - -0.0216401454975).abs() < 1e-12);
    assert_eq!(c.imu.rate_hz, 200.0);
    assert_eq!(c.imu.gyro_noise_density, 1.6968e-04);
    assert!(c.gnss.is_none() && ds.truth().is_none() && ds.origin().is_none());
    let mut stream = ds.events().unwrap();
    let (mut imu, mut frames, mut last) = (0, 0, i64::MIN);
    for e in stream.by_ref() {
        let e = e.unwrap();
        assert!(e.t_ns() >= last);
        last = e.t_ns();
        match e {
            SensorEvent::Imu(_) => imu += 1,
            SensorEvent::Camera(f) => {
                assert_eq!(f.format, uavnav_core::ImageFormat::Png);
                frames += 1;
            }
            SensorEvent::Gnss(_) | SensorEvent::Mag(_) | SensorEvent::Baro(_) => unreachable!(),
        }
    }
    assert_eq!((imu, frames, stream.skipped_images()), (29120, 95, 0));
}

/// A fresh synthetic folder to break.
fn broken(f: impl FnOnce(&Path)) -> (tempfile::TempDir, DatasetError) {
    let dir = tempfile::tempdir().unwrap();
    common::write_asl(dir.path(), 1);
    f(&dir.path().join("mav0"));
    let err = match Dataset::open(dir.path()) {
        Err(e) => e,
        Ok(ds) => read_all(&ds).unwrap_err(),
    };
    (dir, err)
}

fn edit_line(path: &Path, line: usize, edit: impl FnOnce(&str) -> String) {
    let text = fs::read_to_string(path).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    lines[line - 1] = edit(&lines[line - 1]);
    fs::write(path, lines.join("\n") + "\n").unwrap();
}

#[test]
fn missing_column_names_file_and_line() {
    let (_d, e) = broken(|mav| {
        edit_line(&mav.join("imu0/data.csv"), 1, |h| {
            h.replace(",a_RS_S_z [m s^-2]", "")
        })
    });
    let msg = e.to_string();
    assert!(
        msg.contains("imu0/data.csv:1: missing column `a_RS_S_z`"),
        "{msg}"
    );
}

#[test]
fn non_numeric_cell_names_file_and_line() {
    let (_d, e) = broken(|mav| {
        edit_line(&mav.join("gnss0/data.csv"), 3, |row| {
            let mut cells: Vec<&str> = row.split(',').collect();
            cells[2] = "abc";
            cells.join(",")
        })
    });
    let msg = e.to_string();
    assert!(
        msg.contains("gnss0/data.csv:3: column `longitude`: 'abc' is not a finite number"),
        "{msg}"
    );
    assert_eq!(e.line(), Some(3));
}

#[test]
fn timestamps_going_backwards() {
    let (_d, e) = broken(|mav| {
        edit_line(&mav.join("imu0/data.csv"), 10, |row| {
            row.replacen("10", "09", 1)
        })
    });
    assert!(
        matches!(e, DatasetError::TimeBackwards { line: 10, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("imu0/data.csv:10: timestamp"), "{e}");
}

#[test]
fn unreadable_image() {
    let (_d, e) =
        broken(|mav| fs::write(mav.join("cam0/data/1250000000.jpg"), b"not an image").unwrap());
    let msg = e.to_string();
    assert!(
        msg.contains("1250000000.jpg: unreadable image (not a JPEG or PNG file)"),
        "{msg}"
    );
    assert!(msg.contains("cam0/data.csv:4"), "{msg}");
}

#[test]
fn missing_image_is_skipped_and_counted_or_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let (events, _) = common::write_asl(dir.path(), 1);
    fs::remove_file(dir.path().join("mav0/cam0/data/1250000000.jpg")).unwrap();
    let ds = Dataset::open(dir.path()).unwrap();
    let mut stream = ds.events().unwrap();
    let got: Vec<_> = stream.by_ref().map(Result::unwrap).collect();
    assert_eq!(got.len(), events.len() - 1);
    assert_eq!(stream.skipped_images(), 1);

    let strict = ReadOptions {
        missing_images: MissingImages::Error,
        ..Default::default()
    };
    let e = read_all(&Dataset::open_with(dir.path(), &strict).unwrap()).unwrap_err();
    assert!(matches!(e, DatasetError::Image { line: 4, .. }), "{e}");
}

#[test]
fn missing_sensor_yaml() {
    let (_d, e) = broken(|mav| fs::remove_file(mav.join("cam0/sensor.yaml")).unwrap());
    assert!(matches!(e, DatasetError::MissingFile { .. }), "{e}");
    assert!(e.to_string().contains("cam0/sensor.yaml: missing"), "{e}");
}

#[test]
fn bad_sensor_yaml_value_names_the_line() {
    let (_d, e) = broken(|mav| {
        let p = mav.join("imu0/sensor.yaml");
        let text = fs::read_to_string(&p)
            .unwrap()
            .replace("rate_hz: 200.0", "rate_hz: fast");
        fs::write(&p, text).unwrap();
    });
    let msg = e.to_string();
    assert!(
        msg.contains("imu0/sensor.yaml:") && msg.contains("'fast' is not a number"),
        "{msg}"
    );
}

#[test]
fn the_turn_on_biases_are_optional_and_checked() {
    // Absent (EuRoC, Kalibr, older uavnav folders): 0, "not known".
    let dir = tempfile::tempdir().unwrap();
    common::write_asl(dir.path(), 1);
    let p = dir.path().join("mav0/imu0/sensor.yaml");
    let text = fs::read_to_string(&p).unwrap();
    assert!(
        text.contains("gyroscope_turn_on_bias_sigma: 0.005"),
        "{text}"
    );
    let without: String = text
        .lines()
        .filter(|l| !l.contains("turn_on_bias"))
        .map(|l| format!("{l}\n"))
        .collect();
    fs::write(&p, without).unwrap();
    let imu = Dataset::open(dir.path()).unwrap().config().imu;
    assert_eq!(
        (imu.gyro_bias_sigma_radps, imu.accel_bias_sigma_mps2),
        (0.0, 0.0)
    );
    // Negative: refused, naming the file, the line and the key.
    let (_d, e) = broken(|mav| {
        let p = mav.join("imu0/sensor.yaml");
        let text = fs::read_to_string(&p).unwrap().replace(
            "accelerometer_turn_on_bias_sigma: 0.2",
            "accelerometer_turn_on_bias_sigma: -0.2",
        );
        fs::write(&p, text).unwrap();
    });
    let msg = e.to_string();
    assert!(
        msg.contains("imu0/sensor.yaml:")
            && msg.contains("`accelerometer_turn_on_bias_sigma` must be"),
        "{msg}"
    );
}

#[test]
fn not_a_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let e = Dataset::open(dir.path()).unwrap_err();
    assert!(e.to_string().contains("imu0"), "{e}");
}
