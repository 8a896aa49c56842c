//! `uavnav convert SRC --out DST`: ASL folder ↔ MCAP recording (by the `.mcap` extension), a
//! flight log (ArduPilot `.BIN`, PX4 `.ulg`, MAVLink `.tlog`) into either, and the output sink
//! `simulate` shares.

use std::path::{Path, PathBuf};

use uavnav_core::{Lla, SensorEvent, TruthSample, VehicleConfig};
use uavnav_dataset::{AslWriter, McapOptions, McapWriter};

use crate::common::{CliError, CliResult};

/// Arguments of `uavnav convert`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// Source: an ASL folder (with `mav0/`), an `.mcap` recording, or a flight log (ArduPilot
    /// DataFlash `.BIN`, PX4 ULog `.ulg`, MAVLink telemetry `.tlog`; also recognised by its first
    /// bytes). A log's autopilot
    /// estimate is written as a reference (ASL: state_groundtruth_estimate0 marked "NOT ground
    /// truth"; MCAP: the `reference` topic), never as truth.
    pub src: PathBuf,
    /// Destination: an ASL folder, or an MCAP recording when the path ends in `.mcap`.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub read: crate::common::ReadArgs,
}

/// Runs the command.
pub fn run(args: Args) -> CliResult {
    let started = std::time::Instant::now();
    if uavnav_dataset::Format::of_path(&args.out) == uavnav_dataset::Format::Log {
        return Err(CliError::input(anyhow::anyhow!(
            "{}: flight logs are read, not written: give an ASL folder or an .mcap file",
            args.out.display()
        )));
    }
    let options = args.read.options();
    let ds = uavnav_dataset::Dataset::open_with(&args.src, &options)
        .map_err(crate::common::open_error)?;
    crate::common::print_notes(&ds);
    let s = match uavnav_dataset::Format::of_path(&args.out) {
        uavnav_dataset::Format::Mcap => {
            uavnav_dataset::convert::write_mcap(&ds, &args.out, &McapOptions::default())
        }
        _ => uavnav_dataset::convert::write_asl(&ds, &args.out),
    }
    .map_err(CliError::input)?;
    let reference = match (s.reference, ds.reference()) {
        (n, Some(r)) if n > 0 => format!(", {n} {}", r.label()),
        _ => String::new(),
    };
    println!(
        "{} -> {}: {} IMU, {} GNSS, {} mag, {} baro, {} frames, {} truth{reference}{} in {:.1} s",
        args.src.display(),
        args.out.display(),
        s.imu,
        s.gnss,
        s.mag,
        s.baro,
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

/// Where `simulate` writes: an ASL folder or an MCAP recording (one per run).
#[allow(clippy::large_enum_variant)]
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
