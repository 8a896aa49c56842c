//! `uavnav watch [--from URL] [--vehicle ID…|--prefix P|--all] [--out FILE.csv|FILE.tum|FILE.mcap]`:
//! print or record the poses (and health) a service publishes.
//!
//! CSV (stdout by default): the `uavnav estimate` columns plus `vehicle_id`; the innovation
//! diagnostics columns are 0 because the wire pose does not carry them (they are in the health
//! stream). TUM: one line per pose in a local NED frame at each vehicle's first watched pose
//! (use one `--vehicle`). MCAP: poses and health with the `uavnav.v1` schemas.
//!
//! `--foxglove [HOST:PORT]` serves a Foxglove live view of the watched vehicles (pose, path and,
//! over Zenoh, the GNSS fixes and camera frames their publishers send; over gRPC only the service
//! sees inputs: run `uavnavd --foxglove-addr` for those). With it, poses go to stdout only if
//! `--out` says so.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use uavnav_cli::posefmt;
use uavnav_client::keys::Leaf;
use uavnav_client::{Selector, pb};
use uavnav_core::LocalFrame;
use uavnav_liveview::{LiveTap, LiveView};

use crate::common::{CliError, CliResult};

/// Stands for "no limit" in deadlines (a year; never overflows `Instant`).
const FOREVER: Duration = Duration::from_secs(365 * 86_400);
use crate::endpoint::{DEFAULT_URL, SecurityArgs, block_on, client_err, connect};

/// Arguments of `uavnav watch`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// Service URL (grpc://HOST:PORT, grpcs://HOST:PORT, zenoh, zenoh/tcp/HOST:PORT, zenoh/tls/HOST:PORT).
    #[arg(long, env = "UAVNAV_SERVICE", default_value = DEFAULT_URL)]
    pub from: String,
    /// TLS and token.
    #[command(flatten)]
    pub security: SecurityArgs,
    /// Watch this vehicle (repeatable).
    #[arg(long)]
    pub vehicle: Vec<String>,
    /// Watch vehicles whose id starts with this.
    #[arg(long)]
    pub prefix: Option<String>,
    /// Watch every vehicle (the default when no other selector is given).
    #[arg(long)]
    pub all: bool,
    /// Keep one pose in N per vehicle.
    #[arg(long, default_value_t = 1)]
    pub decimation: u32,
    /// Output file: `.csv`, `.tum` or `.mcap` (default: CSV on stdout; with --foxglove: none).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also watch health (recorded in MCAP; one line per report on stderr otherwise).
    #[arg(long)]
    pub health: bool,
    /// Stop after this many poses.
    #[arg(long)]
    pub count: Option<u64>,
    /// Stop after this many seconds.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Stop when no pose arrived for this many seconds (after the first).
    #[arg(long)]
    pub idle_exit: Option<f64>,
    /// Serve a Foxglove live view (WebSocket) on HOST:PORT [default when given: 127.0.0.1:8765].
    #[arg(long, value_name = "HOST:PORT", num_args = 0..=1, default_missing_value = "127.0.0.1:8765")]
    pub foxglove: Option<String>,
}

/// Where poses go (one per command run: the size difference of the variants does not matter).
#[allow(clippy::large_enum_variant)]
enum Out {
    /// Poses go to the live view only.
    Nowhere,
    Csv(Box<dyn Write + Send>),
    Tum(Box<dyn Write + Send>, BTreeMap<String, LocalFrame>),
    Mcap(crate::record::McapSink),
}

impl Out {
    fn open(path: Option<&PathBuf>) -> Result<Out, CliError> {
        let Some(path) = path else {
            let mut w: Box<dyn Write + Send> = Box::new(std::io::stdout());
            writeln!(w, "{}", posefmt::csv_header()).map_err(CliError::runtime)?;
            return Ok(Out::Csv(w));
        };
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        if ext == "mcap" {
            return Ok(Out::Mcap(crate::record::McapSink::create(path)?));
        }
        if ext != "csv" && ext != "tum" && ext != "txt" {
            return Err(CliError::input(anyhow::anyhow!(
                "--out {}: expected .csv, .tum or .mcap",
                path.display()
            )));
        }
        let f = std::fs::File::create(path)
            .with_context(|| format!("cannot create {}", path.display()))
            .map_err(CliError::runtime)?;
        let mut w: Box<dyn Write + Send> = Box::new(std::io::BufWriter::new(f));
        if ext == "csv" {
            writeln!(w, "{}", posefmt::csv_header()).map_err(CliError::runtime)?;
            Ok(Out::Csv(w))
        } else {
            Ok(Out::Tum(w, BTreeMap::new()))
        }
    }

    fn pose(&mut self, p: &pb::PoseEstimate) -> Result<(), CliError> {
        match self {
            Out::Nowhere => {}
            Out::Csv(w) => {
                if let Some(row) = posefmt::csv_row(p) {
                    writeln!(w, "{row}").map_err(CliError::runtime)?;
                }
            }
            Out::Tum(w, frames) => {
                let Some(lla) = p
                    .position
                    .as_ref()
                    .and_then(|g| uavnav_core::Lla::try_from(g).ok())
                else {
                    return Ok(());
                };
                let frame = frames
                    .entry(p.vehicle_id.clone())
                    .or_insert_with(|| LocalFrame::new(lla));
                if let Some(line) = posefmt::tum_line(p, frame) {
                    writeln!(w, "{line}").map_err(CliError::runtime)?;
                }
            }
            Out::Mcap(m) => m.pose(p)?,
        }
        Ok(())
    }

    fn health(&mut self, h: &pb::VehicleHealth) -> Result<(), CliError> {
        match self {
            Out::Mcap(m) => m.health(h),
            _ => {
                let c = h.counters.unwrap_or_default();
                eprintln!(
                    "health {} mode={} accepted={} rejected={} late={} shed={} dropped={}",
                    h.vehicle_id,
                    crate::endpoint::mode_name(h.mode),
                    c.accepted,
                    c.rejected,
                    c.late,
                    c.shed,
                    c.dropped
                );
                Ok(())
            }
        }
    }

    fn finish(self) -> Result<(), CliError> {
        match self {
            Out::Nowhere => Ok(()),
            Out::Csv(mut w) | Out::Tum(mut w, _) => w.flush().map_err(CliError::runtime),
            Out::Mcap(m) => m.finish(),
        }
    }
}

/// The selector the arguments describe (`--all` when nothing else is given).
fn selector(args: &Args) -> Selector {
    let mut sel = Selector::ids(args.vehicle.clone());
    sel.prefix = args.prefix.clone().unwrap_or_default();
    sel.all = args.all || sel.is_empty();
    sel.with_decimation(args.decimation)
}

/// Runs the command until interrupted, `--count`, `--duration` or `--idle-exit`.
pub fn run(args: Args) -> CliResult {
    let mut out = match (&args.foxglove, &args.out) {
        (Some(_), None) => Out::Nowhere,
        _ => Out::open(args.out.as_ref())?,
    };
    block_on(async move {
        let client = connect(&args.from, &args.security).await?;
        let sel = selector(&args);
        let live = match &args.foxglove {
            Some(addr) => Some(start_live_view(addr, &client, &sel).await?),
            None => None,
        };
        let mut poses = client.watch_poses(sel.clone()).await.map_err(client_err)?;
        let mut health = if args.health {
            Some(
                client
                    .watch_health(sel.with_decimation(1))
                    .await
                    .map_err(client_err)?,
            )
        } else {
            None
        };
        let stop = tokio::time::sleep(args.duration.map_or(FOREVER, Duration::from_secs_f64));
        tokio::pin!(stop);
        let idle = args.idle_exit.map(Duration::from_secs_f64);
        let mut n = 0u64;
        let mut last = tokio::time::Instant::now();
        loop {
            let idle_at = last + idle.unwrap_or(FOREVER);
            tokio::select! {
                _ = &mut stop => break,
                _ = tokio::signal::ctrl_c() => break,
                _ = tokio::time::sleep_until(idle_at), if idle.is_some() && n > 0 => break,
                p = poses.next() => match p {
                    Some(Ok(p)) => {
                        out.pose(&p)?;
                        if let Some(view) = &live {
                            view.tap().pose(p);
                        }
                        n += 1;
                        last = tokio::time::Instant::now();
                        if args.count.is_some_and(|c| n >= c) {
                            break;
                        }
                    }
                    Some(Err(e)) => return Err(client_err(e)),
                    None => break,
                },
                h = async { match health.as_mut() { Some(w) => w.next().await, None => std::future::pending().await } } => {
                    if let Some(Ok(h)) = h {
                        out.health(&h)?;
                    }
                }
            }
        }
        out.finish()?;
        eprintln!("uavnav: {n} poses watched from {}", client.endpoint());
        if let Some(view) = live {
            let dropped = view.tap().dropped();
            let shown = view.stop().await;
            eprintln!(
                "uavnav: live view showed {shown} vehicles ({dropped} messages dropped while it was behind)"
            );
        }
        client.close().await;
        Ok(())
    })
}

/// Starts the live view and, over Zenoh, a task that shows the watched vehicles' GNSS fixes and
/// camera frames as their publishers send them.
async fn start_live_view(
    addr: &str,
    client: &uavnav_client::Client,
    sel: &Selector,
) -> Result<LiveView, CliError> {
    let view = LiveView::start(addr, std::sync::Arc::new(|_| {}))
        .await
        .map_err(|e| CliError::runtime(anyhow::anyhow!("--foxglove: {e}")))?;
    eprintln!(
        "uavnav: Foxglove live view on ws://{}:{} (Foxglove app: Open connection)",
        addr.rsplit_once(':').map_or(addr, |(h, _)| h),
        view.port()
    );
    match client.zenoh_session() {
        Some(session) => {
            let sub = session
                .declare_subscriber(uavnav_client::keys::ALL_VEHICLE_KEYS)
                .await
                .map_err(|e| CliError::runtime(anyhow::anyhow!("subscribing to inputs: {e}")))?;
            let (tap, sel) = (view.tap(), sel.clone());
            tokio::spawn(async move {
                while let Ok(s) = sub.recv_async().await {
                    show_input(&tap, &sel, s.key_expr().as_str(), &s.payload().to_bytes());
                }
            });
        }
        None => eprintln!(
            "uavnav: note: over gRPC the live view shows poses and paths only (GNSS and camera: watch over zenoh, or run uavnavd --foxglove-addr)"
        ),
    }
    Ok(view)
}

/// Shows one Zenoh input sample (GNSS or camera) of a watched vehicle; anything else is ignored.
fn show_input(tap: &LiveTap, sel: &Selector, key: &str, bytes: &[u8]) {
    use prost::Message;
    let Some((id, leaf)) = uavnav_client::keys::split(key) else {
        return;
    };
    if !sel.matches(id) {
        return;
    }
    match leaf {
        Leaf::Gnss => {
            if let Ok(f) = pb::GnssFix::decode(bytes) {
                tap.gnss(id, &f);
            }
        }
        Leaf::Camera => {
            if let Ok(f) = pb::CameraFrame::decode(bytes) {
                tap.camera(id, &f);
            }
        }
        _ => {}
    }
}
