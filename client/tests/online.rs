//! End-to-end tests of the client library and the online `uavnav` subcommands against an
//! in-process `uavnavd` (gRPC and HTTP on port 0, Zenoh listening on an explicit localhost port
//! with multicast scouting off). One file so the zenoh-heavy test binary links once.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Arc;
use std::time::Duration;

use uavnav_client::load::{self, Live, LoadParams, Recording};
use uavnav_client::schedule::{self, ScheduleParams, TimedMessage};
use uavnav_client::{Client, ClientError, ConnectOptions, Endpoint, Selector, pb};

const BIN: &str = env!("CARGO_BIN_EXE_uavnav");

/// A free localhost TCP port for Zenoh (bind 0, read, release).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

struct Svc {
    server: uavnavd::RunningServer,
    grpc: String,
    zenoh: String,
}

async fn start() -> Svc {
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

fn smoke_text() -> String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/smoke.toml"))
        .unwrap()
}

/// A short smoke flight without camera: its wire configuration and its schedule.
fn flight(duration_s: f64) -> (pb::VehicleConfig, Vec<TimedMessage>) {
    let mut s = uavnav_sim::Scenario::from_toml_str(&smoke_text()).unwrap();
    s.duration_s = duration_s;
    s.camera.enabled = false;
    let f = uavnav_sim::Flight::new(&s).unwrap();
    let config = pb::VehicleConfig::from(&f.vehicle_config());
    let events: Vec<_> = f.events().collect::<Result<_, _>>().unwrap();
    let msgs = schedule::build(Some(&config), events, &ScheduleParams::default());
    (config, msgs)
}

fn run(args: &[&str]) -> Output {
    let out = Command::new(BIN).args(args).output().unwrap();
    eprintln!(
        "$ uavnav {}\n-> {:?}\nstdout: {}\nstderr: {}",
        args.join(" "),
        out.status.code(),
        String::from_utf8_lossy(&out.stdout)
            .chars()
            .take(2000)
            .collect::<String>(),
        String::from_utf8_lossy(&out.stderr)
            .chars()
            .take(2000)
            .collect::<String>()
    );
    out
}

async fn run_async(args: Vec<String>) -> Output {
    tokio::task::spawn_blocking(move || run(&args.iter().map(String::as_str).collect::<Vec<_>>()))
        .await
        .unwrap()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Feeds a schedule for `id` as fast as the service accepts.
async fn feed(client: &Client, id: &str, msgs: &[TimedMessage]) {
    let ingest = client.ingest().await.unwrap();
    for m in msgs {
        ingest.send(id, m.payload.clone()).await.unwrap();
    }
    let stats = ingest.finish(Duration::from_secs(10)).await;
    let sent = stats.sent.load(std::sync::atomic::Ordering::Relaxed);
    assert_eq!(sent, msgs.len() as u64);
}

/// Collects poses from a watch until `n` arrived or `timeout`.
async fn collect(
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

#[test]
fn zenoh_keys_match_the_service() {
    use uavnav_client::keys;
    assert_eq!(keys::VEHICLE_PREFIX, uavnavd::zenoh_io::VEHICLE_PREFIX);
    assert_eq!(keys::VEHICLES, uavnavd::zenoh_io::VEHICLES_KEY);
    assert_eq!(keys::SERVICE_PREFIX, uavnavd::zenoh_io::SERVICE_PREFIX);
    assert_eq!(
        keys::pose_latest_key("*"),
        uavnavd::zenoh_io::POSE_LATEST_KEYS
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn library_same_api_over_grpc_and_zenoh() {
    let svc = start().await;
    let opts = ConnectOptions::default();
    let g = Client::connect(&svc.grpc.parse().unwrap(), opts.clone())
        .await
        .unwrap();
    let z = Client::connect(&svc.zenoh.parse().unwrap(), opts.clone())
        .await
        .unwrap();
    let (config, msgs) = flight(6.0);

    // Watch over both transports, feed over gRPC (vehicle a) and Zenoh (vehicle b).
    let mut wg = g
        .watch_poses(Selector::ids(["lib-a", "lib-b"]))
        .await
        .unwrap();
    let mut wz = z
        .watch_poses(Selector::prefix("lib-").with_decimation(10))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(g.configure("lib-a", &config).await.unwrap(), Some(true));
    assert_eq!(g.configure("lib-a", &config).await.unwrap(), Some(false));
    assert_eq!(z.configure("lib-b", &config).await.unwrap(), None);
    feed(&g, "lib-a", &msgs).await;
    feed(&z, "lib-b", &msgs).await;

    // lib-a was fed first (as fast as accepted): read until lib-b's poses show up too.
    let mut pg = collect(&mut wg, 200, Duration::from_secs(15)).await;
    let _ = tokio::time::timeout(Duration::from_secs(15), async {
        while !pg.iter().any(|p| p.vehicle_id == "lib-b") {
            match wg.next().await {
                Some(Ok(p)) => pg.push(p),
                _ => break,
            }
        }
    })
    .await;
    let pz = collect(&mut wz, 20, Duration::from_secs(15)).await;
    assert!(pg.len() >= 200, "gRPC watch got {} poses", pg.len());
    assert!(pz.len() >= 20, "Zenoh watch got {} poses", pz.len());
    for id in ["lib-a", "lib-b"] {
        let list = g.list_vehicles("").await.unwrap();
        assert!(
            pg.iter().any(|p| p.vehicle_id == id),
            "no gRPC pose of {id} ({} poses; vehicles {list:?})",
            pg.len()
        );
    }
    // Decimation 10 over Zenoh: consecutive poses of one vehicle are 10 IMU samples (50 ms) apart.
    let za: Vec<i64> = pz
        .iter()
        .filter(|p| p.vehicle_id == pz[0].vehicle_id)
        .map(|p| p.t_ns)
        .collect();
    assert!(za.windows(2).all(|w| w[1] - w[0] == 50_000_000), "{za:?}");

    // List and latest pose agree across transports.
    tokio::time::sleep(Duration::from_millis(500)).await;
    let lg = g.list_vehicles("lib-").await.unwrap();
    let lz = z.list_vehicles("lib-").await.unwrap();
    let ids = |l: &[pb::VehicleSummary]| l.iter().map(|v| v.vehicle_id.clone()).collect::<Vec<_>>();
    assert_eq!(ids(&lg), vec!["lib-a", "lib-b"]);
    assert_eq!(ids(&lg), ids(&lz));
    let a_g = g.get_pose("lib-a").await.unwrap();
    let a_z = z.get_pose("lib-a").await.unwrap();
    assert_eq!(a_g.t_ns, a_z.t_ns);
    assert!(matches!(
        g.get_pose("nobody").await,
        Err(ClientError::NotFound(_))
    ));
    assert!(matches!(
        z.get_pose("nobody").await,
        Err(ClientError::NotFound(_))
    ));
    assert!(matches!(
        g.get_pose("bad id!").await,
        Err(ClientError::InvalidId { .. })
    ));

    // Reset: gRPC only.
    g.reset("lib-a").await.unwrap();
    assert!(matches!(
        z.reset("lib-a").await,
        Err(ClientError::Unsupported { .. })
    ));
    assert!(matches!(
        g.reset("nobody").await,
        Err(ClientError::NotFound(_))
    ));

    // Health over both.
    let mut hg = g.watch_health(Selector::all()).await.unwrap();
    let mut hz = z.watch_health(Selector::ids(["lib-b"])).await.unwrap();
    let h1 = tokio::time::timeout(Duration::from_secs(5), hg.next())
        .await
        .unwrap()
        .unwrap()
        .unwrap();
    let h2 = tokio::time::timeout(Duration::from_secs(5), hz.next())
        .await
        .unwrap()
        .unwrap()
        .unwrap();
    assert!(h1.vehicle_id.starts_with("lib-"));
    assert_eq!(h2.vehicle_id, "lib-b");

    // Errors name what failed.
    let e = Client::connect(
        &"grpc://127.0.0.1:1".parse().unwrap(),
        ConnectOptions {
            connect_timeout: Duration::from_millis(500),
            ..opts
        },
    )
    .await
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("cannot connect to grpc://127.0.0.1:1"),
        "{e}"
    );
    let e = "grpc://nohost".parse::<Endpoint>().unwrap_err();
    assert!(e.to_string().contains("missing :PORT"), "{e}");
    g.close().await;
    z.close().await;
    svc.server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn loadtest_measures_against_the_service_and_the_discard_sink() {
    let svc = start().await;
    let (_, msgs) = flight(4.0);
    let rec = Arc::new(Recording::new(msgs).unwrap());
    // The library directly: every vehicle gets poses, latency is measured.
    let client = Client::connect_url(&svc.grpc).await.unwrap();
    let params = LoadParams {
        vehicles: 3,
        duration: Duration::from_secs(2),
        id_prefix: "ltlib-".into(),
        ..LoadParams::default()
    };
    let o = load::run(&client, Arc::clone(&rec), params, Arc::new(Live::default()))
        .await
        .unwrap();
    assert_eq!(o.sent, o.scheduled);
    assert_eq!(o.vehicles_with_poses, 3);
    assert!(o.poses > 100 && !o.latency_ns.is_empty());
    assert_eq!(o.statuses.get("OK").copied(), Some(o.sent));

    // Against the discard sink nothing is expected back.
    let d = Client::connect_url("discard").await.unwrap();
    let params = LoadParams {
        vehicles: 50,
        duration: Duration::from_secs(1),
        id_prefix: "d-".into(),
        ..LoadParams::default()
    };
    let o = load::run(&d, rec, params, Arc::new(Live::default()))
        .await
        .unwrap();
    assert_eq!(o.sent, o.scheduled);
    assert!(
        o.failures(&load::Thresholds::default()).is_empty(),
        "{:?}",
        o.failures(&load::Thresholds::default())
    );

    // The CLI: the JSON report, field by field.
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("lt.json");
    let out = run_async(vec![
        "loadtest".into(),
        "--to".into(),
        svc.grpc.clone(),
        "--vehicles".into(),
        "2".into(),
        "--duration".into(),
        "2s".into(),
        "--no-camera".into(),
        "--quiet".into(),
        "--json".into(),
        json.display().to_string(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(0));
    assert!(stdout(&out).contains("Latency (ingest to pose)"));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let count = v["count"].as_u64().unwrap();
    // 2 vehicles × ~2 s (the second starts 0.5 s late) × (50 IMU batches + 5 fixes) per s.
    assert!(count > 150, "count {count}");
    assert_eq!(v["uavnav"]["scheduled"].as_u64(), Some(count));
    let total = v["total"].as_u64().unwrap();
    assert!(
        (1_900_000_000..4_000_000_000).contains(&total),
        "total {total} ns"
    );
    let rps = v["rps"].as_f64().unwrap();
    assert!((rps - count as f64 / (total as f64 * 1e-9)).abs() < 1e-6 * rps);
    let (fastest, average, slowest) = (
        v["fastest"].as_u64().unwrap(),
        v["average"].as_u64().unwrap(),
        v["slowest"].as_u64().unwrap(),
    );
    assert!(
        0 < fastest && fastest <= average && average <= slowest,
        "{fastest} {average} {slowest}"
    );
    let dist = v["latencyDistribution"].as_array().unwrap();
    let pcts: Vec<f64> = dist
        .iter()
        .map(|d| d["percentage"].as_f64().unwrap())
        .collect();
    assert_eq!(pcts, vec![50.0, 75.0, 90.0, 95.0, 99.0, 99.9]);
    let lats: Vec<u64> = dist
        .iter()
        .map(|d| d["latency"].as_u64().unwrap())
        .collect();
    assert!(
        lats.windows(2).all(|w| w[0] <= w[1])
            && lats[0] >= fastest
            && *lats.last().unwrap() <= slowest,
        "{lats:?}"
    );
    assert_eq!(v["statusCodeDistribution"]["OK"].as_u64(), Some(count));
    assert_eq!(v["errorDistribution"].as_object().unwrap().len(), 0);
    let x = &v["uavnav"];
    assert_eq!(x["vehicles"].as_u64(), Some(2));
    assert_eq!(x["camera"].as_bool(), Some(false));
    assert_eq!(x["vehiclesWithPoses"].as_u64(), Some(2));
    assert!(x["poses"].as_u64().unwrap() > 300);
    assert_eq!(x["unacked"].as_u64(), Some(0));
    assert_eq!(x["errorRate"].as_f64(), Some(0.0));
    assert_eq!(x["keptUp"].as_bool(), Some(true));
    assert_eq!(x["service"]["vehiclesReporting"].as_u64(), Some(2));
    assert!(x["service"]["accepted"].as_u64().unwrap() > 0);

    // An impossible latency bound: exit 3 with the reason.
    let out = run_async(vec![
        "loadtest".into(),
        "--to".into(),
        svc.grpc.clone(),
        "--vehicles".into(),
        "1".into(),
        "--duration".into(),
        "1s".into(),
        "--no-camera".into(),
        "--quiet".into(),
        "--max-p99-ms".into(),
        "0.001".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&out.stderr).contains("p99 ingest-to-pose latency"));
    svc.server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cli_management_subcommands() {
    let svc = start().await;
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("s.toml");
    std::fs::write(
        &scenario,
        smoke_text().replace("duration_s = 20.0", "duration_s = 3.0"),
    )
    .unwrap();
    let sc = scenario.display().to_string();
    let g = svc.grpc.clone();

    // configure: created, then reconfigured; over Zenoh: published.
    let out = run_async(vec![
        "configure".into(),
        "--from".into(),
        g.clone(),
        "--vehicle".into(),
        "cli-1".into(),
        "--scenario".into(),
        sc.clone(),
        "--no-camera".into(),
    ])
    .await;
    assert_eq!(
        (out.status.code(), stdout(&out).trim()),
        (Some(0), "created cli-1")
    );
    let out = run_async(vec![
        "configure".into(),
        "--from".into(),
        g.clone(),
        "--vehicle".into(),
        "cli-1".into(),
        "--scenario".into(),
        sc.clone(),
    ])
    .await;
    assert_eq!(
        (out.status.code(), stdout(&out).trim()),
        (Some(0), "reconfigured cli-1")
    );
    let out = run_async(vec![
        "configure".into(),
        "--from".into(),
        svc.zenoh.clone(),
        "--vehicle".into(),
        "cli-2".into(),
        "--scenario".into(),
        sc.clone(),
    ])
    .await;
    assert_eq!(
        (out.status.code(), stdout(&out).trim()),
        (Some(0), "published cli-2")
    );

    // vehicles: both listed (over gRPC and Zenoh).
    tokio::time::sleep(Duration::from_millis(300)).await;
    for url in [&g, &svc.zenoh] {
        let out = run_async(vec![
            "vehicles".into(),
            "--from".into(),
            url.clone(),
            "--json".into(),
        ])
        .await;
        assert_eq!(out.status.code(), Some(0));
        let ids: Vec<String> = stdout(&out)
            .lines()
            .map(|l| {
                serde_json::from_str::<serde_json::Value>(l).unwrap()["vehicle_id"]
                    .as_str()
                    .unwrap()
                    .to_string()
            })
            .collect();
        assert_eq!(ids, vec!["cli-1", "cli-2"]);
    }

    // health: service check, then per vehicle; --max-age on an unknown vehicle = exit 3.
    let out = run_async(vec!["health".into(), "--from".into(), g.clone()]).await;
    assert_eq!(out.status.code(), Some(0));
    assert!(stdout(&out).starts_with("ok: "));
    let out = run_async(vec![
        "health".into(),
        "--from".into(),
        g.clone(),
        "--vehicle".into(),
        "cli-1".into(),
        "--wait".into(),
        "0.8".into(),
        "--json".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(0));
    let h: serde_json::Value = serde_json::from_str(stdout(&out).lines().next().unwrap()).unwrap();
    assert_eq!(h["vehicle_id"], "cli-1");
    let out = run_async(vec![
        "health".into(),
        "--from".into(),
        g.clone(),
        "--vehicle".into(),
        "ghost".into(),
        "--wait".into(),
        "0.2".into(),
        "--max-age".into(),
        "5".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(3));

    // reset: ok, unknown = 2, over Zenoh = 2 (unsupported).
    let out = run_async(vec![
        "reset".into(),
        "--from".into(),
        g.clone(),
        "--vehicle".into(),
        "cli-1".into(),
    ])
    .await;
    assert_eq!(
        (out.status.code(), stdout(&out).trim()),
        (Some(0), "reset cli-1")
    );
    let out = run_async(vec![
        "reset".into(),
        "--from".into(),
        g.clone(),
        "--vehicle".into(),
        "ghost".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(2));
    let out = run_async(vec![
        "reset".into(),
        "--from".into(),
        svc.zenoh.clone(),
        "--vehicle".into(),
        "cli-1".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(2));

    // Bad URL = 2, unreachable = 1; every subcommand has --help with the exit codes.
    assert_eq!(
        run(&["vehicles", "--from", "ftp://x:1"]).status.code(),
        Some(2)
    );
    assert_eq!(
        run(&["vehicles", "--from", "grpc://127.0.0.1:1"])
            .status
            .code(),
        Some(1)
    );
    for sub in [
        "replay",
        "watch",
        "record",
        "vehicles",
        "health",
        "configure",
        "reset",
        "loadtest",
    ] {
        let out = run(&[sub, "--help"]);
        assert_eq!(out.status.code(), Some(0));
        assert!(stdout(&out).contains("Exit codes"), "{sub}");
    }
    svc.server.shutdown().await.unwrap();
}

/// Writes a short no-camera smoke flight as a dataset with `uavnav simulate`.
fn simulate(dir: &Path, name: &str, duration_s: f64) -> PathBuf {
    let scenario = dir.join("s.toml");
    let text = smoke_text()
        .replace(
            "duration_s = 20.0",
            &format!("duration_s = {duration_s:.1}"),
        )
        .replace("[camera]\nenabled = true", "[camera]\nenabled = false");
    std::fs::write(&scenario, text).unwrap();
    let out_path = dir.join(name);
    let out = run(&[
        "simulate",
        scenario.to_str().unwrap(),
        "--out",
        out_path.to_str().unwrap(),
        "--quiet",
    ]);
    assert_eq!(out.status.code(), Some(0));
    out_path
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn replay_and_watch_end_to_end() {
    let svc = start().await;
    let dir = tempfile::tempdir().unwrap();
    let ds = simulate(dir.path(), "flight", 4.0);
    let csv = dir.path().join("poses.csv");
    let tum = dir.path().join("poses.tum");
    // Watchers first (CSV over gRPC, TUM over Zenoh), then 2 copies replayed at 4x.
    let w1 = tokio::spawn(run_async(vec![
        "watch".into(),
        "--from".into(),
        svc.grpc.clone(),
        "--prefix".into(),
        "rp-".into(),
        "--out".into(),
        csv.display().to_string(),
        "--idle-exit".into(),
        "1.5".into(),
        "--duration".into(),
        "20".into(),
    ]));
    let w2 = tokio::spawn(run_async(vec![
        "watch".into(),
        "--from".into(),
        svc.zenoh.clone(),
        "--vehicle".into(),
        "rp-1".into(),
        "--out".into(),
        tum.display().to_string(),
        "--idle-exit".into(),
        "1.5".into(),
        "--duration".into(),
        "20".into(),
    ]));
    // A Foxglove live view of rp-0 from a watcher, seen by a Foxglove WebSocket client.
    let fox_port = free_port();
    let w3 = tokio::spawn(run_async(vec![
        "watch".into(),
        "--from".into(),
        svc.grpc.clone(),
        "--vehicle".into(),
        "rp-0".into(),
        "--foxglove".into(),
        format!("127.0.0.1:{fox_port}"),
        "--idle-exit".into(),
        "1.5".into(),
        "--duration".into(),
        "20".into(),
    ]));
    let fox = tokio::spawn(foxglove_first_pose(fox_port, "/vehicle/rp-0/pose"));
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let out = run_async(vec![
        "replay".into(),
        ds.display().to_string(),
        "--to".into(),
        svc.grpc.clone(),
        "--speed".into(),
        "4".into(),
        "--vehicles".into(),
        "2".into(),
        "--id-prefix".into(),
        "rp-".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(0));
    assert!(stdout(&out).starts_with("sent "));
    let (o1, o2) = (w1.await.unwrap(), w2.await.unwrap());
    assert_eq!((o1.status.code(), o2.status.code()), (Some(0), Some(0)));
    let o3 = w3.await.unwrap();
    assert_eq!(o3.status.code(), Some(0));
    assert!(
        o3.stdout.is_empty(),
        "with --foxglove and no --out, nothing on stdout"
    );
    let err3 = String::from_utf8_lossy(&o3.stderr);
    assert!(err3.contains("live view showed 1 vehicles"), "{err3}");
    let pose = fox.await.unwrap();
    assert_eq!(pose.frame_id, "ned");
    let p = pose.pose.unwrap().position.unwrap();
    assert!(p.x.is_finite() && p.x.abs() < 1e4, "{p:?}");

    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    assert_eq!(
        header,
        format!("{},vehicle_id", uavnav_estimator::format::csv_header())
    );
    let rows: Vec<&str> = lines.collect();
    let ncol = header.split(',').count();
    assert!(rows.iter().all(|r| r.split(',').count() == ncol));
    for id in ["rp-0", "rp-1"] {
        let n = rows
            .iter()
            .filter(|r| r.ends_with(&format!(",{id}")))
            .count();
        assert!(n > 300, "{n} rows of {id}");
    }
    let tum_lines = std::fs::read_to_string(&tum).unwrap();
    let n_tum = tum_lines.lines().count();
    assert!(n_tum > 300, "{n_tum} TUM lines");
    assert!(tum_lines.lines().all(|l| l.split(' ').count() == 8));
    svc.server.shutdown().await.unwrap();
}

/// Connects to a Foxglove live view (retrying while it starts), subscribes to `topic` once it is
/// advertised and returns the first message on it, decoded.
async fn foxglove_first_pose(port: u16, topic: &str) -> foxglove::messages::PoseInFrame {
    use futures::{SinkExt, StreamExt};
    use prost::Message as _;
    use tokio_tungstenite::tungstenite::{Message, client::IntoClientRequest};
    let mut ws = None;
    for _ in 0..100 {
        let mut req = format!("ws://127.0.0.1:{port}")
            .into_client_request()
            .unwrap();
        req.headers_mut()
            .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
        if let Ok((s, _)) = tokio_tungstenite::connect_async(req).await {
            ws = Some(s);
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let mut ws = ws.expect("the live view accepts connections");
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    while let Ok(Some(Ok(m))) = tokio::time::timeout_at(deadline, ws.next()).await {
        match m {
            Message::Text(t) => {
                let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap();
                if v["op"] != "advertise" {
                    continue;
                }
                for c in v["channels"].as_array().unwrap() {
                    if c["topic"] == topic {
                        let sub = serde_json::json!({"op": "subscribe",
                            "subscriptions": [{"id": 1, "channelId": c["id"]}]});
                        ws.send(Message::Text(sub.to_string().into()))
                            .await
                            .unwrap();
                    }
                }
            }
            Message::Binary(b) if b.first() == Some(&1) && b.len() > 13 => {
                return foxglove::messages::PoseInFrame::decode(&b[13..]).unwrap();
            }
            _ => {}
        }
    }
    panic!("no {topic} message from the live view");
}

/// Poses recorded on `/uavnav/{vehicle}/pose` in an MCAP file: (t_ns, lat, lon, alt).
fn recorded_poses(path: &Path, vehicle: &str) -> Vec<(i64, f64, f64, f64)> {
    use prost::Message;
    let bytes = std::fs::read(path).unwrap();
    let topic = format!("/uavnav/{vehicle}/pose");
    let mut out = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic == topic {
            let p = pb::PoseEstimate::decode(m.data.as_ref()).unwrap();
            let g = p.position.unwrap();
            out.push((p.t_ns, g.latitude_deg, g.longitude_deg, g.altitude_m));
        }
    }
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
    let mut poses_b: Vec<(i64, f64, f64, f64)> = got
        .iter()
        .map(|p| {
            let g = p.position.clone().unwrap();
            (p.t_ns, g.latitude_deg, g.longitude_deg, g.altitude_m)
        })
        .collect();
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
