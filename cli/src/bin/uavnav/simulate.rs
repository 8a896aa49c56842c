//! `uavnav simulate SCENARIO.toml --out PATH`: a seeded flight into an ASL folder or an MCAP file.

use std::path::PathBuf;

use anyhow::Context;
use uavnav_core::SensorEvent;
use uavnav_sim::{Flight, Scenario};

use crate::common::{CliError, CliResult, progress};

/// Arguments of `uavnav simulate`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// Scenario file (TOML; see `scenarios/`).
    pub scenario: PathBuf,
    /// Output: an ASL folder, or an MCAP recording when the path ends in `.mcap`.
    #[arg(long)]
    pub out: PathBuf,
    /// Vehicle id written into the dataset.
    #[arg(long, default_value = "sim-0")]
    pub vehicle_id: String,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Loads and validates a scenario file, naming the file in any error.
pub fn load_scenario(path: &std::path::Path) -> Result<Scenario, CliError> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read scenario {}", path.display()))
        .map_err(CliError::input)?;
    Scenario::from_toml_str(&text)
        .map_err(|e| CliError::input(anyhow::anyhow!("{}: {e}", path.display())))
}

/// Runs the command.
pub fn run(args: Args) -> CliResult {
    let started = std::time::Instant::now();
    let scenario = load_scenario(&args.scenario)?;
    let flight = Flight::new(&scenario)
        .map_err(|e| CliError::input(anyhow::anyhow!("{}: {e}", args.scenario.display())))?;
    let total = (flight.imu().len()
        + flight.gnss().len()
        + flight.mag().len()
        + flight.baro().len()
        + flight.camera_times_ns().len()) as u64;
    let bar = progress(total, "simulate");
    if args.quiet {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let mut sink = crate::convert::Sink::create(
        &args.out,
        &args.vehicle_id,
        &flight.vehicle_config(),
        Some(flight.origin()),
    )?;
    for ev in flight.events() {
        let ev: SensorEvent =
            ev.map_err(|e| CliError::runtime(anyhow::anyhow!("simulation failed: {e}")))?;
        sink.write_event(&ev)?;
        bar.inc(1);
    }
    for t in flight.truth() {
        sink.write_truth(t)?;
    }
    sink.finish()?;
    bar.finish_and_clear();
    eprintln!(
        "uavnav: wrote {} ({} IMU, {} GNSS, {} frames) in {:.1} s",
        args.out.display(),
        flight.imu().len(),
        flight.gnss().len(),
        flight.camera_times_ns().len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
