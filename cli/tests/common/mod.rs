//! Shared by the CLI's end-to-end tests: an in-process `uavnavd` (gRPC and HTTP on port 0,
//! Zenoh listening on an explicit localhost port with multicast scouting off), simulated flights,
//! and running the `uavnav` binary.
#![allow(dead_code)] // each test file uses a different part

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use uavnav_cli::schedule::{self, ScheduleParams, TimedMessage};
use uavnav_client::{Client, pb};

pub const BIN: &str = env!("CARGO_BIN_EXE_uavnav");

#[allow(unused_imports)] // each test file uses a different part
pub use uavnav_tests::net::free_port;
#[allow(unused_imports)]
pub use uavnav_tests::service::{Svc, smoke_text, start};

/// A short smoke flight without camera: its wire configuration and its schedule.
pub fn flight(duration_s: f64) -> (pb::VehicleConfig, Vec<TimedMessage>) {
    let mut s = uavnav_sim::Scenario::from_toml_str(&smoke_text()).unwrap();
    s.duration_s = duration_s;
    s.camera.enabled = false;
    let f = uavnav_sim::Flight::new(&s).unwrap();
    let config = pb::VehicleConfig::from(&f.vehicle_config());
    let events: Vec<_> = f.events().collect::<Result<_, _>>().unwrap();
    let msgs = schedule::build(Some(&config), events, &ScheduleParams::default());
    (config, msgs)
}

pub fn run(args: &[&str]) -> Output {
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

pub async fn run_async(args: Vec<String>) -> Output {
    tokio::task::spawn_blocking(move || run(&args.iter().map(String::as_str).collect::<Vec<_>>()))
        .await
        .unwrap()
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Feeds a schedule for `id` as fast as the service accepts.
pub async fn feed(client: &Client, id: &str, msgs: &[TimedMessage]) {
    let ingest = client.ingest().await.unwrap();
    for m in msgs {
        ingest.send(id, m.payload.clone()).await.unwrap();
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

/// Writes a short no-camera smoke flight as a dataset with `uavnav simulate`.
pub fn simulate(dir: &Path, name: &str, duration_s: f64) -> PathBuf {
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
