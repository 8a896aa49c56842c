//! Graceful shutdown drains: everything accepted before the stop is fused and published, each
//! vehicle publishes a final health report, watch streams end, the ports close.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::Duration;

use crate::common::*;
use uavnav_proto::v1 as pb;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_drains_queued_data_and_publishes_final_health() {
    let mut cfg = test_config();
    // A long window and a slow health period: nothing would come out before the drain.
    cfg.vehicles.reorder_window_ms = 10_000.0;
    cfg.health.period_ms = 60_000;
    let server = start(cfg).await;
    let grpc_addr = server.grpc_addr;
    let mut c = client(&server).await;
    let mut poses = c
        .watch_poses(pb::WatchRequest {
            all: true,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let mut health = c
        .watch_health(pb::WatchRequest {
            all: true,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let n = 100;
    let mut envs = Vec::new();
    for v in 0..3 {
        for k in 0..n {
            envs.push(imu_env(
                &format!("d{v}"),
                k as u64,
                vec![imu(1_000 + k * 5_000_000)],
            ));
        }
    }
    let acks = ingest(&mut c, envs).await.unwrap();
    assert!(
        acks.iter()
            .all(|a| a.status == pb::IngestStatus::Accepted as i32)
    );
    let hub = server.registry().ctx().hub.clone();
    // Subscribe in-process too, so what is published during shutdown is seen even if the gRPC
    // watch ends first.
    let mut all_poses = hub.poses.subscribe();
    let mut all_health = hub.health.subscribe();
    // Let the initial health tick (at t=0 of each actor) pass.
    tokio::time::sleep(Duration::from_millis(100)).await;
    while all_health.try_recv().is_ok() {}
    server.shutdown().await.unwrap();
    let mut count = 0;
    while let Ok(b) = all_poses.try_recv() {
        assert!(b.vehicle_id.starts_with('d'));
        count += b.poses.len() as i64;
    }
    assert_eq!(count, 3 * n, "every accepted sample fused before exit");
    let mut finals = Vec::new();
    while let Ok(h) = all_health.try_recv() {
        finals.push(h.health.vehicle_id.clone());
    }
    finals.sort();
    assert_eq!(
        finals,
        ["d0", "d1", "d2"],
        "one final health report per vehicle"
    );
    // Watch streams end; the port is closed.
    let end = tokio::time::timeout(Duration::from_secs(5), async {
        while let Ok(Some(_)) = poses.message().await {}
        while let Ok(Some(_)) = health.message().await {}
    });
    end.await.expect("watch streams end at shutdown");
    assert!(
        tokio::net::TcpStream::connect(grpc_addr).await.is_err(),
        "gRPC port closed"
    );
}

#[tokio::test]
async fn idle_vehicles_are_evicted() {
    let mut cfg = test_config();
    cfg.vehicles.idle_evict_s = 0.2;
    let server = start(cfg).await;
    let mut c = client(&server).await;
    ingest(&mut c, vec![imu_env("idle", 1, vec![imu(1)])])
        .await
        .unwrap();
    assert!(server.registry().get("idle").is_some());
    let reg = server.registry().clone();
    assert!(
        eventually(Duration::from_secs(3), || reg.get("idle").is_none()).await,
        "evicted"
    );
    assert!(
        server
            .metrics()
            .encode()
            .contains("uavnav_evictions_total 1")
    );
    // Data after eviction starts a fresh actor.
    let acks = ingest(&mut c, vec![imu_env("idle", 2, vec![imu(1)])])
        .await
        .unwrap();
    assert_eq!(acks[0].status, pb::IngestStatus::Accepted as i32);
    server.shutdown().await.unwrap();
}
