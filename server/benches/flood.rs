//! Flood benchmark (issue row 1: 20,000 new vehicle ids with Zenoh on stalled the whole service:
//! `/livez` 20.9 s, a healthy vehicle lost 3,036 of 3,842 poses). Not a criterion benchmark: it
//! prints figures and exits 1 when a target is missed (`cargo bench -p uavnavd --bench flood --
//! --ids 20000`).
//!
//! Two runs of an in-process `uavnavd` with its defaults (Zenoh on, on a loopback port): a
//! healthy vehicle streams a simulated flight in real time over gRPC; in the second run a flood
//! of `--ids` new vehicle ids, one IMU sample each, comes over a second gRPC stream as fast as
//! the service takes it, starting a second into the flight. Throughout both runs a prober asks
//! `/livez` (HTTP) and `GetPose` (gRPC) every 10 ms. Targets: the healthy vehicle's poses
//! byte-identical in both runs (the fields that say when the service received them aside), and
//! p99 of both probes at most 50 ms.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::sync::Arc;
use std::time::{Duration, Instant};

use hdrhistogram::Histogram;
use prost::Message;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use uavnav_proto::v1 as pb;
use uavnav_proto::v1::sensor_envelope::Payload;
use uavnav_proto::v1::uav_nav_client::UavNavClient;

const HEALTHY: &str = "healthy";

fn t_ns(p: &Payload) -> Option<i64> {
    match p {
        Payload::Imu(b) => b.samples.first().map(|s| s.t_ns),
        Payload::Gnss(f) => Some(f.t_ns),
        Payload::Mag(m) => Some(m.t_ns),
        Payload::Baro(b) => Some(b.t_ns),
        Payload::Camera(c) => Some(c.t_ns),
        Payload::Config(_) => None,
    }
}

struct Run {
    poses: Vec<Vec<u8>>,
    livez: Histogram<u64>,
    get_pose: Histogram<u64>,
    flood_accepted: u64,
    flood_s: f64,
}

async fn livez(addr: std::net::SocketAddr) -> bool {
    let Ok(mut s) = tokio::net::TcpStream::connect(addr).await else {
        return false;
    };
    if s.write_all(b"GET /livez HTTP/1.1\r\nhost: x\r\nconnection: close\r\n\r\n")
        .await
        .is_err()
    {
        return false;
    }
    let mut buf = Vec::new();
    let _ = s.read_to_end(&mut buf).await;
    buf.starts_with(b"HTTP/1.1 200")
}

async fn run(flood_ids: usize, seconds: f64) -> Run {
    let mut cfg = uavnav_tests::service::loopback_config();
    uavnav_tests::service::listen_zenoh(&mut cfg);
    let server = uavnavd::Server::start(cfg).await.unwrap();
    let (grpc, http) = (server.grpc_addr, server.http_addr);
    let mut poses_rx = server.registry().ctx().hub.poses.subscribe();
    let collector = tokio::spawn(async move {
        let mut out = Vec::new();
        while let Ok(b) = poses_rx.recv().await {
            if &*b.vehicle_id == HEALTHY {
                for mut p in b.to_wire() {
                    p.ingest_wall_ns = 0;
                    out.push(p.encode_to_vec());
                }
            }
        }
        out
    });
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let prober = {
        let stop = Arc::clone(&stop);
        tokio::spawn(async move {
            let mut client = UavNavClient::connect(format!("http://{grpc}"))
                .await
                .unwrap();
            let mut l = Histogram::<u64>::new(3).unwrap();
            let mut g = Histogram::<u64>::new(3).unwrap();
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                let t = Instant::now();
                assert!(livez(http).await, "/livez failed");
                l.record(t.elapsed().as_micros() as u64).unwrap();
                let t = Instant::now();
                let _ = client
                    .get_pose(pb::GetPoseRequest {
                        vehicle_id: HEALTHY.into(),
                    })
                    .await;
                g.record(t.elapsed().as_micros() as u64).unwrap();
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
            (l, g)
        })
    };
    let flood = tokio::spawn(async move {
        if flood_ids == 0 {
            return (0, 0.0);
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
        let mut client = UavNavClient::connect(format!("http://{grpc}"))
            .await
            .unwrap();
        let envs: Vec<_> = (0..flood_ids)
            .map(|i| pb::SensorEnvelope {
                vehicle_id: format!("junk-{i}"),
                sequence: i as u64,
                payload: Some(Payload::Imu(pb::ImuBatch {
                    samples: vec![pb::ImuSample {
                        t_ns: 1,
                        ..Default::default()
                    }],
                })),
            })
            .collect();
        let t = Instant::now();
        let mut acks = client
            .ingest(futures::stream::iter(envs))
            .await
            .unwrap()
            .into_inner();
        let (mut n, mut accepted) = (0, 0);
        while n < flood_ids {
            match acks.message().await {
                Ok(Some(a)) => {
                    n += 1;
                    accepted += u64::from(a.status == pb::IngestStatus::Accepted as i32);
                }
                _ => break,
            }
        }
        (accepted, t.elapsed().as_secs_f64())
    });
    // The healthy vehicle, in real time.
    let (config, msgs) = uavnav_tests::flight::wire_flight(seconds);
    let mut client = UavNavClient::connect(format!("http://{grpc}"))
        .await
        .unwrap();
    client
        .configure_vehicle(pb::ConfigureVehicleRequest {
            vehicle_id: HEALTHY.into(),
            config: Some(config),
        })
        .await
        .unwrap();
    let (tx, rx) = tokio::sync::mpsc::channel(64);
    let mut acks = client
        .ingest(tokio_stream::wrappers::ReceiverStream::new(rx))
        .await
        .unwrap()
        .into_inner();
    let acker = tokio::spawn(async move {
        let mut refused = 0u64;
        while let Ok(Some(a)) = acks.message().await {
            refused += u64::from(a.status != pb::IngestStatus::Accepted as i32);
        }
        refused
    });
    let start = Instant::now();
    let t0 = msgs.iter().find_map(t_ns).unwrap_or(0);
    for (i, m) in msgs.into_iter().enumerate() {
        if matches!(m, Payload::Config(_)) {
            continue;
        }
        if let Some(t) = t_ns(&m) {
            let due = start + Duration::from_nanos((t - t0).max(0) as u64);
            tokio::time::sleep_until(due.into()).await;
        }
        tx.send(pb::SensorEnvelope {
            vehicle_id: HEALTHY.into(),
            sequence: i as u64,
            payload: Some(m),
        })
        .await
        .unwrap();
    }
    drop(tx);
    let refused = acker.await.unwrap();
    assert_eq!(refused, 0, "the healthy vehicle's inputs were refused");
    let (flood_accepted, flood_s) = flood.await.unwrap();
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let (livez, get_pose) = prober.await.unwrap();
    server.shutdown().await.unwrap();
    let poses = collector.await.unwrap();
    Run {
        poses,
        livez,
        get_pose,
        flood_accepted,
        flood_s,
    }
}

fn ms(h: &Histogram<u64>, q: f64) -> f64 {
    h.value_at_quantile(q) as f64 / 1000.0
}

fn main() {
    let mut ids = 20_000usize;
    let mut seconds = 10.0;
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        match a.as_str() {
            "--bench" => {}
            "--ids" => ids = it.next().and_then(|v| v.parse().ok()).unwrap_or(ids),
            "--seconds" => seconds = it.next().and_then(|v| v.parse().ok()).unwrap_or(seconds),
            _ => {
                eprintln!("usage: flood [--ids N] [--seconds S]");
                std::process::exit(2);
            }
        }
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .unwrap();
    let quiet = rt.block_on(run(0, seconds));
    let flooded = rt.block_on(run(ids, seconds));
    let same = quiet.poses == flooded.poses;
    for (name, r) in [("without flood", &quiet), ("with flood", &flooded)] {
        println!(
            "{name}: {} healthy poses; /livez p50/p99/max {:.2}/{:.2}/{:.2} ms ({} probes); GetPose p50/p99/max {:.2}/{:.2}/{:.2} ms; flood {} of {ids} ids accepted in {:.2} s",
            r.poses.len(),
            ms(&r.livez, 0.5),
            ms(&r.livez, 0.99),
            r.livez.max() as f64 / 1000.0,
            r.livez.len(),
            ms(&r.get_pose, 0.5),
            ms(&r.get_pose, 0.99),
            r.get_pose.max() as f64 / 1000.0,
            r.flood_accepted,
            r.flood_s
        );
    }
    println!("healthy vehicle's poses byte-identical with and without the flood: {same}");
    let ok = same && ms(&flooded.livez, 0.99) <= 50.0 && ms(&flooded.get_pose, 0.99) <= 50.0;
    if !ok {
        eprintln!("flood: a target was missed");
        std::process::exit(1);
    }
}
