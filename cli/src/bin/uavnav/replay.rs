//! `uavnav replay DATASET|REC.mcap --to URL [--speed X|--max] [--vehicles N] [--id-prefix P]`:
//! stream a recording into a service at real time (or faster), optionally as N copies under
//! different ids, each starting `--stagger` later than the previous.
//!
//! Each copy reads the recording itself (on a blocking thread, a bounded queue ahead of the
//! sender), so memory stays flat for long recordings with images.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use tokio::sync::mpsc;
use uavnav_cli::schedule::{Batcher, ScheduleParams, TimedMessage};
use uavnav_client::{IngestSender, pb};

use crate::common::{CliError, CliResult};
use crate::endpoint::{DEFAULT_URL, SecurityArgs, block_on, client_err, connect};

/// Arguments of `uavnav replay`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// An ASL folder, an `.mcap` dataset, a fleet recording made by `uavnav record`, or a flight
    /// log (ArduPilot `.BIN`, PX4 `.ulg`, MAVLink `.tlog`; its derived configuration, GNSS delay included, is sent
    /// first).
    pub dataset: PathBuf,
    /// Service URL (grpc://HOST:PORT, grpcs://HOST:PORT, zenoh, zenoh/tcp/HOST:PORT, zenoh/tls/HOST:PORT).
    #[arg(long, env = "UAVNAV_SERVICE", default_value = DEFAULT_URL)]
    pub to: String,
    /// TLS and token.
    #[command(flatten)]
    pub security: SecurityArgs,
    /// Replay speed (1 = real time).
    #[arg(long, default_value_t = 1.0, conflicts_with = "max")]
    pub speed: f64,
    /// As fast as the service accepts (back-pressure only).
    #[arg(long)]
    pub max: bool,
    /// Copies of each recorded vehicle, under ids `{id-prefix}{k}` (or `{vehicle}-{k}` without a prefix).
    #[arg(long, default_value_t = 1)]
    pub vehicles: usize,
    /// Id prefix of the copies (default: the recorded vehicle ids; with copies, `{id}-{k}`).
    #[arg(long)]
    pub id_prefix: Option<String>,
    /// Start offset between copies, s.
    #[arg(long, default_value_t = 0.1)]
    pub stagger: f64,
    /// IMU samples per batch message.
    #[arg(long, default_value_t = 4)]
    pub imu_batch: usize,
    /// Do not send the recorded vehicle configuration first.
    #[arg(long)]
    pub no_config: bool,
    #[command(flatten)]
    pub read: crate::common::ReadArgs,
}

/// Opens a fresh reader of one vehicle's events (called once per copy, on a blocking thread).
pub type OpenEvents = Arc<
    dyn Fn() -> anyhow::Result<
            Box<dyn Iterator<Item = anyhow::Result<uavnav_core::SensorEvent>> + Send>,
        > + Send
        + Sync,
>;

/// One recorded vehicle stream.
pub struct Stream {
    /// Recorded vehicle id.
    pub vehicle_id: String,
    /// Its configuration, sent first.
    pub config: Option<pb::VehicleConfig>,
    /// Opens its events.
    pub open: OpenEvents,
}

/// The vehicle streams of a dataset: one for an ASL folder, one per vehicle of an MCAP recording
/// (a single-vehicle dataset or a fleet recording made by `uavnav record`).
pub fn open_streams(
    path: &std::path::Path,
    read: &uavnav_dataset::ReadOptions,
) -> Result<Vec<Stream>, CliError> {
    use uavnav_dataset::{Dataset, Format, ReadOptions};
    let vehicles: Vec<Option<String>> = match Format::of_path(path) {
        Format::Mcap => uavnav_dataset::mcap_io::reader::vehicles(path)
            .map_err(CliError::input)?
            .into_iter()
            .map(Some)
            .collect(),
        Format::Asl | Format::Log => vec![None],
    };
    let mut out = Vec::new();
    for vehicle in vehicles {
        let options = ReadOptions {
            vehicle: vehicle.clone(),
            ..read.clone()
        };
        let ds = Dataset::open_with(path, &options).map_err(crate::common::open_error)?;
        crate::common::print_notes(&ds);
        let config = crate::record::has_config(&ds).then(|| pb::VehicleConfig::from(ds.config()));
        // Each copy streams from a clone of the opened dataset (a flight log is imported once).
        let opened = ds.clone();
        let open: OpenEvents = Arc::new(move || {
            let events: Box<dyn Iterator<Item = anyhow::Result<uavnav_core::SensorEvent>> + Send> =
                Box::new(opened.events()?.map(|e| e.map_err(anyhow::Error::from)));
            Ok(events)
        });
        out.push(Stream {
            vehicle_id: ds.vehicle_id().to_string(),
            config,
            open,
        });
    }
    if out.is_empty() {
        return Err(CliError::input(anyhow::anyhow!(
            "{}: no vehicle in the recording",
            path.display()
        )));
    }
    Ok(out)
}

/// The id of copy `k` of a recorded vehicle.
fn copy_id(args: &Args, recorded: &str, k: usize) -> String {
    match (&args.id_prefix, args.vehicles) {
        (Some(p), _) => format!("{p}{k}"),
        (None, 1) => recorded.to_string(),
        (None, _) => format!("{recorded}-{k}"),
    }
}

/// Runs the command; prints a summary line `sent N accepted A refused R` on stdout.
pub fn run(args: Args) -> CliResult {
    if !(args.speed > 0.0 && args.speed.is_finite()) {
        return Err(CliError::input(anyhow::anyhow!("--speed must be positive")));
    }
    let streams = open_streams(&args.dataset, &args.read.options())?;
    if args.id_prefix.is_some() && streams.len() > 1 {
        return Err(CliError::input(anyhow::anyhow!(
            "--id-prefix needs a single-vehicle recording ({} vehicles here)",
            streams.len()
        )));
    }
    block_on(async move {
        let client = connect(&args.to, &args.security).await?;
        if client.zenoh_session().is_some() {
            // Let the service's subscriptions reach us before the first put.
            tokio::time::sleep(Duration::from_millis(300)).await;
        }
        let ingest = client.ingest().await.map_err(client_err)?;
        let start = Instant::now() + Duration::from_millis(20);
        let mut tasks = Vec::new();
        let mut k_global = 0usize;
        for s in &streams {
            for k in 0..args.vehicles.max(1) {
                let id = copy_id(&args, &s.vehicle_id, k);
                uavnav_client::error::check_vehicle_id(&id).map_err(CliError::input)?;
                let offset = Duration::from_secs_f64(args.stagger.max(0.0) * k_global as f64);
                k_global += 1;
                let config = if args.no_config { None } else { s.config };
                tasks.push(tokio::spawn(copy(
                    ingest.sender(),
                    id,
                    config,
                    Arc::clone(&s.open),
                    start + offset,
                    if args.max { None } else { Some(args.speed) },
                    args.imu_batch,
                )));
            }
        }
        let mut first_err = None;
        for t in tasks {
            match t.await {
                Ok(Ok(())) => {}
                Ok(Err(e)) => first_err = first_err.or(Some(e)),
                Err(e) => {
                    first_err = first_err.or(Some(CliError::runtime(anyhow::anyhow!(
                        "replay task failed: {e}"
                    ))))
                }
            }
        }
        let stats = ingest.finish(Duration::from_secs(30)).await;
        let sent = stats.sent.load(Ordering::Relaxed);
        let accepted = stats.accepted.load(Ordering::Relaxed);
        println!(
            "sent {sent} accepted {accepted} statuses {:?} errors {:?} in {:.2} s",
            stats.statuses(),
            stats.errors(),
            start.elapsed().as_secs_f64()
        );
        for (reason, n) in stats.permission_denied() {
            eprintln!("uavnav: {n} messages refused (PERMISSION_DENIED): {reason}");
        }
        client.close().await;
        match first_err {
            Some(e) => Err(e),
            None => Ok(()),
        }
    })
}

/// Replays one copy: a blocking reader thread cuts messages, this task sends them on time.
async fn copy(
    sender: IngestSender,
    id: String,
    config: Option<pb::VehicleConfig>,
    open: OpenEvents,
    start: Instant,
    speed: Option<f64>,
    imu_batch: usize,
) -> CliResult {
    let (tx, mut rx) = mpsc::channel::<anyhow::Result<TimedMessage>>(256);
    let reader = tokio::task::spawn_blocking(move || {
        let events = match open() {
            Ok(e) => e,
            Err(e) => {
                let _ = tx.blocking_send(Err(e));
                return;
            }
        };
        let mut b = Batcher::new(ScheduleParams { imu_batch });
        for ev in events {
            let msgs = match ev {
                Ok(ev) => b.push(&ev).into_iter().map(Ok).collect::<Vec<_>>(),
                Err(e) => vec![Err(e)],
            };
            for m in msgs {
                let failed = m.is_err();
                if tx.blocking_send(m).is_err() || failed {
                    return;
                }
            }
        }
        if let Some(m) = b.finish() {
            let _ = tx.blocking_send(Ok(m));
        }
    });
    if let Some(c) = config {
        sender
            .send(&id, pb::sensor_envelope::Payload::Config(c))
            .await
            .map_err(client_err)?;
    }
    while let Some(m) = rx.recv().await {
        let m = m.map_err(CliError::input)?;
        if let Some(speed) = speed {
            let due = start + Duration::from_secs_f64(m.offset_ns.max(0) as f64 * 1e-9 / speed);
            tokio::time::sleep_until(due.into()).await;
        }
        sender.send(&id, m.payload).await.map_err(client_err)?;
    }
    let _ = reader.await;
    Ok(())
}
