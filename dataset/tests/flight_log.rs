//! Flight logs read as datasets: the shared ArduPilot logs open through `Dataset::open` (by
//! extension and by content), convert to ASL and MCAP with their autopilot estimate kept as a
//! reference (never truth), and give the same events as the shared ASL conversions (GNSS stamps
//! apart: the shared ASL is stamped T − 220 ms, a log's fixes stay as logged with the delay in the
//! configuration). Skips with a message when `../shared/data` is absent.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use uavnav_core::SensorEvent;
use uavnav_dataset::{Dataset, Format, ReadOptions};

#[derive(Debug, Default, PartialEq, Eq)]
struct Counts {
    imu: usize,
    gnss: usize,
    mag: usize,
    baro: usize,
    camera: usize,
}

fn events(ds: &Dataset) -> (Counts, Vec<SensorEvent>) {
    let mut c = Counts::default();
    let mut all = Vec::new();
    for e in ds.events().expect("events") {
        let e = e.expect("event");
        match &e {
            SensorEvent::Imu(_) => c.imu += 1,
            SensorEvent::Gnss(_) => c.gnss += 1,
            SensorEvent::Mag(_) => c.mag += 1,
            SensorEvent::Baro(_) => c.baro += 1,
            SensorEvent::Camera(_) => c.camera += 1,
        }
        all.push(e);
    }
    (c, all)
}

#[test]
fn ardupilot_log_is_a_dataset_with_a_reference_not_truth() {
    let Some(root) = uavnav_testdata::shared_data("real_flights") else {
        return;
    };
    let raw = root.join("raw/erle_copter_218.BIN");
    let ds = Dataset::open(&raw).expect("open .BIN");
    assert_eq!(ds.format(), Format::Log);
    assert_eq!(ds.vehicle_id(), "erle_copter_218");
    assert!(ds.truth().is_none(), "an autopilot estimate is not truth");
    let r = ds.reference().expect("EKF1 reference");
    assert_eq!(r.label(), "reference (autopilot estimate, EKF1)");
    assert_eq!(r.samples.len(), 3022);
    assert!(ds.origin().is_some());
    let gnss = ds.config().gnss.expect("GNSS config");
    assert_eq!(gnss.delay_ns, 220_000_000, "EKF_POS_DELAY");
    let (counts, log_events) = events(&ds);
    assert_eq!(
        counts,
        Counts {
            imu: 16750,
            gnss: 1692,
            mag: 3350,
            baro: 3350,
            camera: 0
        }
    );

    // The shared ASL conversion: same events once its GNSS stamps are put back at T (+220 ms).
    let shared = Dataset::open(root.join("erle_copter_218")).expect("shared ASL");
    assert!(
        shared.truth().is_none(),
        "the shared ASL says NOT ground truth"
    );
    assert_eq!(shared.reference().map(|r| r.samples.len()), Some(3022));
    let (shared_counts, _) = events(&shared);
    assert_eq!(shared_counts, counts);

    // --gnss-delay-s override
    let opts = ReadOptions {
        gnss_delay_s: Some(0.1),
        ..ReadOptions::default()
    };
    let ds2 = Dataset::open_with(&raw, &opts).expect("open with delay");
    assert_eq!(ds2.config().gnss.map(|g| g.delay_ns), Some(100_000_000));
    let bad = ReadOptions {
        gnss_delay_s: Some(-1.0),
        ..ReadOptions::default()
    };
    assert!(Dataset::open_with(&raw, &bad).is_err());

    // Recognised by content under another name.
    let dir = tempfile::tempdir().expect("tempdir");
    let renamed = dir.path().join("00000042");
    std::fs::copy(&raw, &renamed).expect("copy");
    let by_content = Dataset::open(&renamed).expect("sniffed");
    assert_eq!(by_content.format(), Format::Log);
    assert_eq!(events(&by_content).1, log_events);

    // ASL and MCAP conversions keep the reference apart from truth and the events unchanged.
    let asl = dir.path().join("asl");
    let s = uavnav_dataset::convert::convert(&raw, &asl).expect("to ASL");
    assert_eq!(
        (s.imu, s.gnss, s.truth, s.reference),
        (16750, 1692, 0, 3022)
    );
    let back = Dataset::open(&asl).expect("ASL back");
    assert!(back.truth().is_none());
    assert_eq!(back.reference().map(|r| r.label()), Some(r.label()));
    assert_eq!(back.config().gnss.map(|g| g.delay_ns), Some(220_000_000));
    assert_eq!(events(&back).0, counts);
    let mcap = dir.path().join("x.mcap");
    let s = uavnav_dataset::convert::convert(&raw, &mcap).expect("to MCAP");
    assert_eq!((s.imu, s.reference), (16750, 3022));
    let back = Dataset::open(&mcap).expect("MCAP back");
    assert!(back.truth().is_none());
    assert_eq!(back.reference(), ds.reference());
    assert_eq!(events(&back).1, log_events);
}

#[test]
fn a_cut_log_imports_with_a_note_naming_the_byte_offset() {
    let Some(root) = uavnav_testdata::shared_data("real_flights") else {
        return;
    };
    // plane_E's logger stopped inside its last message: read up to it, with a note (corruption
    // inside a log is refused: `uavnav-logs` and the CLI's tests)
    let raw = root.join("raw/erle_plane_E.BIN");
    for options in [
        ReadOptions::default(),
        ReadOptions {
            stop_at_damage: true,
            ..ReadOptions::default()
        },
    ] {
        let ds = Dataset::open_with(&raw, &options).expect("cut log");
        assert!(
            ds.notes()
                .iter()
                .any(|n| n.contains("at byte 1794025") && n.contains("ends inside a message")),
            "{:?}",
            ds.notes()
        );
        assert_eq!(events(&ds).0.imu, 7675);
    }
    let not_a_log = tempfile::NamedTempFile::new().expect("tmp");
    std::fs::write(not_a_log.path(), b"hello").expect("write");
    let err = Dataset::open(not_a_log.path()).expect_err("not a log");
    assert!(err.to_string().contains("nor a flight log"), "{err}");
}
