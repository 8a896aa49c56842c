//! Shared by the client library's end-to-end tests: an in-process `uavnavd` (gRPC and HTTP on
//! port 0, Zenoh listening on an explicit localhost port with multicast scouting off) and
//! simulated flights as wire messages, from the test kit; feeding and watching through the client.
#![allow(dead_code)] // each test file uses a different part

use std::time::Duration;

use uavnav_client::pb::sensor_envelope::Payload;
use uavnav_client::{Client, pb};

#[allow(unused_imports)] // each test file uses a different part
pub use uavnav_tests::flight::wire_flight as flight;
#[allow(unused_imports)]
pub use uavnav_tests::net::free_port;
#[allow(unused_imports)]
pub use uavnav_tests::service::{Svc, loopback_config, smoke_text, start};

/// Feeds messages for `id` as fast as the service accepts.
pub async fn feed(client: &Client, id: &str, msgs: &[Payload]) {
    let ingest = client.ingest().await.unwrap();
    for m in msgs {
        ingest.send(id, m.clone()).await.unwrap();
    }
    let stats = ingest.finish(Duration::from_secs(10)).await;
    let sent = stats.sent.load(std::sync::atomic::Ordering::Relaxed);
    assert_eq!(sent, msgs.len() as u64);
}

/// Collects poses from a watch until `n` arrived or `timeout`.
pub async fn collect(
    w: &mut uavnav_client::Watch<pb::PoseEstimate>,
    n: usize,
    timeout: Duration,
) -> Vec<pb::PoseEstimate> {
    let mut out = Vec::new();
    let _ = tokio::time::timeout(timeout, async {
        while out.len() < n {
            match w.next().await {
                Some(Ok(p)) => out.push(p),
                _ => break,
            }
        }
    })
    .await;
    out
}
