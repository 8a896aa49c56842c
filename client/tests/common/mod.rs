//! Shared by the client library's end-to-end tests: an in-process `uavnavd` (gRPC and HTTP on
//! port 0, Zenoh listening on an explicit localhost port with multicast scouting off) and
//! simulated flights as wire messages.
#![allow(dead_code)] // each test file uses a different part

use std::time::Duration;

use uavnav_client::pb::sensor_envelope::Payload;
use uavnav_client::{Client, pb};

#[allow(unused_imports)] // each test file uses a different part
pub use uavnav_tests::net::free_port;
#[allow(unused_imports)]
pub use uavnav_tests::service::{Svc, smoke_text, start};

/// A short smoke flight without camera: its wire configuration and its messages (the
/// configuration first, then the sensors in time order, IMU samples four to a batch).
pub fn flight(duration_s: f64) -> (pb::VehicleConfig, Vec<Payload>) {
    let mut s = uavnav_sim::Scenario::from_toml_str(&smoke_text()).unwrap();
    s.duration_s = duration_s;
    s.camera.enabled = false;
    let f = uavnav_sim::Flight::new(&s).unwrap();
    let config = pb::VehicleConfig::from(&f.vehicle_config());
    let mut msgs = vec![Payload::Config(config)];
    let mut imu = Vec::new();
    for ev in f.events() {
        match ev.unwrap() {
            uavnav_core::SensorEvent::Imu(s) => {
                imu.push(s);
                if imu.len() == 4 {
                    msgs.push(Payload::Imu(pb::ImuBatch::from(imu.as_slice())));
                    imu.clear();
                }
            }
            other => {
                if !imu.is_empty() {
                    msgs.push(Payload::Imu(pb::ImuBatch::from(imu.as_slice())));
                    imu.clear();
                }
                msgs.push(Payload::from(&other));
            }
        }
    }
    if !imu.is_empty() {
        msgs.push(Payload::Imu(pb::ImuBatch::from(imu.as_slice())));
    }
    (config, msgs)
}

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
