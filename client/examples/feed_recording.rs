//! Streams a recording into a running service and prints the poses it estimates, with the client
//! library alone (no other uavnav crate): what a ground-station backend does with `uavnav-client`.
//!
//! ```text
//! cargo run -p uavnav-client --example feed_recording -- REC.mcap [--to URL] [--max | --speed X]
//!     [--vehicle ID] [--id-prefix P] [--every N]
//! ```
//!
//! `REC.mcap` is any uavnav MCAP recording: `uavnav record`, the service's recorder
//! (`uavnavd-NNNNNN.mcap`), or `uavnav simulate`/`convert` with an `.mcap` output. Its inputs
//! (configuration, IMU, GNSS, magnetometer, barometer, camera) are sent at the recorded pace (the
//! MCAP log times; `--speed 2` twice as fast, `--max` as fast as the service accepts) under the
//! recorded vehicle ids (`--id-prefix P`: `P{recorded id}`), while a watch on those vehicles prints
//! one pose in `--every` (default 50: 4 lines a second at 200 Hz IMU). URL defaults to
//! `grpc://127.0.0.1:50051` (`zenoh/tcp/HOST:7447` works the same way).

use std::collections::BTreeMap;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use uavnav_client::recording::{self, RecordedMessage, RecordingReader};
use uavnav_client::{Client, Selector, pb};

const USAGE: &str = "usage: feed_recording REC.mcap [--to URL] [--max | --speed X] \
                     [--vehicle ID] [--id-prefix P] [--every N]";

#[derive(Debug)]
struct Args {
    path: String,
    url: String,
    /// `None` = as fast as accepted.
    speed: Option<f64>,
    vehicle: Option<String>,
    id_prefix: String,
    every: u32,
}

fn parse_args() -> anyhow::Result<Args> {
    let mut args = Args {
        path: String::new(),
        url: "grpc://127.0.0.1:50051".into(),
        speed: Some(1.0),
        vehicle: None,
        id_prefix: String::new(),
        every: 50,
    };
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        let mut value = |name: &str| it.next().with_context(|| format!("{name} needs a value"));
        match a.as_str() {
            "--to" => args.url = value("--to")?,
            "--max" => args.speed = None,
            "--speed" => {
                let s: f64 = value("--speed")?.parse().context("--speed")?;
                if !(s > 0.0 && s.is_finite()) {
                    bail!("--speed must be positive");
                }
                args.speed = Some(s);
            }
            "--vehicle" => args.vehicle = Some(value("--vehicle")?),
            "--id-prefix" => args.id_prefix = value("--id-prefix")?,
            "--every" => args.every = value("--every")?.parse().context("--every")?,
            "-h" | "--help" => {
                println!("{USAGE}");
                std::process::exit(0);
            }
            _ if a.starts_with('-') => bail!("unknown option {a}\n{USAGE}"),
            _ if args.path.is_empty() => args.path = a,
            _ => bail!("one recording only\n{USAGE}"),
        }
    }
    if args.path.is_empty() {
        bail!("{USAGE}");
    }
    Ok(args)
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let args = parse_args()?;
    let mut ids = recording::vehicles(&args.path)?;
    if let Some(v) = &args.vehicle {
        ids.retain(|id| id == v);
    }
    if ids.is_empty() {
        bail!("{}: no vehicle to replay", args.path);
    }
    let sent_ids: Vec<String> = ids
        .iter()
        .map(|id| format!("{}{id}", args.id_prefix))
        .collect();
    println!("replaying {} as {}", args.path, sent_ids.join(", "));

    let client = Client::connect_url(&args.url).await?;
    // Watch first, so that the first poses are not missed.
    let mut poses = client
        .watch_poses(Selector::ids(sent_ids).with_decimation(args.every))
        .await?;
    let (stop, mut stopped) = tokio::sync::oneshot::channel::<()>();
    let printer = tokio::spawn(async move {
        let mut count: BTreeMap<String, u64> = BTreeMap::new();
        loop {
            tokio::select! {
                p = poses.next() => match p {
                    Some(Ok(p)) => {
                        print_pose(&p);
                        *count.entry(p.vehicle_id).or_default() += 1;
                    }
                    Some(Err(e)) => {
                        eprintln!("watch: {e}");
                        break;
                    }
                    None => break,
                },
                _ = &mut stopped => break,
            }
        }
        count
    });
    if client.endpoint().transport() == "Zenoh" {
        // Let the service's subscriptions reach this session before the first put.
        tokio::time::sleep(Duration::from_millis(300)).await;
    }

    // Reading MCAP is blocking file I/O (and decompression): a thread ahead of the sender.
    let (tx, mut rx) = tokio::sync::mpsc::channel::<RecordedMessage>(256);
    let mut reader = RecordingReader::open(&args.path)?;
    if let Some(v) = &args.vehicle {
        reader = reader.vehicle(v.clone());
    }
    let read = tokio::task::spawn_blocking(move || -> anyhow::Result<()> {
        for m in reader {
            if tx.blocking_send(m?).is_err() {
                break;
            }
        }
        Ok(())
    });

    let ingest = client.ingest().await?;
    let start = Instant::now();
    let mut first_log_ns = None;
    while let Some(m) = rx.recv().await {
        if let Some(speed) = args.speed {
            // Due at the recorded pace: the log-time offset from the first message, scaled.
            let t0 = *first_log_ns.get_or_insert(m.log_time_ns);
            let offset = Duration::from_nanos(m.log_time_ns.saturating_sub(t0)).div_f64(speed);
            tokio::time::sleep_until((start + offset).into()).await;
        }
        let id = format!("{}{}", args.id_prefix, m.vehicle_id);
        ingest.send(&id, m.payload).await?;
    }
    read.await??;
    let stats = ingest.finish(Duration::from_secs(10)).await;
    println!(
        "sent {} messages in {:.1} s: {} accepted, statuses {:?}, errors {:?}",
        stats.sent.load(Ordering::Relaxed),
        start.elapsed().as_secs_f64(),
        stats.accepted.load(Ordering::Relaxed),
        stats.statuses(),
        stats.errors()
    );
    // The last poses are estimated after the last input: give them a moment, then stop watching.
    tokio::time::sleep(Duration::from_secs(1)).await;
    let _ = stop.send(());
    let counts = printer.await?;
    for (id, n) in counts {
        println!("{id}: {n} poses printed");
    }
    client.close().await;
    Ok(())
}

fn print_pose(p: &pb::PoseEstimate) {
    let pos = p.position.unwrap_or_default();
    let mode = pb::EstimatorMode::try_from(p.mode)
        .map_or("?", |m| m.as_str_name())
        .trim_start_matches("ESTIMATOR_MODE_");
    println!(
        "{:<12} t {:>8.3} s  lat {:>12.7} lon {:>12.7} alt {:>8.1} m  roll {:>6.1} pitch {:>6.1} yaw {:>6.1} deg  {mode}",
        p.vehicle_id,
        p.t_ns as f64 * 1e-9,
        pos.latitude_deg,
        pos.longitude_deg,
        pos.altitude_m,
        p.roll_rad.to_degrees(),
        p.pitch_rad.to_degrees(),
        p.yaw_rad.to_degrees(),
    );
}
