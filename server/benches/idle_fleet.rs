//! Idle fleet benchmark: what a fleet that sends nothing costs. Not a criterion benchmark: it
//! prints the process's CPU over a quiet interval (`cargo bench -p uavnavd --bench idle_fleet --
//! --vehicles 10000 --quiet-s 30`).
//!
//! An in-process `uavnavd` with its defaults (Zenoh on, on a loopback port; health every second)
//! gets one IMU sample for each of `--vehicles` vehicles over one gRPC stream; after
//! `--settle-s` (the vehicles' last reorder windows flushed, their first reports sent) the
//! process's CPU time (utime + stime from `/proc/self/stat`; the idle client in the same process
//! included) is read over `--quiet-s`. Target: at most 0.05 core for 10,000 vehicles.
//!
//! `--configure` sends each vehicle a configuration first. `--watch LEAF` adds what a sender's
//! keeper does: a Zenoh peer subscribed to one vehicle's `LEAF` (`health`, or `unconfigured`,
//! which the client library's keeper uses), which makes the service publish that leaf for the
//! fleet whenever its reports are due (a quiet vehicle's repeats within
//! `zenoh.repeat_health_per_s`, which `--repeat-health-per-s R` sets; the figure printed after
//! the rate is how many were held back).
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::{Duration, Instant};

use uavnav_proto::v1 as pb;
use uavnav_proto::v1::uav_nav_client::UavNavClient;

struct Args {
    vehicles: usize,
    settle_s: f64,
    quiet_s: f64,
    configure: bool,
    watch: Option<uavnav_proto::keys::Leaf>,
    repeat_health_per_s: Option<f64>,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        vehicles: 10_000,
        settle_s: 15.0,
        quiet_s: 30.0,
        configure: false,
        watch: None,
        repeat_health_per_s: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut val = || it.next().ok_or(format!("{arg} needs a value"));
        match arg.as_str() {
            "--bench" => {}
            "--vehicles" => a.vehicles = val()?.parse().map_err(|e| format!("--vehicles: {e}"))?,
            "--settle-s" => a.settle_s = val()?.parse().map_err(|e| format!("--settle-s: {e}"))?,
            "--quiet-s" => a.quiet_s = val()?.parse().map_err(|e| format!("--quiet-s: {e}"))?,
            "--configure" => a.configure = true,
            "--repeat-health-per-s" => {
                a.repeat_health_per_s = Some(
                    val()?
                        .parse()
                        .map_err(|e| format!("--repeat-health-per-s: {e}"))?,
                );
            }
            "--watch" => {
                let leaf = val()?;
                a.watch = Some(
                    uavnav_proto::keys::Leaf::parse(&leaf)
                        .filter(|l| !l.is_input())
                        .ok_or(format!("--watch: {leaf} is not an output leaf"))?,
                );
            }
            "--help" | "-h" => {
                return Err(
                    "usage: idle_fleet [--vehicles N] [--settle-s S] [--quiet-s S] \
                     [--configure] [--watch health|unconfigured|pose] [--repeat-health-per-s R]"
                        .into(),
                );
            }
            other => return Err(format!("unknown argument {other}")),
        }
    }
    Ok(a)
}

/// CPU seconds of this process so far (user + system).
fn cpu_s() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // The fields after the command name (which may hold spaces) start after the last ')'.
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .map(|(_, rest)| rest.split_whitespace().collect())
        .unwrap_or_default();
    // utime and stime are fields 14 and 15 of the whole line: 12 and 13 after the name.
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|f| f.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    (ticks(11) + ticks(12)) / 100.0
}

fn main() {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async move {
        let mut cfg = uavnav_tests::service::loopback_config();
        let endpoint = uavnav_tests::service::listen_zenoh(&mut cfg);
        if let Some(r) = args.repeat_health_per_s {
            cfg.zenoh.repeat_health_per_s = r;
        }
        let server = uavnavd::Server::start(cfg).await.unwrap();
        let mut client = UavNavClient::connect(format!("http://{}", server.grpc_addr))
            .await
            .unwrap();
        let mut envs = Vec::new();
        for v in 0..args.vehicles {
            let vehicle_id = format!("idle-{v}");
            if args.configure {
                envs.push(pb::SensorEnvelope {
                    vehicle_id: vehicle_id.clone(),
                    sequence: envs.len() as u64,
                    payload: Some(pb::sensor_envelope::Payload::Config(
                        uavnav_tests::wire::vehicle_config(false),
                    )),
                });
            }
            envs.push(pb::SensorEnvelope {
                vehicle_id,
                sequence: envs.len() as u64,
                payload: Some(pb::sensor_envelope::Payload::Imu(pb::ImuBatch {
                    samples: vec![pb::ImuSample {
                        t_ns: 1_000_000_000,
                        accel_z_mps2: -9.81,
                        ..Default::default()
                    }],
                })),
            });
        }
        // The keeper of one vehicle (kept open for the whole run).
        let mut watcher = None;
        if let Some(leaf) = args.watch {
            let mut zc = zenoh::Config::default();
            zc.insert_json5("mode", "\"peer\"").unwrap();
            zc.insert_json5("listen/endpoints", "[]").unwrap();
            zc.insert_json5("connect/endpoints", &format!("[\"{endpoint}\"]"))
                .unwrap();
            zc.insert_json5("scouting/multicast/enabled", "false")
                .unwrap();
            let z = zenoh::open(zc).await.unwrap();
            let key = uavnav_proto::keys::vehicle_key("idle-0", leaf);
            let sub = z.declare_subscriber(key).await.unwrap();
            watcher = Some((z, sub));
        }
        let n = envs.len();
        let mut acks = client
            .ingest(futures::stream::iter(envs))
            .await
            .unwrap()
            .into_inner();
        let mut got = 0;
        while got < n && acks.message().await.unwrap().is_some() {
            got += 1;
        }
        assert_eq!(server.metrics().vehicles.get() as usize, args.vehicles);
        tokio::time::sleep(Duration::from_secs_f64(args.settle_s)).await;
        let skipped = || server.metrics().zenoh_health_repeats_skipped.get();
        let (c0, t0, r0, s0) = (
            cpu_s(),
            Instant::now(),
            server.metrics().health_reports.get(),
            skipped(),
        );
        tokio::time::sleep(Duration::from_secs_f64(args.quiet_s)).await;
        let (cpu, wall) = (cpu_s() - c0, t0.elapsed().as_secs_f64());
        let reports = server.metrics().health_reports.get() - r0;
        let skipped = skipped() - s0;
        let received = watcher.as_ref().map_or(0, |(_, s)| s.drain().count());
        println!(
            "idle fleet: {} vehicles{}{}, {:.2} s CPU in {:.1} s = {:.4} core, {:.0} health reports/s \
             ({:.0}/s repeats not published on Zenoh), {received} samples for the watched vehicle",
            args.vehicles,
            if args.configure { ", configured" } else { "" },
            args.watch.map(|l| format!(", one vehicle's {} watched", l.as_str())).unwrap_or_default(),
            cpu,
            wall,
            cpu / wall,
            reports as f64 / wall,
            skipped as f64 / wall
        );
        server.shutdown().await.unwrap();
    });
}
