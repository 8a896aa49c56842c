//! Idle fleet benchmark: what a fleet that sends nothing costs. Not a criterion benchmark: it
//! prints the process's CPU over a quiet interval (`cargo bench -p uavnavd --bench idle_fleet --
//! --vehicles 10000 --quiet-s 30`).
//!
//! An in-process `uavnavd` with its defaults (Zenoh on, on a loopback port; health every second)
//! gets one IMU sample for each of `--vehicles` vehicles over one gRPC stream; after
//! `--settle-s` (the vehicles' last reorder windows flushed, their first reports sent) the
//! process's CPU time (utime + stime from `/proc/self/stat`; the idle client in the same process
//! included) is read over `--quiet-s`. Target: at most 0.05 core for 10,000 vehicles.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::{Duration, Instant};

use uavnav_proto::v1 as pb;
use uavnav_proto::v1::uav_nav_client::UavNavClient;

struct Args {
    vehicles: usize,
    settle_s: f64,
    quiet_s: f64,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        vehicles: 10_000,
        settle_s: 15.0,
        quiet_s: 30.0,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut val = || it.next().ok_or(format!("{arg} needs a value"));
        match arg.as_str() {
            "--bench" => {}
            "--vehicles" => a.vehicles = val()?.parse().map_err(|e| format!("--vehicles: {e}"))?,
            "--settle-s" => a.settle_s = val()?.parse().map_err(|e| format!("--settle-s: {e}"))?,
            "--quiet-s" => a.quiet_s = val()?.parse().map_err(|e| format!("--quiet-s: {e}"))?,
            "--help" | "-h" => {
                return Err("usage: idle_fleet [--vehicles N] [--settle-s S] [--quiet-s S]".into());
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
        uavnav_tests::service::listen_zenoh(&mut cfg);
        let server = uavnavd::Server::start(cfg).await.unwrap();
        let mut client = UavNavClient::connect(format!("http://{}", server.grpc_addr))
            .await
            .unwrap();
        let envs: Vec<_> = (0..args.vehicles)
            .map(|v| pb::SensorEnvelope {
                vehicle_id: format!("idle-{v}"),
                sequence: v as u64,
                payload: Some(pb::sensor_envelope::Payload::Imu(pb::ImuBatch {
                    samples: vec![pb::ImuSample {
                        t_ns: 1_000_000_000,
                        accel_z_mps2: -9.81,
                        ..Default::default()
                    }],
                })),
            })
            .collect();
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
        let (c0, t0, r0) = (
            cpu_s(),
            Instant::now(),
            server.metrics().health_reports.get(),
        );
        tokio::time::sleep(Duration::from_secs_f64(args.quiet_s)).await;
        let (cpu, wall) = (cpu_s() - c0, t0.elapsed().as_secs_f64());
        let reports = server.metrics().health_reports.get() - r0;
        println!(
            "idle fleet: {} vehicles, {:.2} s CPU in {:.1} s = {:.4} core, {:.0} health reports/s",
            args.vehicles,
            cpu,
            wall,
            cpu / wall,
            reports as f64 / wall
        );
        server.shutdown().await.unwrap();
    });
}
