//! `uavnav convert SRC --out DST`: ASL folder ↔ MCAP recording (by the `.mcap` extension), and the
//! output sink `simulate` shares.

use std::path::{Path, PathBuf};

use uavnav_core::{Lla, SensorEvent, TruthSample, VehicleConfig};
use uavnav_dataset::{AslWriter, McapOptions, McapWriter};

use crate::common::{CliError, CliResult};

/// Arguments of `uavnav convert`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// Source: an ASL folder (with `mav0/`) or an `.mcap` recording.
    pub src: PathBuf,
    /// Destination: an ASL folder, or an MCAP recording when the path ends in `.mcap`.
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs the command.
pub fn run(args: Args) -> CliResult {
    let started = std::time::Instant::now();
    let s = uavnav_dataset::convert::convert(&args.src, &args.out).map_err(CliError::input)?;
    println!(
        "{} -> {}: {} IMU, {} GNSS, {} frames, {} truth{} in {:.1} s",
        args.src.display(),
        args.out.display(),
        s.imu,
        s.gnss,
        s.frames,
        s.truth,
        if s.skipped_images > 0 {
            format!(" ({} rows without an image skipped)", s.skipped_images)
        } else {
            String::new()
        },
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Where `simulate` writes: an ASL folder or an MCAP recording.
pub enum Sink {
    /// ASL folder.
    Asl(AslWriter),
    /// MCAP recording; truth is interleaved in time order.
    Mcap {
        writer: McapWriter,
        vehicle: String,
        truth: Vec<TruthSample>,
        started: bool,
        config: VehicleConfig,
        origin: Option<Lla>,
    },
}

impl Sink {
    /// Creates the sink chosen by the path's extension.
    pub fn create(
        path: &Path,
        vehicle: &str,
        config: &VehicleConfig,
        origin: Option<Lla>,
    ) -> Result<Self, CliError> {
        if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
        {
            let writer =
                McapWriter::create(path, &McapOptions::default()).map_err(CliError::runtime)?;
            Ok(Sink::Mcap {
                writer,
                vehicle: vehicle.to_string(),
                truth: Vec::new(),
                started: false,
                config: config.clone(),
                origin,
            })
        } else {
            Ok(Sink::Asl(
                AslWriter::create(path, vehicle, config, origin).map_err(CliError::runtime)?,
            ))
        }
    }

    /// Writes one sensor event.
    pub fn write_event(&mut self, ev: &SensorEvent) -> Result<(), CliError> {
        match self {
            Sink::Asl(w) => w.write_event(ev).map_err(CliError::runtime),
            Sink::Mcap {
                writer,
                vehicle,
                started,
                config,
                origin,
                ..
            } => {
                if !*started {
                    writer
                        .write_config(vehicle, config, ev.t_ns())
                        .map_err(CliError::runtime)?;
                    writer
                        .write_info(vehicle, origin.as_ref(), ev.t_ns())
                        .map_err(CliError::runtime)?;
                    *started = true;
                }
                writer
                    .write_event(vehicle, ev, ev.t_ns())
                    .map_err(CliError::runtime)
            }
        }
    }

    /// Writes one truth sample.
    pub fn write_truth(&mut self, s: &TruthSample) -> Result<(), CliError> {
        match self {
            Sink::Asl(w) => w.write_truth(s).map_err(CliError::runtime),
            Sink::Mcap { truth, .. } => {
                truth.push(*s);
                Ok(())
            }
        }
    }

    /// Flushes and closes.
    pub fn finish(self) -> Result<(), CliError> {
        match self {
            Sink::Asl(w) => w.finish().map_err(CliError::runtime),
            Sink::Mcap {
                mut writer,
                vehicle,
                truth,
                ..
            } => {
                for s in &truth {
                    writer
                        .write_truth(&vehicle, s, s.t_ns)
                        .map_err(CliError::runtime)?;
                }
                writer.finish().map_err(CliError::runtime)
            }
        }
    }
}
