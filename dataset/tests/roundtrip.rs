//! ASL ↔ MCAP conversions: byte-identical CSVs and images, the real EuRoC subset, fleets.

#![allow(clippy::unwrap_used)] // tests may unwrap

mod common;

use std::fs;
use std::path::Path;

use uavnav_core::SensorEvent;
use uavnav_dataset::convert::{asl_to_mcap, convert, mcap_to_asl};
use uavnav_dataset::mcap_io::reader::{McapEvents, vehicles};
use uavnav_dataset::{Dataset, Format, McapOptions, McapWriter};

const CSVS: [&str; 4] = [
    "imu0/data.csv",
    "gnss0/data.csv",
    "cam0/data.csv",
    "state_groundtruth_estimate0/data.csv",
];

fn files_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    names
}

#[test]
fn asl_to_mcap_to_asl_is_byte_identical() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, m, b) = (
        tmp.path().join("a"),
        tmp.path().join("flight.mcap"),
        tmp.path().join("b"),
    );
    let (events, truth) = common::write_asl(&a, 4);
    let s1 = asl_to_mcap(&a, &m, &McapOptions::default()).unwrap();
    let s2 = mcap_to_asl(&m, &b, None).unwrap();
    assert_eq!(s1, s2);
    assert_eq!(
        (s1.imu + s1.gnss + s1.mag + s1.baro + s1.frames, s1.truth),
        (events.len(), truth.len())
    );
    for csv in CSVS {
        let (x, y) = (
            fs::read(a.join("mav0").join(csv)).unwrap(),
            fs::read(b.join("mav0").join(csv)).unwrap(),
        );
        assert!(x == y, "{csv} differs after ASL → MCAP → ASL");
    }
    let (ia, ib) = (a.join("mav0/cam0/data"), b.join("mav0/cam0/data"));
    assert_eq!(files_in(&ia), files_in(&ib));
    for name in files_in(&ia) {
        assert_eq!(
            fs::read(ia.join(&name)).unwrap(),
            fs::read(ib.join(&name)).unwrap(),
            "{name}"
        );
    }
    let (da, db) = (Dataset::open(&a).unwrap(), Dataset::open(&b).unwrap());
    // sensor.yaml stores T_BS as a printed matrix: its rotation round-trips to ~1e-16, not bits.
    let (ca, cb) = (da.config(), db.config());
    assert_eq!(
        (ca.imu, ca.gnss, ca.terrain_elevation_m, ca.profile),
        (cb.imu, cb.gnss, cb.terrain_elevation_m, cb.profile)
    );
    let (ka, kb) = (ca.camera.as_ref().unwrap(), cb.camera.as_ref().unwrap());
    assert_eq!((ka.rate_hz, ka.model), (kb.rate_hz, kb.model));
    assert!(
        (ka.body_from_cam.to_homogeneous() - kb.body_from_cam.to_homogeneous())
            .abs()
            .max()
            < 1e-14
    );
    assert_eq!(da.origin(), db.origin());
    assert_eq!(db.vehicle_id(), "uav-test");
}

#[test]
fn mcap_reads_back_the_same_events_config_and_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, m) = (tmp.path().join("a"), tmp.path().join("x.MCAP"));
    let (events, truth) = common::write_asl(&a, 2);
    convert(&a, &m).unwrap();
    let ds = Dataset::open(&m).unwrap();
    assert_eq!(ds.format(), Format::Mcap);
    let got: Vec<SensorEvent> = ds.events().unwrap().map(Result::unwrap).collect();
    assert_eq!(got, events);
    assert_eq!(ds.truth().unwrap(), truth.as_slice());
    assert_eq!(ds.config(), Dataset::open(&a).unwrap().config());
    assert_eq!(ds.origin(), Some(common::origin()));
}

#[test]
fn recordings_are_deterministic() {
    let tmp = tempfile::tempdir().unwrap();
    let a = tmp.path().join("a");
    common::write_asl(&a, 1);
    let (m1, m2) = (tmp.path().join("1.mcap"), tmp.path().join("2.mcap"));
    convert(&a, &m1).unwrap();
    convert(&a, &m2).unwrap();
    assert_eq!(fs::read(m1).unwrap(), fs::read(m2).unwrap());
}

#[test]
fn euroc_to_mcap_and_back_keeps_values_and_images() {
    let Some(euroc) = common::euroc() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let (m, b) = (tmp.path().join("euroc.mcap"), tmp.path().join("b"));
    let s = convert(&euroc, &m).unwrap();
    assert_eq!((s.imu, s.frames), (29120, 95));
    convert(&m, &b).unwrap();
    let (src, back) = (Dataset::open(&euroc).unwrap(), Dataset::open(&b).unwrap());
    let x: Vec<_> = src.events().unwrap().map(Result::unwrap).collect();
    let y: Vec<_> = back.events().unwrap().map(Result::unwrap).collect();
    assert!(x == y, "events differ after EuRoC → MCAP → ASL");
    let name = "1403715273262142976.png";
    assert_eq!(
        fs::read(euroc.join("mav0/cam0/data").join(name)).unwrap(),
        fs::read(b.join("mav0/cam0/data").join(name)).unwrap()
    );
}

#[test]
fn fleet_recordings() {
    let tmp = tempfile::tempdir().unwrap();
    let m = tmp.path().join("fleet.mcap");
    let (events, _) = common::events(1, 3);
    let mut w = McapWriter::create(&m, &McapOptions::default()).unwrap();
    for (i, e) in events.iter().enumerate() {
        w.write_event("b", e, e.t_ns()).unwrap();
        if i % 2 == 0 {
            w.write_event("a", e, e.t_ns()).unwrap();
        }
    }
    w.finish().unwrap();
    assert_eq!(vehicles(&m).unwrap(), vec!["a".to_owned(), "b".to_owned()]);
    let e = Dataset::open(&m).unwrap_err().to_string();
    assert!(e.contains("several vehicles (a, b)"), "{e}");
    let opts = uavnav_dataset::ReadOptions {
        vehicle: Some("b".into()),
        ..Default::default()
    };
    let b: Vec<_> = Dataset::open_with(&m, &opts)
        .unwrap()
        .events()
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(b, events);
    let all: Vec<_> = McapEvents::open(&m, None)
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(all.len(), events.len() + events.len().div_ceil(2));
    assert!(
        all.windows(2)
            .all(|w| w[0].event.t_ns() <= w[1].event.t_ns())
    );
}

#[test]
fn negative_times_cannot_be_recorded() {
    let tmp = tempfile::tempdir().unwrap();
    let mut w = McapWriter::create(&tmp.path().join("n.mcap"), &McapOptions::default()).unwrap();
    let (events, _) = common::events(1, 1);
    let e = w.write_event("a", &events[0], -5).unwrap_err().to_string();
    assert!(e.contains("negative"), "{e}");
}

#[test]
fn corrupt_mcap_is_an_error_not_a_panic() {
    let tmp = tempfile::tempdir().unwrap();
    let a = tmp.path().join("a");
    common::write_asl(&a, 1);
    let m = tmp.path().join("c.mcap");
    convert(&a, &m).unwrap();
    let mut bytes = fs::read(&m).unwrap();
    bytes.truncate(bytes.len() / 2);
    fs::write(&m, bytes).unwrap();
    let e = Dataset::open(&m).unwrap_err().to_string();
    assert!(e.contains("c.mcap"), "{e}");
}

#[test]
fn a_pose_without_a_position_is_recorded_without_a_display_pose() {
    use uavnav_proto::v1;
    let tmp = tempfile::tempdir().unwrap();
    let m = tmp.path().join("poses.mcap");
    let frame = uavnav_core::LocalFrame::new(uavnav_core::Lla::from_deg(43.0, -3.0, 50.0));
    let level = Some(v1::Quaternion {
        w: 1.0,
        ..Default::default()
    });
    let placed = v1::PoseEstimate {
        vehicle_id: "a".into(),
        t_ns: 1_000,
        position: Some(v1::GeodeticPosition {
            latitude_deg: 43.0,
            longitude_deg: -3.0,
            altitude_m: 50.0,
        }),
        nav_from_body: level,
        ..Default::default()
    };
    // Attitude only (running without GNSS): no position, so no place in the display frame.
    let attitude_only = v1::PoseEstimate {
        t_ns: 2_000,
        position: None,
        ..placed.clone()
    };
    let mut w = McapWriter::create(&m, &McapOptions::default()).unwrap();
    w.write_pose("a", &placed, 1_000, Some(&frame)).unwrap();
    w.write_pose("a", &attitude_only, 2_000, Some(&frame))
        .unwrap();
    w.finish().unwrap();
    let bytes = fs::read(&m).unwrap();
    let mut topics = std::collections::BTreeMap::<String, usize>::new();
    for msg in mcap::MessageStream::new(&bytes).unwrap() {
        *topics
            .entry(msg.unwrap().channel.topic.clone())
            .or_default() += 1;
    }
    let count = |leaf: &str| {
        topics
            .iter()
            .filter(|(t, _)| t.ends_with(leaf))
            .map(|(_, n)| n)
            .sum::<usize>()
    };
    assert_eq!(count("/pose"), 2, "{topics:?}");
    assert_eq!(count("/pose/frame"), 1, "{topics:?}");
}
