//! `uavnav record` then `uavnav replay`: a recording reproduces the poses.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::path::Path;
use std::time::Duration;

use crate::common::*;
use uavnav_client::{Client, Selector, pb};

/// A pose as (t_ns, lat, lon, alt).
fn lla(p: &pb::PoseEstimate) -> (i64, f64, f64, f64) {
    let g = p.position.unwrap();
    (p.t_ns, g.latitude_deg, g.longitude_deg, g.altitude_m)
}

/// The poses of `vehicle` in an MCAP recording, by time.
fn recorded_poses(path: &Path, vehicle: &str) -> Vec<(i64, f64, f64, f64)> {
    let mut out: Vec<_> = uavnav_tests::recording::recorded_poses(path, vehicle)
        .iter()
        .map(lla)
        .collect();
    out.sort_by_key(|p| p.0);
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn record_then_replay_reproduces_the_poses() {
    let dir = tempfile::tempdir().unwrap();
    let ds = simulate(dir.path(), "flight.mcap", 4.0);
    let rec = dir.path().join("fleet.mcap");

    // Service A: record everything on its Zenoh bus while a flight is replayed into it over Zenoh.
    let a = start().await;
    let recorder = tokio::spawn(run_async(vec![
        "record".into(),
        "--from".into(),
        a.zenoh.clone(),
        "--out".into(),
        rec.display().to_string(),
        "--idle-exit".into(),
        "2".into(),
        "--duration".into(),
        "30".into(),
    ]));
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let out = run_async(vec![
        "replay".into(),
        ds.display().to_string(),
        "--to".into(),
        a.zenoh.clone(),
        "--speed".into(),
        "4".into(),
        "--vehicles".into(),
        "2".into(),
        "--id-prefix".into(),
        "rec-".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(0));
    let out = recorder.await.unwrap();
    assert_eq!(out.status.code(), Some(0));
    a.server.shutdown().await.unwrap();
    let poses_a = recorded_poses(&rec, "rec-1");
    assert!(poses_a.len() > 300, "{} poses recorded", poses_a.len());

    // Service B: replay the recording over gRPC, watch the poses.
    let b = start().await;
    let client = Client::connect_url(&b.grpc).await.unwrap();
    let mut w = client.watch_poses(Selector::ids(["rec-1"])).await.unwrap();
    let out = run_async(vec![
        "replay".into(),
        rec.display().to_string(),
        "--to".into(),
        b.grpc.clone(),
        "--max".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(0));
    let got = collect(&mut w, poses_a.len(), Duration::from_secs(20)).await;
    let mut poses_b: Vec<(i64, f64, f64, f64)> = got.iter().map(lla).collect();
    poses_b.sort_by_key(|p| p.0);
    assert_eq!(poses_b.len(), poses_a.len());
    for (x, y) in poses_a.iter().zip(&poses_b) {
        assert_eq!(x.0, y.0);
        assert!(
            (x.1 - y.1).abs() < 1e-12 && (x.2 - y.2).abs() < 1e-12 && (x.3 - y.3).abs() < 1e-6,
            "{x:?} vs {y:?}"
        );
    }
    b.server.shutdown().await.unwrap();
}

/// The service's own recorder (`[record]`): its file, replayed with `uavnav replay` through a
/// fresh service, gives the poses the first service recorded (an operator replaying an incident).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_services_recording_replays_through_a_fresh_service() {
    let dir = tempfile::tempdir().unwrap();
    let ds = simulate(dir.path(), "flight.mcap", 4.0);
    let rec_dir = dir.path().join("recorded");
    let mut cfg = uavnav_tests::service::loopback_config();
    cfg.record.directory = Some(rec_dir.clone());
    let a = uavnavd::Server::start(cfg).await.unwrap();
    let out = run_async(vec![
        "replay".into(),
        ds.display().to_string(),
        "--to".into(),
        format!("grpc://{}", a.grpc_addr),
        "--max".into(),
        "--id-prefix".into(),
        "inc-".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    // Shutdown drains the vehicles and finishes the recording with their last poses.
    a.shutdown().await.unwrap();
    let files = uavnav_tests::recording::recordings(&rec_dir);
    assert_eq!(files.len(), 1, "{files:?}");
    let poses_a = recorded_poses(&files[0], "inc-0");
    assert!(poses_a.len() > 300, "{} poses recorded", poses_a.len());

    let b = start().await;
    let client = Client::connect_url(&b.grpc).await.unwrap();
    let mut w = client.watch_poses(Selector::ids(["inc-0"])).await.unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    let out = run_async(vec![
        "replay".into(),
        files[0].display().to_string(),
        "--to".into(),
        b.grpc.clone(),
        "--max".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    let got = collect(&mut w, poses_a.len(), Duration::from_secs(20)).await;
    let mut poses_b: Vec<(i64, f64, f64, f64)> = got.iter().map(lla).collect();
    poses_b.sort_by_key(|p| p.0);
    assert_eq!(poses_b.len(), poses_a.len());
    // The same inputs in the same order: the same estimates, to the bit.
    assert_eq!(poses_a, poses_b);
    b.server.shutdown().await.unwrap();
}
