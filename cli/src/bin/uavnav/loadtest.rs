//! `uavnav loadtest --to URL --vehicles N --duration D [--camera|--no-camera] [--recording R]
//! [--ramp] [--json FILE]`: drive N vehicles at their real rates and measure the service.
//!
//! Each vehicle replays the same stream (by default a simulated smoke flight made in memory; or a
//! recording) under its own id, starting at a staggered offset. Latency is ingest-to-pose from each
//! message's scheduled send time (coordinated-omission correct, HDR histogram); see
//! `uavnav_cli::load`. `--to discard` measures the generator alone. Exit 3 when the service
//! falls behind real time (latency, send lag, or any camera frame shed by the service) or errors
//! pass the threshold; `--ramp` doubles N from `--vehicles` until
//! it falls behind, bisects, and reports the largest N sustained.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use anyhow::Context;
use uavnav_cli::load::{self, Live, LoadOutcome, LoadParams, Recording, Thresholds};
use uavnav_cli::report::Report;
use uavnav_cli::schedule::{self, ScheduleParams};
use uavnav_client::{Client, pb};

use crate::common::{CliError, CliResult, progress};
use crate::endpoint::{DEFAULT_URL, SecurityArgs, block_on_threads, client_err, connect};
use crate::{machine_ref, service_cpu};

/// The built-in flight (the repository's smoke scenario).
const SMOKE_SCENARIO: &str = include_str!("../../../../scenarios/smoke.toml");
/// Longest simulated flight with camera frames (they are rendered; longer runs loop it), s.
const MAX_CAMERA_FLIGHT_S: f64 = 60.0;
/// Longest simulated flight without camera, s.
const MAX_FLIGHT_S: f64 = 900.0;

/// Arguments of `uavnav loadtest`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// Service URL: grpc://HOST:PORT, grpcs://HOST:PORT, zenoh/tcp/HOST:PORT, zenoh/tls/HOST:PORT, or `discard` (the generator alone).
    #[arg(long, env = "UAVNAV_SERVICE", default_value = DEFAULT_URL)]
    pub to: String,
    /// TLS and token.
    #[command(flatten)]
    pub security: SecurityArgs,
    /// Vehicles driven at once (with --ramp: the first stage).
    #[arg(long, default_value_t = 10)]
    pub vehicles: usize,
    /// Send phase length: `30s`, `2m`, `500ms` or seconds.
    #[arg(long, default_value = "10s", value_parser = parse_duration)]
    pub duration: Duration,
    /// Include camera frames (the default).
    #[arg(long, overrides_with = "no_camera")]
    pub camera: bool,
    /// Leave camera frames out.
    #[arg(long)]
    pub no_camera: bool,
    /// Replay this recording (ASL folder, MCAP, or a flight log: ArduPilot `.BIN`, PX4 `.ulg`, MAVLink `.tlog`)
    /// instead of the simulated smoke flight.
    #[arg(long)]
    pub recording: Option<PathBuf>,
    #[command(flatten)]
    pub read: crate::common::ReadArgs,
    /// Find the largest N sustained in real time.
    #[arg(long)]
    pub ramp: bool,
    /// Largest N tried by --ramp.
    #[arg(long, default_value_t = 20_000)]
    pub ramp_max: usize,
    /// Write the report as JSON (ghz-like field names, durations in ns).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Parallel ingest streams.
    #[arg(long, default_value_t = 4)]
    pub streams: usize,
    /// Async worker threads of the generator: 1 (the default) runs it on one thread, with no
    /// cross-thread wake-ups, taking the least CPU from a service on the same machine; 0 = one
    /// per core.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Keep one pose in N per vehicle for the latency measurement.
    #[arg(long, default_value_t = 1)]
    pub decimation: u32,
    /// IMU samples per batch message.
    #[arg(long, default_value_t = 4)]
    pub imu_batch: usize,
    /// Vehicle id prefix (a run tag is appended so runs never collide).
    #[arg(long, default_value = "lt")]
    pub id_prefix: String,
    /// Fell behind when the p99 ingest-to-pose latency exceeds this, ms.
    #[arg(long, default_value_t = 1000.0)]
    pub max_p99_ms: f64,
    /// Fell behind when the p99 send lag exceeds this, ms.
    #[arg(long, default_value_t = 500.0)]
    pub max_send_lag_ms: f64,
    /// Failed when refused + lost messages exceed this fraction.
    #[arg(long, default_value_t = 0.01)]
    pub max_error_rate: f64,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// The service's metrics, http://HOST:PORT/PATH (its side port: `http://127.0.0.1:9464/metrics`
    /// by default): its process CPU and resident memory are read before and after the run and
    /// the CPU per accepted input printed, with the generator's own CPU and, measured before the
    /// load, this machine's speed: the estimator alone for as many vehicles taking messages of
    /// --imu-batch samples in turn (about a second). Plain HTTP, no token; not with --ramp.
    #[arg(long, conflicts_with = "ramp")]
    pub metrics: Option<String>,
}

/// `30s`, `2m`, `500ms`, `1h`, or plain seconds.
pub fn parse_duration(s: &str) -> Result<Duration, String> {
    let s = s.trim();
    let (num, scale) = if let Some(v) = s.strip_suffix("ms") {
        (v, 1e-3)
    } else if let Some(v) = s.strip_suffix('s') {
        (v, 1.0)
    } else if let Some(v) = s.strip_suffix('m') {
        (v, 60.0)
    } else if let Some(v) = s.strip_suffix('h') {
        (v, 3600.0)
    } else {
        (s, 1.0)
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a duration (e.g. 30s, 2m, 500ms)"))?;
    if !v.is_finite() || v <= 0.0 {
        return Err(format!("'{s}': the duration must be positive"));
    }
    Ok(Duration::from_secs_f64(v * scale))
}

/// The stream every vehicle replays.
fn build_recording(args: &Args, camera: bool) -> Result<Recording, CliError> {
    let params = ScheduleParams {
        imu_batch: args.imu_batch.max(1),
    };
    let messages = match &args.recording {
        Some(path) => {
            let ds = uavnav_dataset::Dataset::open_with(path, &args.read.options())
                .map_err(crate::common::open_error)?;
            crate::common::print_notes(&ds);
            let mut config = ds.config().clone();
            if !camera {
                config.camera = None;
            }
            let wire = pb::VehicleConfig::from(&config);
            let mut events = Vec::new();
            for ev in ds.events().map_err(CliError::input)? {
                let ev = ev.map_err(CliError::input)?;
                if camera || !matches!(ev, uavnav_core::SensorEvent::Camera(_)) {
                    events.push(ev);
                }
            }
            schedule::build(Some(&wire), events, &params)
        }
        None => {
            let mut s = uavnav_sim::Scenario::from_toml_str(SMOKE_SCENARIO).map_err(|e| {
                CliError::runtime(anyhow::anyhow!("built-in smoke scenario: {e:?}"))
            })?;
            let cap = if camera {
                MAX_CAMERA_FLIGHT_S
            } else {
                MAX_FLIGHT_S
            };
            s.duration_s = (args.duration.as_secs_f64() + 2.0).clamp(5.0, cap);
            s.camera.enabled = camera;
            let flight = uavnav_sim::Flight::new(&s)
                .map_err(|e| CliError::runtime(anyhow::anyhow!("simulating the flight: {e}")))?;
            let wire = pb::VehicleConfig::from(&flight.vehicle_config());
            let events: Vec<_> = flight
                .events()
                .collect::<Result<_, _>>()
                .map_err(|e| CliError::runtime(anyhow::anyhow!("simulating the flight: {e}")))?;
            schedule::build(Some(&wire), events, &params)
        }
    };
    Recording::new(messages).map_err(CliError::input)
}

/// A short tag unique to this run (vehicle ids must not collide with earlier runs' vehicles).
fn run_tag() -> String {
    let ms = uavnav_client::unix_now_ns() / 1_000_000;
    format!("{:x}", ms & 0xff_ffff)
}

/// Runs one stage with a progress bar.
async fn stage(
    client: &Client,
    rec: &Arc<Recording>,
    args: &Args,
    vehicles: usize,
    prefix: String,
    baseline: Arc<BTreeMap<String, pb::InputCounters>>,
) -> Result<LoadOutcome, CliError> {
    let params = LoadParams {
        vehicles,
        duration: args.duration,
        id_prefix: prefix,
        streams: args.streams,
        decimation: args.decimation,
        baseline,
        ..LoadParams::default()
    };
    let live = Arc::new(Live::default());
    let bar = progress(args.duration.as_millis() as u64, "loadtest");
    if args.quiet {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let ticker = {
        let (bar, live) = (bar.clone(), Arc::clone(&live));
        let started = std::time::Instant::now();
        tokio::spawn(async move {
            loop {
                tokio::time::sleep(Duration::from_millis(200)).await;
                bar.set_position(started.elapsed().as_millis() as u64);
                bar.set_message(format!(
                    "{vehicles} veh, {} sent, {} poses",
                    live.sent.load(Ordering::Relaxed),
                    live.poses.load(Ordering::Relaxed)
                ));
            }
        })
    };
    let out = load::run(client, Arc::clone(rec), params, live).await;
    ticker.abort();
    bar.finish_and_clear();
    out.map_err(client_err)
}

/// Runs the command.
pub fn run(args: Args) -> CliResult {
    if args.vehicles == 0 {
        return Err(CliError::input(anyhow::anyhow!(
            "--vehicles must be at least 1"
        )));
    }
    let camera = !args.no_camera;
    let rec = Arc::new(build_recording(&args, camera)?);
    eprintln!(
        "uavnav: each vehicle replays {} messages per {:.1} s lap (camera {})",
        rec.messages_per_lap(),
        rec.period_ns() as f64 * 1e-9,
        if camera { "on" } else { "off" }
    );
    let thresholds = Thresholds {
        max_p99_latency: Duration::from_secs_f64(args.max_p99_ms / 1e3),
        max_p99_send_lag: Duration::from_secs_f64(args.max_send_lag_ms / 1e3),
        max_error_rate: args.max_error_rate,
    };
    block_on_threads(args.threads, async move {
        let client = connect(&args.to, &args.security).await?;
        let target = client.endpoint().to_string();
        let tag = run_tag();
        if !args.ramp {
            // Before the load, so that the two never share the machine.
            let reference = args.metrics.as_ref().map(|_| {
                machine_ref::measure(SMOKE_SCENARIO, args.vehicles, args.imu_batch)
                    .inspect_err(|e| eprintln!("uavnav: machine reference not measured: {e}"))
            });
            let before = match &args.metrics {
                Some(url) => Some(
                    service_cpu::scrape(url)
                        .await
                        .map_err(|e| CliError::input(anyhow::anyhow!("--metrics: {e}")))?,
                ),
                None => None,
            };
            let started = std::time::Instant::now();
            let generator_before = uavnavd::process::read();
            let o = stage(
                &client,
                &rec,
                &args,
                args.vehicles,
                format!("{}{tag}-", args.id_prefix),
                Arc::default(),
            )
            .await?;
            let wall_s = started.elapsed().as_secs_f64();
            let report = Report::new(&o, &target, camera, &thresholds);
            print!("{}", report.table());
            if let (Some(url), Some(before)) = (&args.metrics, before) {
                match service_cpu::scrape(url).await {
                    Ok(after) => println!(
                        "{}",
                        service_cpu::line(&before, &after, wall_s, report.uavnav.service.accepted)
                    ),
                    Err(e) => eprintln!("uavnav: --metrics after the run: {e}"),
                }
                // The generator's own share of the machine, when both run on it.
                if let (Some(b), Some(a)) = (generator_before, uavnavd::process::read()) {
                    println!("{}", service_cpu::generator_line(b.cpu_s, a.cpu_s, wall_s));
                }
                if let Some(Ok(r)) = &reference {
                    println!("{}", machine_ref::line(r));
                }
            }
            write_json(
                args.json.as_ref(),
                &serde_json::to_value(&report).map_err(CliError::runtime)?,
            )?;
            client.close().await;
            return if report.uavnav.kept_up {
                Ok(())
            } else {
                Err(CliError::Target(report.uavnav.failures.join("; ")))
            };
        }
        let (best, stages) = ramp(&client, &rec, &args, &tag, &target, camera, &thresholds).await?;
        write_json(
            args.json.as_ref(),
            &serde_json::json!({ "sustainedVehicles": best, "camera": camera, "target": target, "stages": stages }),
        )?;
        client.close().await;
        match best {
            Some(n) => {
                println!(
                    "sustained in real time: {n} vehicles (camera {})",
                    if camera { "on" } else { "off" }
                );
                Ok(())
            }
            None => Err(CliError::Target(format!(
                "not even {} vehicles were sustained in real time",
                args.vehicles
            ))),
        }
    })
}

/// Doubling then bisection; returns the largest N that kept up and every stage's report.
async fn ramp(
    client: &Client,
    rec: &Arc<Recording>,
    args: &Args,
    tag: &str,
    target: &str,
    camera: bool,
    t: &Thresholds,
) -> Result<(Option<usize>, Vec<serde_json::Value>), CliError> {
    let (mut lo, mut hi): (Option<usize>, Option<usize>) = (None, None);
    let mut n = args.vehicles;
    let mut stages = Vec::new();
    // Every stage drives the same ids (vehicle `i` of a stage is vehicle `i` of the others), with
    // sensor time going on from where the previous stage stopped: the service sees a fleet whose
    // size changes, not a new fleet per stage (which would fill `vehicles.max_vehicles`).
    let prefix = format!("{}{tag}-", args.id_prefix);
    let stage_ns = (args.duration + Duration::from_secs(2)).as_nanos() as i64;
    // The service's counters of those vehicles so far, so each stage reports only its own.
    let mut counters = BTreeMap::new();
    for k in 0.. {
        let later = Arc::new(rec.later_by(k as i64 * stage_ns));
        let baseline = Arc::new(std::mem::take(&mut counters));
        let o = stage(
            client,
            &later,
            args,
            n,
            prefix.clone(),
            Arc::clone(&baseline),
        )
        .await?;
        counters = Arc::unwrap_or_clone(baseline);
        counters.extend(o.final_counters.clone());
        let report = Report::new(&o, target, camera, t);
        let p99_ms = report
            .latency_distribution
            .iter()
            .find(|p| p.percentage == 99.0)
            .map_or(0.0, |p| p.latency as f64 / 1e6);
        println!(
            "stage {k}: {n:>6} vehicles  {:>10.0} msg/s  p99 {:>9.2} ms  {}",
            report.rps,
            p99_ms,
            if report.uavnav.kept_up {
                "kept up".to_string()
            } else {
                format!("behind: {}", report.uavnav.failures.join("; "))
            }
        );
        let kept_up = report.uavnav.kept_up;
        stages.push(serde_json::to_value(&report).map_err(CliError::runtime)?);
        if kept_up {
            lo = Some(n)
        } else {
            hi = Some(n)
        }
        n = match (lo, hi) {
            (Some(l), None) if l >= args.ramp_max => break,
            (Some(l), None) => (l * 2).min(args.ramp_max),
            (None, Some(_)) => break,
            (Some(l), Some(h)) if h - l <= (l / 10).max(1) => break,
            (Some(l), Some(h)) => l + (h - l) / 2,
            (None, None) => break,
        };
        // Let the service settle (queues drain, previous vehicles go idle) between stages.
        tokio::time::sleep(Duration::from_secs(2)).await;
    }
    Ok((lo, stages))
}

fn write_json(path: Option<&PathBuf>, value: &serde_json::Value) -> CliResult {
    let Some(path) = path else { return Ok(()) };
    let text = serde_json::to_string_pretty(value).map_err(CliError::runtime)?;
    std::fs::write(path, text + "\n")
        .with_context(|| format!("cannot write {}", path.display()))
        .map_err(CliError::runtime)?;
    Ok(())
}
