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

/// Peers that open streams and never read them take at most `grpc.max_streams` slots, however
/// many connections they open: the next call is answered at once with RESOURCE_EXHAUSTED naming
/// the setting and counted in `/metrics`, the service stays up for everyone else (the HTTP
/// probes), and calls are served again once the streams close.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn open_streams_are_bounded_across_connections_and_refusals_counted() {
    let mut c = test_config();
    c.grpc.max_streams = 6;
    let server = start(c).await;
    let streams = server.metrics().streams.clone();
    // Two connections of four streams each: the limit is fleet-wide, not per connection.
    let a = stalled_watch(server.grpc_addr, 4).await.expect("first");
    let b = stalled_watch(server.grpc_addr, 4).await.expect("second");
    assert_eq!(streams.open.get(), 6, "six slots taken");
    let mut refused_so_far = streams.refused.get();
    assert_eq!(
        refused_so_far, 2,
        "two streams of the second connection refused"
    );
    // A well-behaved client is refused too, at once and with the reason.
    let status = client(&server)
        .await
        .list_vehicles(pb::ListVehiclesRequest::default())
        .await
        .expect_err("no slot");
    assert_eq!(status.code(), tonic::Code::ResourceExhausted, "{status:?}");
    assert!(status.message().contains("grpc.max_streams"), "{status:?}");
    refused_so_far += 1;
    assert_eq!(streams.refused.get(), refused_so_far);
    let text = server.metrics().encode();
    assert!(
        text.contains("uavnav_grpc_streams_refused_total 3"),
        "{text}"
    );
    assert!(text.contains("uavnav_grpc_streams_open 6"), "{text}");
    served_again_once_they_leave(&server, vec![a, b]).await;
    assert_eq!(streams.refused.get(), refused_so_far);
    server.shutdown().await.unwrap();
}

/// The stalled peers go away: their slots come back, and a call is served again.
async fn served_again_once_they_leave(server: &uavnavd::RunningServer, peers: Vec<StalledWatch>) {
    let streams = server.metrics().streams.clone();
    drop(peers);
    assert!(
        eventually(Duration::from_secs(10), || streams.open.get() == 0).await,
        "open streams after the peers left: {}",
        streams.open.get()
    );
    client(server)
        .await
        .list_vehicles(pb::ListVehiclesRequest::default())
        .await
        .expect("served again once the streams closed");
}

/// One host that opens streams and never reads them takes at most its address's share,
/// `grpc.max_streams_per_peer`, whatever the number of its connections: its further calls are
/// refused with that key's name and counted, while a client from another address is still
/// served from the slots the share leaves. (Both ends on loopback: the other client binds
/// 127.0.0.2, which Linux routes to the same host.)
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_peer_address_cannot_take_every_stream_slot() {
    let mut c = test_config();
    c.grpc.max_streams = 6;
    c.grpc.max_streams_per_peer = 4;
    let server = start(c).await;
    let streams = server.metrics().streams.clone();
    let a = stalled_watch(server.grpc_addr, 4).await.expect("first");
    let b = stalled_watch(server.grpc_addr, 4).await.expect("second");
    assert_eq!(streams.open.get(), 4, "the greedy address holds its share");
    assert_eq!(
        streams.peer_refused.get(),
        4,
        "its second connection refused"
    );
    assert_eq!(streams.refused.get(), 0, "the service itself is not full");
    // The same address again: refused at once, naming the key.
    let status = client(&server)
        .await
        .list_vehicles(pb::ListVehiclesRequest::default())
        .await
        .expect_err("beyond the address's share");
    assert_eq!(status.code(), tonic::Code::ResourceExhausted, "{status:?}");
    assert!(
        status.message().contains("grpc.max_streams_per_peer"),
        "{status:?}"
    );
    // Another address is served.
    let channel = tonic::transport::Endpoint::from_shared(format!("http://{}", server.grpc_addr))
        .unwrap()
        .local_address(Some([127, 0, 0, 2].into()))
        .connect()
        .await
        .expect("a connection from 127.0.0.2");
    uavnav_proto::v1::uav_nav_client::UavNavClient::new(channel)
        .list_vehicles(pb::ListVehiclesRequest::default())
        .await
        .expect("another address is served");
    let text = server.metrics().encode();
    assert!(
        text.contains("uavnav_grpc_streams_peer_refused_total 5"),
        "{text}"
    );
    served_again_once_they_leave(&server, vec![a, b]).await;
    server.shutdown().await.unwrap();
}
