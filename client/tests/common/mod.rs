//! Shared by the client library's end-to-end tests: an in-process `uavnavd` (gRPC and HTTP on
//! port 0, Zenoh listening on an explicit localhost port with multicast scouting off) and
//! simulated flights as wire messages.
#![allow(dead_code)] // each test file uses a different part

use std::path::Path;
use std::time::Duration;

use uavnav_client::pb::sensor_envelope::Payload;
use uavnav_client::{Client, pb};

/// A free localhost TCP port for Zenoh (bind 0, read, release).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

pub struct Svc {
    pub server: uavnavd::RunningServer,
    pub grpc: String,
    pub zenoh: String,
}

pub async fn start() -> Svc {
    let mut c = uavnavd::Config::default();
    c.grpc.addr = "127.0.0.1:0".parse().unwrap();
    c.http.addr = "127.0.0.1:0".parse().unwrap();
    let port = free_port();
    c.zenoh.listen = vec![format!("tcp/127.0.0.1:{port}")];
    c.zenoh.multicast_scouting = false;
    c.health.period_ms = 200;
    let server = uavnavd::Server::start(c).await.unwrap();
    let grpc = format!("grpc://{}", server.grpc_addr);
    Svc {
        server,
        grpc,
        zenoh: format!("zenoh/tcp/127.0.0.1:{port}"),
    }
}

pub fn smoke_text() -> String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/smoke.toml"))
        .unwrap()
}

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
