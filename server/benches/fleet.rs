//! Fleet load benchmark: how many vehicles one in-process `uavnavd` sustains in real time on this
//! machine, load generator included. Not a criterion benchmark: it is a load test that prints a
//! table (`cargo bench -p uavnavd --bench fleet -- --help`).
//!
//! Each vehicle replays the simulated `scenarios/smoke.toml` flight (200 Hz IMU, 5 Hz GNSS and, with
//! `--camera`, 10 Hz 640×480 JPEG frames) at real time over gRPC `Ingest`, IMU batched `--batch`
//! samples per envelope. A run is *sustained* when ≥ 99 % of the IMU samples sent came back as
//! poses, the generator kept its schedule (p99 send lag < 50 ms) and p99 ingest-to-pose latency is
//! ≤ 50 ms. Latency is the service's: from the envelope's arrival (`PoseEstimate.ingest_wall_ns`)
//! to the pose reaching the output hub. RSS is sampled every second.
//!
//! `--tls`: the same load with security on: TLS (certificates made for the run), every client
//! authenticated by a bearer token and every envelope authorized against a fleet grant — the cost
//! of security on the hot path, against the plaintext rows.
//!
//! `--zenoh-watch-one`: Zenoh on, and a Zenoh peer subscribed to one vehicle's `pose` and `health` (`v0`):
//! what one watched vehicle costs a fleet. The poses the service put on Zenoh
//! (`uavnav_zenoh_poses_published_total`) and those the watcher got are printed on stderr. The
//! `cores` column is the process's CPU time (service and load generator) over the run's wall time.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

#[path = "../tests/common/mod.rs"]
mod common;

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use hdrhistogram::Histogram;
use tokio::sync::mpsc;
use uavnav_core::SensorEvent;
use uavnav_proto::v1 as pb;
use uavnav_proto::v1::uav_nav_client::UavNavClient;
use uavnavd::{Config, Server};

#[derive(Debug, Clone)]
struct Args {
    vehicles: Vec<usize>,
    camera: bool,
    duration_s: f64,
    batch: usize,
    clients: usize,
    tls: bool,
    zenoh_watch_one: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        vehicles: vec![250, 500, 1000, 2000],
        camera: false,
        duration_s: 15.0,
        batch: 4,
        clients: 8,
        tls: false,
        zenoh_watch_one: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut val = || it.next().ok_or(format!("{arg} needs a value"));
        match arg.as_str() {
            "--bench" => {}
            "--camera" => a.camera = true,
            "--tls" => a.tls = true,
            "--zenoh-watch-one" => a.zenoh_watch_one = true,
            "--vehicles" => {
                a.vehicles = val()?.split(',').map(|s| s.trim().parse().map_err(|e| format!("--vehicles: {e}"))).collect::<Result<_, _>>()?
            }
            "--duration-s" => a.duration_s = val()?.parse().map_err(|e| format!("--duration-s: {e}"))?,
            "--batch" => a.batch = val()?.parse().map_err(|e| format!("--batch: {e}"))?,
            "--clients" => a.clients = val()?.parse().map_err(|e| format!("--clients: {e}"))?,
            "--help" | "-h" => {
                return Err("usage: fleet [--vehicles N,N,...] [--camera] [--tls] [--zenoh-watch-one] [--duration-s S] [--batch K] [--clients C]".into())
            }
            other => return Err(format!("unknown argument {other}")),
        }
    }
    if a.duration_s > 19.0 {
        return Err("--duration-s must be <= 19 (the smoke flight lasts 20 s)".into());
    }
    Ok(a)
}

/// CPU time of this process (user + system), seconds.
fn cpu_s() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which may hold spaces): utime and stime are 14 and 15.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<f64> = rest
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0.0))
        .collect();
    // Clock ticks of 1/100 s (`getconf CLK_TCK` on Linux).
    (f.get(11).copied().unwrap_or(0.0) + f.get(12).copied().unwrap_or(0.0)) / 100.0
}

/// One wire payload at its sensor time.
#[derive(Clone)]
struct Item {
    t_ns: i64,
    payload: pb::sensor_envelope::Payload,
    imu_samples: u64,
}

/// The flight as wire payloads, IMU batched.
fn script(events: &[SensorEvent], batch: usize, camera: bool) -> Vec<Item> {
    use pb::sensor_envelope::Payload as P;
    let mut out = Vec::new();
    let mut imu: Vec<pb::ImuSample> = Vec::new();
    let flush = |imu: &mut Vec<pb::ImuSample>, out: &mut Vec<Item>| {
        if let Some(last) = imu.last() {
            let t_ns = last.t_ns;
            let n = imu.len() as u64;
            out.push(Item {
                t_ns,
                payload: P::Imu(pb::ImuBatch {
                    samples: std::mem::take(imu),
                }),
                imu_samples: n,
            });
        }
    };
    for e in events {
        match e {
            SensorEvent::Imu(s) => {
                imu.push(s.into());
                if imu.len() == batch {
                    flush(&mut imu, &mut out);
                }
            }
            SensorEvent::Gnss(f) => {
                flush(&mut imu, &mut out);
                out.push(Item {
                    t_ns: f.t_ns,
                    payload: P::Gnss(f.into()),
                    imu_samples: 0,
                });
            }
            SensorEvent::Camera(c) if camera => {
                flush(&mut imu, &mut out);
                out.push(Item {
                    t_ns: c.t_ns,
                    payload: P::Camera(c.into()),
                    imu_samples: 0,
                });
            }
            SensorEvent::Camera(_) => {}
            SensorEvent::Mag(m) => {
                flush(&mut imu, &mut out);
                out.push(Item {
                    t_ns: m.t_ns,
                    payload: P::Mag(m.into()),
                    imu_samples: 0,
                });
            }
            SensorEvent::Baro(b) => {
                flush(&mut imu, &mut out);
                out.push(Item {
                    t_ns: b.t_ns,
                    payload: P::Baro(b.into()),
                    imu_samples: 0,
                });
            }
        }
    }
    flush(&mut imu, &mut out);
    out
}

#[derive(Debug, Default)]
struct Row {
    vehicles: usize,
    seconds: f64,
    envelopes_per_s: f64,
    imu_sent: u64,
    poses: u64,
    frames_sent: u64,
    not_accepted: u64,
    shed: u64,
    lag_p99_ms: f64,
    lat_p50_ms: f64,
    lat_p99_ms: f64,
    lat_max_ms: f64,
    rss_start_mib: f64,
    rss_end_mib: f64,
    cores: f64,
}

impl Row {
    fn sustained(&self) -> bool {
        self.poses as f64 >= 0.99 * self.imu_sent as f64
            && self.lag_p99_ms < 50.0
            && self.lat_p99_ms <= 50.0
    }
}

fn rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .map(str::to_owned)
        })
        .and_then(|l| {
            l.split_whitespace()
                .nth(1)
                .and_then(|v| v.parse::<f64>().ok())
        })
        .map_or(0.0, |kib| kib / 1024.0)
}

/// The bench's token (its SHA-256 is in the service's configuration).
const TOKEN: &str = "fleet-bench-token";

/// Adds the bearer token (if any) to every call.
type Intercept =
    Box<dyn FnMut(tonic::Request<()>) -> Result<tonic::Request<()>, tonic::Status> + Send>;

type Client = UavNavClient<
    tonic::service::interceptor::InterceptedService<tonic::transport::Channel, Intercept>,
>;

/// Where the clients connect: plaintext, or TLS trusting `ca` with the bench's token.
#[derive(Clone)]
struct Target {
    addr: std::net::SocketAddr,
    ca: Option<Vec<u8>>,
}

async fn connect(t: &Target) -> Client {
    let (scheme, tls) = match &t.ca {
        Some(ca) => (
            "https",
            Some(
                tonic::transport::ClientTlsConfig::new()
                    .ca_certificate(tonic::transport::Certificate::from_pem(ca))
                    .domain_name("localhost"),
            ),
        ),
        None => ("http", None),
    };
    let mut ep =
        tonic::transport::Endpoint::from_shared(format!("{scheme}://localhost:{}", t.addr.port()))
            .expect("endpoint");
    if let Some(tls) = tls {
        ep = ep.tls_config(tls).expect("tls");
    }
    let channel = ep.connect().await.expect("connect");
    let token: Option<tonic::metadata::MetadataValue<tonic::metadata::Ascii>> =
        t.ca.as_ref()
            .map(|_| format!("Bearer {TOKEN}").parse().expect("token"));
    let f: Intercept = Box::new(move |mut r: tonic::Request<()>| {
        if let Some(v) = &token {
            r.metadata_mut().insert("authorization", v.clone());
        }
        Ok(r)
    });
    UavNavClient::with_interceptor(channel, f).max_encoding_message_size(16 << 20)
}

async fn run(n: usize, args: &Args, items: Arc<Vec<Item>>, config: pb::VehicleConfig) -> Row {
    let mut cfg = Config::default();
    cfg.grpc.addr = "127.0.0.1:0".parse().expect("addr");
    cfg.http.addr = "127.0.0.1:0".parse().expect("addr");
    cfg.zenoh.enabled = false;
    let zenoh_endpoint = args
        .zenoh_watch_one
        .then(|| uavnav_tests::service::listen_zenoh(&mut cfg));
    cfg.vehicles.max_vehicles = n + 16;
    let dir = tempfile::tempdir().expect("tempdir");
    let ca = if args.tls {
        let pki = uavnav_tests::pki::Pki::new(dir.path(), "bench");
        let svc = pki.service("uavnavd");
        cfg.security.tls = Some(uavnavd::security::TlsConfig {
            certificate: svc.cert,
            private_key: svc.key,
            client_ca: None,
            require_client_certificate: false,
            reload_s: 10.0,
        });
        cfg.security.principals = vec![uavnavd::security::PrincipalConfig {
            name: "bench".into(),
            certificate_names: vec![],
            token_sha256: vec![uavnavd::security::auth::token_digest_hex(TOKEN)],
            grants: vec![uavnavd::security::Grant {
                vehicles: "v".into(),
                verbs: vec![
                    uavnavd::security::Verb::Feed,
                    uavnavd::security::Verb::Configure,
                ],
            }],
        }];
        Some(std::fs::read(&pki.ca).expect("CA"))
    } else {
        None
    };
    let server = Server::start(cfg).await.expect("server starts");
    let zenoh_watcher = match &zenoh_endpoint {
        Some(endpoint) => {
            let z = common::zenoh_peer(endpoint).await;
            let got = Arc::new(AtomicU64::new(0));
            let g = Arc::clone(&got);
            let sub = z
                .declare_subscriber(uavnav_proto::keys::vehicle_key(
                    "v0",
                    uavnav_proto::keys::Leaf::Pose,
                ))
                .callback(move |_| {
                    g.fetch_add(1, Ordering::Relaxed);
                })
                .await
                .expect("zenoh subscriber");
            // And its health, as a ground station watching one vehicle would: health goes out
            // on keys nobody declared, whose routing walks the session's declared keys.
            let health = z
                .declare_subscriber(uavnav_proto::keys::vehicle_key(
                    "v0",
                    uavnav_proto::keys::Leaf::Health,
                ))
                .callback(|_| {})
                .await
                .expect("zenoh subscriber");
            let sub = (sub, got, health);
            Some((z, sub))
        }
        None => None,
    };
    let target = Target {
        addr: server.grpc_addr,
        ca,
    };
    let mut c = connect(&target).await;
    for v in 0..n {
        c.configure_vehicle(pb::ConfigureVehicleRequest {
            vehicle_id: format!("v{v}"),
            config: Some(config),
        })
        .await
        .expect("configure");
    }
    // Latency and pose count, in-process on the output hub.
    let mut poses_rx = server.registry().ctx().hub.poses.subscribe();
    let poses = Arc::new(AtomicU64::new(0));
    let hist = Arc::new(std::sync::Mutex::new(
        Histogram::<u64>::new_with_bounds(1, 60_000_000, 3).expect("hist"),
    ));
    let (p2, h2) = (Arc::clone(&poses), Arc::clone(&hist));
    let watcher = tokio::spawn(async move {
        loop {
            match poses_rx.recv().await {
                Ok(batch) => {
                    p2.fetch_add(batch.poses.len() as u64, Ordering::Relaxed);
                    let now_ns = uavnavd::vehicle::wall_ns();
                    if let Ok(mut h) = h2.lock() {
                        for p in &batch.poses {
                            let lat_us = (now_ns - p.ingest_wall_ns) / 1000;
                            let _ = h.record(lat_us.max(1) as u64);
                        }
                    }
                }
                Err(tokio::sync::broadcast::error::RecvError::Lagged(k)) => {
                    // k batches skipped, counted as one pose each (a lower bound).
                    p2.fetch_add(k, Ordering::Relaxed);
                }
                Err(_) => break,
            }
        }
    });
    let rss_start = rss_mib();
    let cpu_start_s = cpu_s();
    let t_first = items[0].t_ns;
    let horizon_ns = (args.duration_s * 1e9) as i64;
    let start = tokio::time::Instant::now() + Duration::from_millis(300);
    let (imu_sent, frames_sent, not_accepted, envelopes) = (
        Arc::new(AtomicU64::new(0)),
        Arc::new(AtomicU64::new(0)),
        Arc::new(AtomicU64::new(0)),
        Arc::new(AtomicU64::new(0)),
    );
    let lag = Arc::new(std::sync::Mutex::new(
        Histogram::<u64>::new_with_bounds(1, 60_000_000, 3).expect("hist"),
    ));
    let mut tasks = Vec::new();
    for k in 0..args.clients.min(n) {
        let ids: Vec<String> = (k..n)
            .step_by(args.clients)
            .map(|v| format!("v{v}"))
            .collect();
        let (items, target) = (Arc::clone(&items), target.clone());
        let (imu_sent, frames_sent, not_accepted, envelopes, lag) = (
            imu_sent.clone(),
            frames_sent.clone(),
            not_accepted.clone(),
            envelopes.clone(),
            lag.clone(),
        );
        tasks.push(tokio::spawn(async move {
            let mut client = connect(&target).await;
            let (tx, rx) = mpsc::channel::<pb::SensorEnvelope>(4096);
            let mut acks = client
                .ingest(tokio_stream::wrappers::ReceiverStream::new(rx))
                .await
                .expect("ingest")
                .into_inner();
            let na = not_accepted.clone();
            let ack_task = tokio::spawn(async move {
                while let Ok(Some(a)) = acks.message().await {
                    if a.status != pb::IngestStatus::Accepted as i32 {
                        na.fetch_add(1, Ordering::Relaxed);
                    }
                }
            });
            let mut seq = 0u64;
            for item in items.iter().take_while(|i| i.t_ns - t_first <= horizon_ns) {
                let due = start + Duration::from_nanos((item.t_ns - t_first) as u64);
                tokio::time::sleep_until(due).await;
                let late_us = tokio::time::Instant::now()
                    .saturating_duration_since(due)
                    .as_micros() as u64;
                if let Ok(mut h) = lag.lock() {
                    let _ = h.record(late_us.max(1));
                }
                for id in &ids {
                    seq += 1;
                    let env = pb::SensorEnvelope {
                        vehicle_id: id.clone(),
                        sequence: seq,
                        payload: Some(item.payload.clone()),
                    };
                    if tx.send(env).await.is_err() {
                        return;
                    }
                    envelopes.fetch_add(1, Ordering::Relaxed);
                    imu_sent.fetch_add(item.imu_samples, Ordering::Relaxed);
                    if matches!(item.payload, pb::sensor_envelope::Payload::Camera(_)) {
                        frames_sent.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
            drop(tx);
            let _ = ack_task.await;
        }));
    }
    for t in tasks {
        let _ = t.await;
    }
    let seconds = start.elapsed().as_secs_f64();
    // The last reorder window is flushed after the idle delay.
    tokio::time::sleep(Duration::from_millis(500)).await;
    let shed = server
        .registry()
        .list("")
        .iter()
        .map(|h| h.shared.stats.shed.load(Ordering::Relaxed))
        .sum();
    let rss_end = rss_mib();
    let cores = (cpu_s() - cpu_start_s) / (seconds + 0.5);
    if let Some((z, sub)) = zenoh_watcher {
        eprintln!(
            "{n} vehicles, v0 watched on Zenoh: {} poses put on Zenoh, {} received by the watcher",
            server.metrics().zenoh_poses_published.get(),
            sub.1.load(Ordering::Relaxed)
        );
        let _ = z.close().await;
    }
    server.shutdown().await.expect("shutdown");
    watcher.abort();
    let h = hist.lock().map(|h| h.clone()).expect("hist");
    let l = lag.lock().map(|h| h.clone()).expect("lag");
    Row {
        vehicles: n,
        seconds,
        envelopes_per_s: envelopes.load(Ordering::Relaxed) as f64 / seconds,
        imu_sent: imu_sent.load(Ordering::Relaxed),
        poses: poses.load(Ordering::Relaxed),
        frames_sent: frames_sent.load(Ordering::Relaxed),
        not_accepted: not_accepted.load(Ordering::Relaxed),
        shed,
        lag_p99_ms: l.value_at_quantile(0.99) as f64 / 1e3,
        lat_p50_ms: h.value_at_quantile(0.5) as f64 / 1e3,
        lat_p99_ms: h.value_at_quantile(0.99) as f64 / 1e3,
        lat_max_ms: h.max() as f64 / 1e3,
        rss_start_mib: rss_start,
        rss_end_mib: rss_end,
        cores,
    }
}

fn main() {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let scenario_path = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenarios/smoke.toml");
    let text = std::fs::read_to_string(scenario_path).expect("scenarios/smoke.toml");
    let scenario = uavnav_sim::scenario::Scenario::from_toml_str(&text).expect("scenario");
    let flight = uavnav_sim::flight::Flight::new(&scenario).expect("flight");
    eprintln!(
        "simulating the smoke flight{}…",
        if args.camera {
            " with camera frames"
        } else {
            ""
        }
    );
    let events: Vec<SensorEvent> = if args.camera {
        flight.events().collect::<Result<_, _>>().expect("events")
    } else {
        let mut ev: Vec<SensorEvent> = flight.imu().iter().map(|s| SensorEvent::Imu(*s)).collect();
        ev.extend(flight.gnss().iter().map(|g| SensorEvent::Gnss(*g)));
        ev.sort_by_key(|e| (e.t_ns(), matches!(e, SensorEvent::Gnss(_))));
        ev
    };
    let mut vc = flight.vehicle_config();
    if !args.camera {
        vc.camera = None;
    }
    let config = pb::VehicleConfig::from(&vc);
    let items = Arc::new(script(&events, args.batch, args.camera));
    // As `uavnavd` runs: a worker that parks gives back its free memory.
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .on_thread_park(|| {
            uavnavd::allocator::collect_on_park();
        })
        .build()
        .expect("runtime");
    println!(
        "| vehicles | camera | TLS + auth | s | envelopes/s | IMU sent | poses | frames sent | refused | shed | send lag p99 ms | latency p50 / p99 / max ms | RSS start → end MiB | cores | sustained |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for &n in &args.vehicles {
        let r = rt.block_on(run(n, &args, Arc::clone(&items), config));
        println!(
            "| {} | {} | {} | {:.1} | {:.0} | {} | {} | {} | {} | {} | {:.1} | {:.1} / {:.1} / {:.1} | {:.0} → {:.0} | {:.2} | {} |",
            r.vehicles,
            if args.camera { "10 Hz" } else { "no" },
            if args.tls { "yes" } else { "no" },
            r.seconds,
            r.envelopes_per_s,
            r.imu_sent,
            r.poses,
            r.frames_sent,
            r.not_accepted,
            r.shed,
            r.lag_p99_ms,
            r.lat_p50_ms,
            r.lat_p99_ms,
            r.lat_max_ms,
            r.rss_start_mib,
            r.rss_end_mib,
            r.cores,
            if r.sustained() { "yes" } else { "no" }
        );
    }
}
