//! Recording: a simulated flight streamed into a service with `[record]` on is in the MCAP file
//! afterwards, inputs in order, and replaying those inputs gives exactly the recorded poses; files
//! rotate by size (the oldest deleted) and by time; a tiny queue budget drops (counted), never
//! blocks; a full disk loses the recording, counted, and nothing else.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use crate::common;

use std::path::Path;
use std::time::Duration;

use crate::common::test_config;
use uavnav_core::SensorEvent;
use uavnav_dataset::mcap_io::reader::McapDataset;
use uavnav_proto::v1 as pb;
use uavnav_tests::recording::{self, recordings};
use uavnavd::metrics::{RecordDrop, RecordDropLabels};
use uavnavd::{Config, RunningServer, Server};

fn offline(config: &uavnav_core::VehicleConfig, events: &[SensorEvent]) -> Vec<pb::PoseEstimate> {
    common::offline_poses(config, events)
        .into_iter()
        .map(strip)
        .collect()
}

fn strip(mut p: pb::PoseEstimate) -> pb::PoseEstimate {
    p.vehicle_id.clear();
    p.ingest_wall_ns = 0;
    p
}

fn record_config(dir: &Path) -> Config {
    let mut cfg = test_config();
    cfg.record.directory = Some(dir.to_owned());
    cfg
}

/// Streams the flight into `server` as vehicle `id` and waits for `n_poses` poses.
async fn stream_flight(
    server: &RunningServer,
    id: &str,
    config: &uavnav_core::VehicleConfig,
    events: &[SensorEvent],
    n_poses: usize,
) -> Vec<pb::PoseEstimate> {
    let mut rx = server.registry().ctx().hub.poses.subscribe();
    let mut c = common::client(server).await;
    c.configure_vehicle(pb::ConfigureVehicleRequest {
        vehicle_id: id.into(),
        config: Some(config.into()),
    })
    .await
    .unwrap();
    let envs: Vec<_> = events
        .iter()
        .enumerate()
        .map(|(i, e)| common::event_env(id, i as u64, e))
        .collect();
    let n = envs.len();
    let mut acks = c
        .ingest(futures::stream::iter(envs))
        .await
        .unwrap()
        .into_inner();
    let mut accepted = 0;
    while let Some(a) = acks.message().await.unwrap() {
        assert_eq!(a.status, pb::IngestStatus::Accepted as i32, "{a:?}");
        accepted += 1;
        if accepted == n {
            break;
        }
    }
    let mut got = Vec::with_capacity(n_poses);
    let all = async {
        while got.len() < n_poses {
            got.extend(rx.recv().await.unwrap().to_wire().into_iter().map(strip));
        }
    };
    tokio::time::timeout(Duration::from_secs(60), all)
        .await
        .expect("all poses within 60 s");
    got
}

/// The poses recorded for `id`, in file order, without what differs between runs.
fn recorded_poses(path: &Path, id: &str) -> Vec<pb::PoseEstimate> {
    recording::recorded_poses(path, id)
        .into_iter()
        .map(strip)
        .collect()
}

fn dropped(server: &RunningServer, reason: RecordDrop) -> u64 {
    server
        .metrics()
        .record_dropped
        .get_or_create(&RecordDropLabels { reason })
        .get()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn recorded_flight_replays_to_the_recorded_poses() {
    let dir = tempfile::tempdir().unwrap();
    let (config, events) = common::sim_flight("smoke", 3.0);
    let want = offline(&config, &events);
    assert!(want.len() > 300, "{} offline poses", want.len());

    let server = Server::start(record_config(dir.path())).await.unwrap();
    let live = stream_flight(&server, "rec", &config, &events, want.len()).await;
    assert_eq!(dropped(&server, RecordDrop::QueueFull), 0);
    assert_eq!(dropped(&server, RecordDrop::WriteError), 0);
    let metrics = server.metrics().clone();
    server.shutdown().await.unwrap();
    assert!(metrics.record_bytes.get() > 0);
    assert_eq!(metrics.record_files.get(), 1);

    let files = recordings(dir.path());
    assert_eq!(files.len(), 1, "{files:?}");
    let ds = McapDataset::open(&files[0], Some("rec")).unwrap();
    assert!(ds.has_config());
    assert_eq!(ds.config(), &config);
    let read: Vec<SensorEvent> = ds.events().unwrap().map(|e| e.unwrap().event).collect();
    assert_eq!(read.len(), events.len());
    assert!(
        read == events,
        "the recorded inputs differ from the sent ones"
    );

    let recorded = recorded_poses(&files[0], "rec");
    assert_eq!(recorded.len(), live.len());
    assert!(
        recorded == live,
        "the recorded poses differ from the published ones"
    );
    let replayed = offline(ds.config(), &read);
    assert_eq!(replayed.len(), recorded.len());
    for (i, (r, p)) in replayed.iter().zip(&recorded).enumerate() {
        assert_eq!(r, p, "pose {i}: replay differs from the recording");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rotation_by_size_and_retention() {
    let dir = tempfile::tempdir().unwrap();
    let (config, events) = common::sim_flight("smoke", 3.0);
    let want = offline(&config, &events);
    let mut cfg = record_config(dir.path());
    cfg.record.rotate_bytes = 20_000;
    cfg.record.retain_bytes = 60_000;
    // A stale recording from an earlier run: the index continues after it and retention
    // deletes it first.
    std::fs::write(dir.path().join("uavnavd-000007.mcap"), [0u8; 100]).unwrap();
    let server = Server::start(cfg).await.unwrap();
    stream_flight(&server, "rot", &config, &events, want.len()).await;
    let metrics = server.metrics().clone();
    server.shutdown().await.unwrap();

    let closed = metrics.record_files.get();
    assert!(closed >= 5, "{closed} files closed");
    let files = recordings(dir.path());
    assert!(files.len() >= 2, "{files:?}");
    assert!((files.len() as u64) < closed, "nothing deleted: {files:?}");
    let names: Vec<_> = files
        .iter()
        .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert!(!names.contains(&"uavnavd-000007.mcap".to_owned()));
    assert!(!names.contains(&"uavnavd-000008.mcap".to_owned()));
    let total: u64 = files
        .iter()
        .map(|f| std::fs::metadata(f).unwrap().len())
        .sum();
    assert!(total <= 60_000, "{total} bytes kept");
    // Every kept file was finished: its poses read back.
    for f in &files {
        assert!(!recorded_poses(f, "rot").is_empty(), "{}", f.display());
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_queue_drops_and_counts_instead_of_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let (config, events) = common::sim_flight("smoke", 1.0);
    let want = offline(&config, &events);
    let mut cfg = record_config(dir.path());
    cfg.record.queue_bytes = 8;
    let server = Server::start(cfg).await.unwrap();
    let got = stream_flight(&server, "tiny", &config, &events, want.len()).await;
    assert_eq!(got, want);
    // Inputs are dropped before their acks; poses as the recorder's feed task reads them, which
    // may trail the test's own subscription.
    let every = (events.len() + 1 + want.len()) as u64;
    let all_counted = common::eventually(Duration::from_secs(10), || {
        dropped(&server, RecordDrop::QueueFull) >= every
    })
    .await;
    let full = dropped(&server, RecordDrop::QueueFull);
    assert!(all_counted, "{full} of {every} dropped");
    assert_eq!(server.metrics().record_written.get(), 0);
    let text = server.metrics().encode();
    assert!(
        text.contains("uavnav_record_dropped_total{reason=\"queue_full\"}"),
        "{text}"
    );
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rotation_by_time_closes_an_idle_file() {
    let dir = tempfile::tempdir().unwrap();
    let (config, events) = common::sim_flight("smoke", 1.0);
    let want = offline(&config, &events);
    let mut cfg = record_config(dir.path());
    cfg.record.rotate_s = 0.3;
    let server = Server::start(cfg).await.unwrap();
    stream_flight(&server, "first", &config, &events, want.len()).await;
    let metrics = server.metrics().clone();
    // Nothing more arrives: the file is closed on time, not at the next message or shutdown.
    assert!(
        common::eventually(Duration::from_secs(5), || metrics.record_files.get() >= 1).await,
        "no file closed by time"
    );
    stream_flight(&server, "second", &config, &events, want.len()).await;
    server.shutdown().await.unwrap();
    let files = recordings(dir.path());
    assert!(files.len() >= 2, "{files:?}");
    // The first vehicle's poses are in the first file, the second's in a later one.
    assert_eq!(recorded_poses(&files[0], "first").len(), want.len());
    let last = files.last().unwrap();
    assert_eq!(recorded_poses(last, "second").len(), want.len());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_sheds_and_counts_and_estimation_goes_on() {
    let full = Path::new("/dev/full");
    if !full.exists() {
        eprintln!("skipping: no /dev/full on this system (a device whose writes fail with ENOSPC)");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (config, events) = common::sim_flight("smoke", 2.0);
    let want = offline(&config, &events);
    let server = Server::start(record_config(dir.path())).await.unwrap();
    // Every file the recorder will open is the full device: each write fails with ENOSPC.
    for i in 0..50 {
        std::os::unix::fs::symlink(full, uavnavd::record::file_path(dir.path(), i)).unwrap();
    }
    let got = stream_flight(&server, "full", &config, &events, want.len()).await;
    assert_eq!(got, want, "the poses changed with a full disk");
    let metrics = server.metrics().clone();
    server.shutdown().await.unwrap();
    // Everything handed to the recorder was lost, and all of it is counted.
    let lost = metrics
        .record_dropped
        .get_or_create(&RecordDropLabels {
            reason: RecordDrop::WriteError,
        })
        .get();
    let written = metrics.record_written.get();
    assert!(lost > 0, "nothing counted as write_error");
    assert!(
        lost >= written,
        "{lost} counted lost of {written} handed to files"
    );
    assert_eq!(
        metrics.record_files.get(),
        0,
        "a file on a full disk was finished"
    );
}
