//! The recording reader: files written in the recorders' layout (the test kit's recording
//! builder, through the writer every uavnav recorder uses) and by the service's own recorder read
//! back as the wire messages sent, in
//! log-time order, per vehicle; broken and disordered files are errors that say where.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::Duration;

use crate::common::*;
use uavnav_client::pb::sensor_envelope::Payload;
use uavnav_client::recording::{self, RecordedMessage, RecordingError, RecordingReader};
use uavnav_client::{Client, pb};
use uavnav_dataset::mcap_io::Stream;
use uavnav_tests::recording::{RecordingBuilder, record_flight, recordings, write_recording};

fn imu(t_ns: i64) -> pb::ImuBatch {
    pb::ImuBatch {
        samples: vec![pb::ImuSample {
            t_ns,
            gyro_x_radps: 0.01,
            accel_z_mps2: -9.8,
            ..Default::default()
        }],
    }
}

fn gnss(t_ns: i64) -> pb::GnssFix {
    pb::GnssFix {
        t_ns,
        latitude_deg: 41.0,
        longitude_deg: 14.0,
        altitude_m: 100.0,
        num_satellites: 9,
        ..Default::default()
    }
}

fn camera(t_ns: i64, camera_id: u32) -> pb::CameraFrame {
    let mut frame = pb::CameraFrame {
        t_ns,
        camera_id,
        image: Some(Default::default()),
    };
    if let Some(image) = frame.image.as_mut() {
        image.timestamp = uavnav_proto::foxglove_conv::timestamp(t_ns);
        image.frame_id = uavnav_proto::foxglove_conv::camera_frame_id(camera_id);
        image.format = "jpeg".into();
        image.data = vec![0xff, 0xd8, 0xff, 0xe0, 1, 2, 3].into();
    }
    frame
}

fn read_all(reader: RecordingReader) -> Vec<RecordedMessage> {
    reader.map(|m| m.unwrap()).collect()
}

#[test]
fn reads_every_input_in_log_time_order_and_skips_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fleet.mcap");
    let config = pb::VehicleConfig::default();
    let mag = pb::MagSample {
        t_ns: 30,
        field_x_t: 2e-5,
        ..Default::default()
    };
    let baro = pb::BaroSample {
        t_ns: 40,
        pressure_pa: 1e5,
        temperature_degc: None,
    };
    // Log times out of order by a few messages (two recorder threads), equal ones kept in file
    // order; outputs and truth in between. Publish times are the recorders': the sensor time, the
    // arrival for a configuration.
    let records = [
        ("a", Payload::Config(config), 1_000, 1_000),
        ("a", Payload::Imu(imu(10)), 10, 1_010),
        ("b", Payload::Imu(imu(10)), 10, 1_005),
        ("a", Payload::Gnss(gnss(20)), 20, 1_020),
        ("b", Payload::Mag(mag), 30, 1_020),
        ("a", Payload::Baro(baro), 40, 1_040),
        ("a", Payload::Camera(camera(50, 1)), 50, 1_030),
    ];
    let mut w = RecordingBuilder::create(&path);
    for (i, (v, p, _, log)) in records.iter().enumerate() {
        w.input(v, p, *log);
        if i == 2 {
            let pose = pb::PoseEstimate {
                vehicle_id: "a".into(),
                t_ns: 10,
                ..Default::default()
            };
            w.writer().write_pose("a", &pose, 1_011, None).unwrap();
            let truth = pb::TruthSample {
                t_ns: 10,
                ..Default::default()
            };
            w.writer()
                .write_message("a", Stream::Truth, &truth, 10, 1_011)
                .unwrap();
        }
    }
    w.finish();

    assert_eq!(recording::vehicles(&path).unwrap(), ["a", "b"]);
    let got = read_all(RecordingReader::open(&path).unwrap());
    let order: Vec<(&str, u64)> = got
        .iter()
        .map(|m| (&*m.vehicle_id, m.log_time_ns))
        .collect();
    assert_eq!(
        order,
        [
            ("a", 1_000),
            ("b", 1_005),
            ("a", 1_010),
            ("a", 1_020),
            ("b", 1_020),
            ("a", 1_030),
            ("a", 1_040)
        ]
    );
    // Every payload comes back as sent, the camera frame rebuilt from its image.
    for m in &got {
        let (_, sent, publish, _) = records
            .iter()
            .find(|(v, _, _, log)| *v == &*m.vehicle_id && *log as u64 == m.log_time_ns)
            .unwrap();
        assert_eq!(&m.payload, sent);
        assert_eq!(m.publish_time_ns, *publish as u64);
    }
    let a = read_all(RecordingReader::open(&path).unwrap().vehicle("a"));
    assert_eq!(a.len(), 5);
    assert!(a.iter().all(|m| &*m.vehicle_id == "a"));
}

#[test]
fn disorder_beyond_the_window_and_broken_files_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("late.mcap");
    let records: Vec<_> = [10, 20, 5]
        .into_iter()
        .map(|log| ("v", Payload::Imu(imu(log)), log))
        .collect();
    write_recording(&path, &records);
    // The default window restores the order; a window of one message cannot.
    assert_eq!(read_all(RecordingReader::open(&path).unwrap()).len(), 3);
    let mut r = RecordingReader::open(&path).unwrap().window(1);
    assert_eq!(r.next().unwrap().unwrap().log_time_ns, 10);
    let e = r.next().unwrap().unwrap_err();
    assert!(
        matches!(
            e,
            RecordingError::OutOfOrder {
                log_time_ns: 5,
                previous_ns: 10,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("late.mcap"), "{e}");
    assert!(r.next().is_none());

    let missing = dir.path().join("missing.mcap");
    let e = RecordingReader::open(&missing).unwrap_err();
    assert!(matches!(e, RecordingError::Io { .. }), "{e}");
    assert!(e.to_string().contains("missing.mcap"), "{e}");

    let garbage = dir.path().join("garbage.mcap");
    std::fs::write(&garbage, b"this is not an MCAP file at all").unwrap();
    let mut r = RecordingReader::open(&garbage).unwrap();
    let e = r.next().unwrap().unwrap_err();
    assert!(matches!(e, RecordingError::Mcap { .. }), "{e}");
    assert!(r.next().is_none());

    // A message whose bytes are not its schema: the messages before it, then the error naming it.
    let bad = dir.path().join("bad.mcap");
    let mut w = RecordingBuilder::create(&bad);
    w.input("v", &Payload::Imu(imu(1)), 1);
    let not_a_fix = pb::ImuBatch {
        samples: vec![pb::ImuSample::default(); 3],
    };
    w.writer()
        .write_message("v", Stream::Camera, &not_a_fix, 2, 2)
        .unwrap();
    w.finish();
    let got: Vec<_> = RecordingReader::open(&bad).unwrap().collect();
    assert_eq!(got.len(), 2, "{got:?}");
    assert_eq!(got[0].as_ref().unwrap().log_time_ns, 1);
    let e = got[1].as_ref().unwrap_err();
    assert!(e.to_string().contains("/uavnav/v/camera"), "{e}");
}

/// A simulated flight recorded as the recorders write it reads back as the messages sent, in
/// order, with the recorders' times (publish = sensor time, the arrival for the configuration).
#[test]
fn reads_a_recorded_flight_back_as_sent() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flight.mcap");
    let sent = record_flight(&path, "sim-1", 2.0);
    assert!(sent.len() > 100, "{} messages", sent.len());
    let got = read_all(RecordingReader::open(&path).unwrap());
    let payloads: Vec<Payload> = got.iter().map(|m| m.payload.clone()).collect();
    assert!(payloads == sent, "the recording differs from what was sent");
    assert!(got.iter().all(|m| &*m.vehicle_id == "sim-1"));
    // The configuration leads, logged at the first sensor time; IMU batches are published at
    // their last sample.
    assert_eq!(got[0].publish_time_ns, got[0].log_time_ns);
    assert_eq!(got[0].log_time_ns, got[1].log_time_ns);
    for m in &got {
        if let Payload::Imu(b) = &m.payload {
            assert_eq!(m.publish_time_ns, b.samples.last().unwrap().t_ns as u64);
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reads_back_what_the_service_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = loopback_config();
    c.record.directory = Some(dir.path().to_owned());
    let server = uavnavd::Server::start(c).await.unwrap();
    let client = Client::connect_url(&format!("grpc://{}", server.grpc_addr))
        .await
        .unwrap();
    let (_, msgs) = flight(2.0);
    feed(&client, "rec-a", &msgs).await;
    feed(&client, "rec-b", &msgs[..msgs.len() / 2]).await;
    client.close().await;
    tokio::time::sleep(Duration::from_millis(200)).await;
    server.shutdown().await.unwrap();

    let files = recordings(dir.path());
    assert_eq!(files.len(), 1, "{files:?}");
    assert_eq!(recording::vehicles(&files[0]).unwrap(), ["rec-a", "rec-b"]);
    let got = read_all(RecordingReader::open(&files[0]).unwrap());
    let of = |id: &str| -> Vec<Payload> {
        got.iter()
            .filter(|m| &*m.vehicle_id == id)
            .map(|m| m.payload.clone())
            .collect()
    };
    assert!(
        of("rec-a") == msgs,
        "rec-a: the recording differs from what was sent"
    );
    assert!(
        of("rec-b") == msgs[..msgs.len() / 2],
        "rec-b: the recording differs from what was sent"
    );
    assert!(got.windows(2).all(|w| w[0].log_time_ns <= w[1].log_time_ns));
}
