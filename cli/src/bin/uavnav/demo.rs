//! `uavnav demo`: the main job on a fresh machine, with nothing to start by hand.
//!
//! Starts an in-process `uavnavd` (gRPC and an embedded Zenoh peer on loopback), simulates a short
//! flight, streams it in twice at `--speed` times real time — as vehicle `demo-grpc` over gRPC and as `demo-zenoh` over Zenoh —,
//! watches the poses over gRPC, runs the same data offline (what `uavnav estimate` does), and
//! prints an accuracy table against the simulator's truth plus the largest difference between the
//! service's poses and the offline ones (zero: the service is deterministic).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context;
use nalgebra::Vector3;
use uavnav_cli::{posefmt, schedule};
use uavnav_client::{Client, Selector, pb};
use uavnav_core::{LocalFrame, SensorEvent, TruthSample};
use uavnav_report::accuracy::{attitude_rmse, truth_at};
use uavnav_runner::{PoseOutput, RunnerParams, VehicleRunner};
use uavnav_sim::{Flight, Scenario};
use uavnavd::runner_engine::pose_to_wire;

use crate::common::{CliError, CliResult};

const SMOKE: &str = include_str!("../../../../scenarios/smoke.toml");
const VEHICLES: [&str; 2] = ["demo-grpc", "demo-zenoh"];

/// Arguments of `uavnav demo`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// Scenario to fly (default: the built-in 20 s smoke flight, `scenarios/smoke.toml`).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Give up waiting for the service's poses after this many seconds.
    #[arg(long, default_value_t = 120.0)]
    pub timeout_s: f64,
    /// Feed speed (1 = real time). The service sheds camera frames when it is fed faster than it
    /// can run vision (an overload, counted in health); the default stays well inside its budget.
    #[arg(long, default_value_t = 2.0)]
    pub speed: f64,
}

/// Runs the command.
pub fn run(args: Args) -> CliResult {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    rt.block_on(demo(args))
}

async fn demo(args: Args) -> CliResult {
    if !(args.speed > 0.0 && args.speed.is_finite()) {
        return Err(CliError::input(anyhow::anyhow!(
            "--speed must be a positive number, not {}",
            args.speed
        )));
    }
    let scenario = match &args.scenario {
        Some(p) => crate::simulate::load_scenario(p)?,
        None => Scenario::from_toml_str(SMOKE)
            .map_err(|e| CliError::input(anyhow::anyhow!("smoke scenario: {e}")))?,
    };
    let started = Instant::now();
    let flight = Flight::new(&scenario).map_err(|e| CliError::input(anyhow::anyhow!("{e}")))?;
    let events: Vec<SensorEvent> = flight
        .events()
        .collect::<Result<_, _>>()
        .map_err(|e| CliError::runtime(anyhow::anyhow!("simulation failed: {e}")))?;
    eprintln!(
        "demo: simulated {:.0} s flight ({} events) in {:.1} s",
        scenario.duration_s,
        events.len(),
        started.elapsed().as_secs_f64()
    );

    let zenoh_port = free_port()?;
    let server = uavnavd::Server::start(service_config(zenoh_port))
        .await
        .context("starting uavnavd")?;
    eprintln!(
        "demo: uavnavd on grpc://{} (HTTP {}), Zenoh tcp/127.0.0.1:{zenoh_port}",
        server.grpc_addr, server.http_addr
    );
    let grpc = Client::connect_url(&format!("grpc://{}", server.grpc_addr))
        .await
        .context("gRPC client")?;
    let zenoh = Client::connect_url(&format!("zenoh/tcp/127.0.0.1:{zenoh_port}"))
        .await
        .context("Zenoh client")?;
    let mut watch = grpc
        .watch_poses(Selector::prefix("demo-"))
        .await
        .context("watching poses")?;
    tokio::time::sleep(Duration::from_millis(300)).await; // let the subscription settle

    let config = flight.vehicle_config();
    let wire_config = pb::VehicleConfig::from(&config);
    let messages = schedule::build(
        Some(&wire_config),
        events.iter().cloned(),
        &schedule::ScheduleParams::default(),
    );
    let feeds = [(grpc, VEHICLES[0]), (zenoh, VEHICLES[1])].map(|(client, id)| {
        let msgs = messages.clone();
        let speed = args.speed;
        tokio::spawn(async move { feed(client, id, msgs, speed).await })
    });
    let last_imu_t = events
        .iter()
        .rev()
        .find_map(|e| matches!(e, SensorEvent::Imu(_)).then(|| e.t_ns()))
        .unwrap_or(0);
    let received = collect(
        &mut watch,
        last_imu_t,
        Duration::from_secs_f64(args.timeout_s),
    )
    .await;
    for f in feeds {
        f.await
            .context("feeding task")?
            .map_err(CliError::runtime)?;
    }
    server.shutdown().await.context("stopping uavnavd")?;

    let offline = offline_run(&config, &events);
    print_table(&flight, &received, &offline);
    let ok = VEHICLES
        .iter()
        .all(|v| received.get(*v).is_some_and(|p| !p.is_empty()));
    if !ok {
        return Err(CliError::Target(
            "some vehicle produced no pose through the service".into(),
        ));
    }
    eprintln!("demo: done in {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}

fn service_config(zenoh_port: u16) -> uavnavd::Config {
    let mut c = uavnavd::Config::default();
    c.grpc.addr = ([127, 0, 0, 1], 0).into();
    c.http.addr = ([127, 0, 0, 1], 0).into();
    c.zenoh.listen = vec![format!("tcp/127.0.0.1:{zenoh_port}")];
    c.zenoh.multicast_scouting = false;
    c.zenoh.instance = format!("demo-{zenoh_port}");
    c
}

fn free_port() -> Result<u16, CliError> {
    let l = std::net::TcpListener::bind("127.0.0.1:0").context("finding a free port")?;
    Ok(l.local_addr().context("finding a free port")?.port())
}

async fn feed(
    client: Client,
    id: &'static str,
    msgs: Vec<schedule::TimedMessage>,
    speed: f64,
) -> anyhow::Result<()> {
    let ingest = client
        .ingest()
        .await
        .with_context(|| format!("opening the ingest stream for {id}"))?;
    let start = tokio::time::Instant::now();
    for m in msgs {
        let due = Duration::from_secs_f64(m.offset_ns.max(0) as f64 * 1e-9 / speed);
        tokio::time::sleep_until(start + due).await;
        ingest
            .send(id, m.payload)
            .await
            .with_context(|| format!("sending {id}'s data"))?;
    }
    let stats = ingest.finish(Duration::from_secs(30)).await;
    let sent = stats.sent.load(std::sync::atomic::Ordering::Relaxed);
    let accepted = stats.accepted.load(std::sync::atomic::Ordering::Relaxed);
    eprintln!("demo: {id}: {sent} messages sent, {accepted} accepted");
    let errors = stats.errors();
    if !errors.is_empty() {
        eprintln!("demo: {id}: errors: {errors:?}");
    }
    client.close().await;
    Ok(())
}

/// Poses per vehicle until every vehicle reached `last_t_ns` or the time is up.
async fn collect(
    watch: &mut uavnav_client::Watch<pb::PoseEstimate>,
    last_t_ns: i64,
    timeout: Duration,
) -> BTreeMap<String, Vec<pb::PoseEstimate>> {
    let mut got: BTreeMap<String, Vec<pb::PoseEstimate>> = BTreeMap::new();
    let done = |g: &BTreeMap<String, Vec<pb::PoseEstimate>>| {
        VEHICLES.iter().all(|v| {
            g.get(*v)
                .and_then(|p| p.last())
                .is_some_and(|p| p.t_ns >= last_t_ns)
        })
    };
    let deadline = tokio::time::Instant::now() + timeout;
    while !done(&got) {
        match tokio::time::timeout_at(deadline, watch.next()).await {
            Ok(Some(Ok(p))) => got.entry(p.vehicle_id.clone()).or_default().push(p),
            Ok(Some(Err(e))) => eprintln!("demo: watch: {e}"),
            Ok(None) | Err(_) => {
                eprintln!("demo: stopped waiting for poses");
                break;
            }
        }
    }
    got
}

fn offline_run(config: &uavnav_core::VehicleConfig, events: &[SensorEvent]) -> Vec<PoseOutput> {
    let mut runner = VehicleRunner::new(config.clone(), RunnerParams::default(), None);
    events
        .iter()
        .filter_map(|e| runner.push_inline(e.clone()).ok())
        .flatten()
        .collect()
}

struct Row {
    label: String,
    poses: usize,
    att_rmse_deg: Option<Vector3<f64>>,
    pos_rmse_m: f64,
    max_diff_offline: Option<f64>,
}

fn row(
    label: &str,
    outputs: &[PoseOutput],
    truth: &[TruthSample],
    from_ns: i64,
    offline: Option<&BTreeMap<i64, pb::PoseEstimate>>,
    wire: Option<&[pb::PoseEstimate]>,
) -> Row {
    let mut se = 0.0;
    let mut n = 0usize;
    for o in outputs.iter().filter(|o| o.t_ns >= from_ns) {
        if let Some(t) = truth_at(truth, o.t_ns) {
            se += (o.pos_ned_m - t.pos_ned_m).norm_squared();
            n += 1;
        }
    }
    let max_diff_offline = match (offline, wire) {
        (Some(off), Some(w)) => Some(
            w.iter()
                .map(|p| wire_diff(p, off.get(&p.t_ns)))
                .fold(0.0, f64::max),
        ),
        _ => None,
    };
    Row {
        label: label.to_string(),
        poses: outputs.len(),
        att_rmse_deg: attitude_rmse(outputs, truth, from_ns).map(|v| v.map(f64::to_degrees)),
        pos_rmse_m: if n > 0 {
            (se / n as f64).sqrt()
        } else {
            f64::NAN
        },
        max_diff_offline,
    }
}

/// Largest absolute difference between two wire poses' numbers (∞ when the offline one is missing).
fn wire_diff(a: &pb::PoseEstimate, b: Option<&pb::PoseEstimate>) -> f64 {
    let Some(b) = b else { return f64::INFINITY };
    let mut a = a.clone();
    a.vehicle_id.clear();
    a.ingest_wall_ns = 0;
    if &a == b {
        0.0
    } else {
        f64::INFINITY.min(pose_gap(&a, b))
    }
}

fn pose_gap(a: &pb::PoseEstimate, b: &pb::PoseEstimate) -> f64 {
    let (pa, pb_) = (a.position.as_ref(), b.position.as_ref());
    match (pa, pb_) {
        (Some(x), Some(y)) => ((x.latitude_deg - y.latitude_deg).abs() * 1.1e5)
            .max((x.longitude_deg - y.longitude_deg).abs() * 1.1e5)
            .max((x.altitude_m - y.altitude_m).abs())
            .max((a.roll_rad - b.roll_rad).abs())
            .max((a.yaw_rad - b.yaw_rad).abs()),
        _ => f64::INFINITY,
    }
}

fn print_table(
    flight: &Flight,
    received: &BTreeMap<String, Vec<pb::PoseEstimate>>,
    offline: &[PoseOutput],
) {
    let frame = LocalFrame::new(flight.origin());
    let truth = flight.truth();
    let from_ns = truth.first().map_or(0, |t| t.t_ns) + 5_000_000_000;
    let in_frame = |p: &PoseOutput| PoseOutput {
        pos_ned_m: frame.lla_to_ned(&p.lla),
        ..*p
    };
    let offline_out: Vec<PoseOutput> = offline.iter().map(in_frame).collect();
    let offline_wire: BTreeMap<i64, pb::PoseEstimate> =
        offline.iter().map(|p| (p.t_ns, pose_to_wire(p))).collect();
    let mut rows = vec![row(
        "offline (uavnav estimate)",
        &offline_out,
        truth,
        from_ns,
        None,
        None,
    )];
    for v in VEHICLES {
        let wire = received.get(v).map(Vec::as_slice).unwrap_or(&[]);
        let outs: Vec<PoseOutput> = wire
            .iter()
            .filter_map(|p| posefmt::to_output(p, Some(&frame)))
            .collect();
        let transport = if v.ends_with("grpc") { "gRPC" } else { "Zenoh" };
        rows.push(row(
            &format!("{v} via {transport}"),
            &outs,
            truth,
            from_ns,
            Some(&offline_wire),
            Some(wire),
        ));
    }
    // The sources the offline run fused (its estimator's counters), not the ones configured.
    let fused: Vec<&str> = std::iter::once("IMU")
        .chain(
            crate::estimate_report::fused_sources(offline.last().map(|p| &p.health))
                .into_iter()
                .filter_map(|(name, fused)| fused.then_some(name)),
        )
        .collect();
    println!(
        "Accuracy against the simulator's truth (after the first 5 s; eskf, {}):",
        fused.join("+")
    );
    println!(
        "| run | poses | roll RMSE ° | pitch RMSE ° | yaw RMSE ° | position RMSE m | max diff vs offline |"
    );
    println!("|---|---|---|---|---|---|---|");
    for r in rows {
        let (ro, pi, ya) = r
            .att_rmse_deg
            .map_or((f64::NAN, f64::NAN, f64::NAN), |v| (v.x, v.y, v.z));
        let diff = r.max_diff_offline.map_or("–".to_string(), |d| {
            if d == 0.0 {
                "0 (identical)".into()
            } else {
                format!("{d:.3e}")
            }
        });
        println!(
            "| {} | {} | {ro:.3} | {pi:.3} | {ya:.3} | {:.2} | {diff} |",
            r.label, r.poses, r.pos_rmse_m
        );
    }
}
