//! `uavnav record [--from URL] --out fleet.mcap [--duration S] [--idle-exit S]`: everything a
//! service receives and publishes, as MCAP with the `uavnav.v1` schemas, replayable by `replay`.
//!
//! Over Zenoh every key under `uavnav/v1/vehicle/**` is recorded: the inputs any publisher sends
//! (imu, gnss, camera, config) and the service's outputs (pose, health). Over gRPC there is no
//! way to observe other clients' inputs: only poses and health are recorded (a warning says so).

use std::path::{Path, PathBuf};
use std::time::Duration;

use std::collections::BTreeMap;

use uavnav_client::keys::Leaf;
use uavnav_client::{Selector, pb, unix_now_ns};
use uavnav_core::LocalFrame;
use uavnav_dataset::{McapOptions, McapWriter};

use crate::common::{CliError, CliResult};

/// Stands for "no limit" in deadlines (a year; never overflows `Instant`).
const FOREVER: Duration = Duration::from_secs(365 * 86_400);
use crate::endpoint::{DEFAULT_URL, SecurityArgs, block_on, client_err, connect};

/// Arguments of `uavnav record`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// Service URL; Zenoh (zenoh, zenoh/tcp/HOST:PORT, zenoh/tls/HOST:PORT) records inputs and outputs, gRPC outputs only.
    #[arg(long, env = "UAVNAV_SERVICE", default_value = DEFAULT_URL)]
    pub from: String,
    /// TLS and token.
    #[command(flatten)]
    pub security: SecurityArgs,
    /// The MCAP file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Stop after this many seconds (default: until Ctrl-C).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Stop when nothing arrived for this many seconds (after the first message).
    #[arg(long)]
    pub idle_exit: Option<f64>,
}

/// MCAP output of the online commands (poses, health, raw inputs), through the dataset crate's
/// writer so topics and schemas are those of every other uavnav recording.
pub struct McapSink {
    path: PathBuf,
    writer: McapWriter,
    /// Per-vehicle local frame (at its first pose) for the Foxglove display channel.
    frames: BTreeMap<String, LocalFrame>,
}

impl McapSink {
    /// Creates the file.
    pub fn create(path: &Path) -> Result<Self, CliError> {
        let writer =
            McapWriter::create(path, &McapOptions::default()).map_err(CliError::runtime)?;
        Ok(Self {
            path: path.to_path_buf(),
            writer,
            frames: BTreeMap::new(),
        })
    }

    fn err(&self, e: impl std::fmt::Display) -> CliError {
        CliError::runtime(anyhow::anyhow!("{}: {e}", self.path.display()))
    }

    /// Records a pose (log time = now).
    pub fn pose(&mut self, p: &pb::PoseEstimate) -> Result<(), CliError> {
        if !self.frames.contains_key(&p.vehicle_id)
            && let Some(lla) = p
                .position
                .as_ref()
                .and_then(|g| uavnav_core::Lla::try_from(g).ok())
        {
            self.frames
                .insert(p.vehicle_id.clone(), LocalFrame::new(lla));
        }
        let frame = self.frames.get(&p.vehicle_id);
        self.writer
            .write_pose(&p.vehicle_id, p, unix_now_ns(), frame)
            .map_err(CliError::runtime)
    }

    /// Records a health report (log time = now).
    pub fn health(&mut self, h: &pb::VehicleHealth) -> Result<(), CliError> {
        self.writer
            .write_health(&h.vehicle_id, h, unix_now_ns())
            .map_err(CliError::runtime)
    }

    /// Records one raw message of `vehicle_id` on `leaf` (protobuf bytes as received) at
    /// `log_time_ns`, inputs in the service recorder's layout ([`McapWriter::write_input`]).
    /// Undecodable messages, and camera frames without an image, are skipped (the service refuses
    /// them too) and counted by the caller.
    pub fn raw(
        &mut self,
        vehicle_id: &str,
        leaf: Leaf,
        bytes: &[u8],
        log_time_ns: i64,
    ) -> Result<bool, CliError> {
        use prost::Message;
        match leaf {
            Leaf::Pose => {
                return match pb::PoseEstimate::decode(bytes) {
                    Ok(m) => self.pose(&m).map(|()| true),
                    Err(_) => Ok(false),
                };
            }
            Leaf::Health => {
                return match pb::VehicleHealth::decode(bytes) {
                    Ok(m) => self
                        .writer
                        .write_health(vehicle_id, &m, log_time_ns)
                        .map(|()| true)
                        .map_err(|e| self.err(e)),
                    Err(_) => Ok(false),
                };
            }
            _ => {}
        }
        let Some(Ok(input)) = leaf.decode_input(bytes) else {
            return Ok(false);
        };
        if matches!(&input, pb::sensor_envelope::Payload::Camera(f) if f.image.is_none()) {
            return Ok(false);
        }
        self.writer
            .write_input(vehicle_id, (&input).into(), log_time_ns)
            .map(|_| true)
            .map_err(|e| self.err(e))
    }

    /// Finishes the file (summary and index).
    pub fn finish(self) -> Result<(), CliError> {
        self.writer.finish().map_err(CliError::runtime)
    }
}

/// Whether a dataset carries a configuration (MCAP recordings may not).
pub fn has_config(ds: &uavnav_dataset::Dataset) -> bool {
    match ds.format() {
        // A flight log's configuration is derived by the import (rates, noise, GNSS delay).
        uavnav_dataset::Format::Asl | uavnav_dataset::Format::Log => true,
        uavnav_dataset::Format::Mcap => {
            uavnav_dataset::mcap_io::reader::McapDataset::open(ds.path(), Some(ds.vehicle_id()))
                .map(|m| m.has_config())
                .unwrap_or(false)
        }
    }
}

/// Runs the command until Ctrl-C, `--duration` or `--idle-exit`; prints the message count.
pub fn run(args: Args) -> CliResult {
    let mut sink = McapSink::create(&args.out)?;
    block_on(async move {
        let client = connect(&args.from, &args.security).await?;
        let stop = tokio::time::sleep(args.duration.map_or(FOREVER, Duration::from_secs_f64));
        tokio::pin!(stop);
        let idle = args.idle_exit.map(Duration::from_secs_f64);
        let (mut n, mut skipped) = (0u64, 0u64);
        let mut last = tokio::time::Instant::now();
        if let Some(session) = client.zenoh_session() {
            let key = uavnav_client::keys::ALL_VEHICLE_KEYS;
            let sub = session
                .declare_subscriber(key)
                .await
                .map_err(|e| CliError::runtime(anyhow::anyhow!("subscribing to {key}: {e}")))?;
            loop {
                let idle_at = last + idle.unwrap_or(FOREVER);
                tokio::select! {
                    _ = &mut stop => break,
                    _ = tokio::signal::ctrl_c() => break,
                    _ = tokio::time::sleep_until(idle_at), if idle.is_some() && n > 0 => break,
                    s = sub.recv_async() => {
                        let Ok(s) = s else { break };
                        let Some((id, leaf)) = uavnav_client::keys::split(s.key_expr().as_str()) else { continue };
                        if sink.raw(id, leaf, &s.payload().to_bytes(), unix_now_ns())? {
                            n += 1;
                        } else {
                            skipped += 1;
                        }
                        last = tokio::time::Instant::now();
                    }
                }
            }
        } else {
            eprintln!(
                "uavnav: warning: over gRPC only poses and health are recorded (inputs need --from zenoh…)"
            );
            let mut poses = client
                .watch_poses(Selector::all())
                .await
                .map_err(client_err)?;
            let mut health = client
                .watch_health(Selector::all())
                .await
                .map_err(client_err)?;
            loop {
                let idle_at = last + idle.unwrap_or(FOREVER);
                tokio::select! {
                    _ = &mut stop => break,
                    _ = tokio::signal::ctrl_c() => break,
                    _ = tokio::time::sleep_until(idle_at), if idle.is_some() && n > 0 => break,
                    p = poses.next() => match p {
                        Some(Ok(p)) => { sink.pose(&p)?; n += 1; last = tokio::time::Instant::now(); }
                        Some(Err(e)) => return Err(client_err(e)),
                        None => break,
                    },
                    h = health.next() => if let Some(Ok(h)) = h { sink.health(&h)?; n += 1; },
                }
            }
        }
        sink.finish()?;
        if skipped > 0 {
            eprintln!("uavnav: {skipped} undecodable messages skipped");
        }
        println!("recorded {n} messages -> {}", args.out.display());
        client.close().await;
        Ok(())
    })
}
