//! A gRPC watcher whose peer stops reading holds up only itself: what the service buffers for
//! its streams is bounded (hyper's per-stream send buffer, the byte-bounded response queue,
//! `transport::grpc_serve` and `transport::response_queue`), and neither the vehicle's ingest nor
//! another watcher waits for it. The memory this costs is measured by `cargo bench -p uavnavd
//! --bench memory -- --only 6`.

use std::time::Duration;

use crate::common::*;
use uavnav_proto::v1 as pb;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_watcher_that_stops_reading_holds_up_nobody() {
    let server = start(test_config()).await;
    let stalled = stalled_watch(server.grpc_addr, 4)
        .await
        .expect("the stalled watcher's connection");
    assert_eq!(stalled.streams(), 4, "the service answers every stream");
    let mut healthy = client(&server)
        .await
        .watch_poses(pb::WatchRequest {
            vehicle_ids: vec!["v".into()],
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    // 20,000 poses: some 4 MB on each stalled stream, more than the sockets and the service's
    // buffers take, so its forwarders block while this goes on.
    const MESSAGES: i64 = 2_000;
    const PER_MESSAGE: i64 = 10;
    let t0 = 1_000_000_000_000;
    let mut envs = vec![config_env("v", 0, false), gnss_env("v", 1, fix(t0))];
    for m in 0..MESSAGES {
        let samples = (0..PER_MESSAGE)
            .map(|k| imu(t0 + 1 + (m * PER_MESSAGE + k) * 5_000_000))
            .collect();
        envs.push(imu_env("v", 2 + m as u64, samples));
    }
    let mut c = client(&server).await;
    let sender = tokio::spawn(async move { ingest(&mut c, envs).await });
    let mut got = 0;
    while got < MESSAGES * PER_MESSAGE {
        match tokio::time::timeout(Duration::from_secs(30), healthy.message()).await {
            Ok(Ok(Some(_))) => got += 1,
            other => panic!("the healthy watcher stopped after {got} poses: {other:?}"),
        }
    }
    let acks = sender.await.unwrap().unwrap();
    let accepted = acks
        .iter()
        .filter(|a| a.status == pb::IngestStatus::Accepted as i32)
        .count();
    assert_eq!(accepted, acks.len(), "every envelope accepted");
    // Still open, still not read: the service did not have to drop it to go on.
    assert_eq!(stalled.streams(), 4);
    drop(stalled);
}
