//! `uavnav estimate DATASET`: offline poses at IMU rate from an ASL folder or an MCAP recording.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use uavnav_core::{FilterProfile, SensorEvent, TruthSample};
use uavnav_estimator::format::{csv_header, csv_row, tum_line};
use uavnav_runner::{PoseOutput, RunnerParams, VehicleRunner};

use crate::common::{CliError, CliResult};

/// Arguments of `uavnav estimate`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// An ASL folder (with `mav0/`) or an `.mcap` recording.
    pub dataset: PathBuf,
    /// Filter profile: `eskf` (default) or `paper` (the paper's three EKFs).
    #[arg(long, default_value = "eskf", value_parser = parse_profile)]
    pub profile: FilterProfile,
    /// Do not use the camera.
    #[arg(long)]
    pub no_vision: bool,
    /// Do not use GNSS (inertial, plus vision when present).
    #[arg(long)]
    pub no_gnss: bool,
    /// Output CSV: one row per IMU sample once initialised.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the trajectory in the TUM format (time s, NED position from the first fix, qx qy qz qw).
    #[arg(long)]
    pub tum: Option<PathBuf>,
    /// Where the dataset has truth: write an accuracy table (JSON, Markdown) and PNG plots here.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

fn parse_profile(s: &str) -> Result<FilterProfile, String> {
    s.parse()
}

/// Everything one offline run produced.
#[derive(Debug, Default)]
pub struct RunOutput {
    /// Poses in time order.
    pub poses: Vec<PoseOutput>,
    /// Inputs the estimator refused, with the first reasons.
    pub rejected: u64,
    /// GNSS fix times seen (for outage detection).
    pub gnss_t_ns: Vec<i64>,
    /// The dataset's truth origin, if any (the frame of its truth).
    pub origin: Option<uavnav_core::Lla>,
}

/// Runs one dataset through a [`VehicleRunner`] with vision inline; calls `sink` per pose.
pub fn run_dataset(
    path: &Path,
    profile: FilterProfile,
    use_vision: bool,
    use_gnss: bool,
    mut sink: impl FnMut(&PoseOutput) -> anyhow::Result<()>,
) -> Result<(RunOutput, Option<Vec<TruthSample>>), CliError> {
    let ds = uavnav_dataset::Dataset::open(path).map_err(CliError::input)?;
    let mut config = ds.config().clone();
    config.profile = profile;
    let params = RunnerParams {
        use_vision,
        use_gnss,
        ..RunnerParams::default()
    };
    // The local frame is fixed at the first GNSS fix, exactly as in the service, so that the same
    // input gives the same poses offline and online; the report maps poses into the truth frame.
    let mut runner = VehicleRunner::new(config, params, None);
    let truth = ds.truth().map(|t| t.to_vec());
    let mut out = RunOutput {
        origin: ds.origin(),
        ..RunOutput::default()
    };
    for ev in ds.events().map_err(CliError::input)? {
        let ev = ev.map_err(CliError::input)?;
        if let SensorEvent::Gnss(g) = &ev {
            out.gnss_t_ns.push(g.t_ns);
        }
        match runner.push_inline(ev) {
            Ok(poses) => {
                for p in poses {
                    sink(&p).map_err(CliError::runtime)?;
                    out.poses.push(p);
                }
            }
            Err(e) => {
                out.rejected += 1;
                if out.rejected <= 5 {
                    eprintln!("uavnav: input refused: {e}");
                }
            }
        }
    }
    Ok((out, truth))
}

/// Runs the command.
pub fn run(args: Args) -> CliResult {
    let file = std::fs::File::create(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))
        .map_err(CliError::runtime)?;
    let mut csv = std::io::BufWriter::new(file);
    writeln!(csv, "{}", csv_header()).map_err(|e| CliError::runtime(e))?;
    let mut tum = match &args.tum {
        Some(p) => Some(std::io::BufWriter::new(
            std::fs::File::create(p)
                .with_context(|| format!("cannot create {}", p.display()))
                .map_err(CliError::runtime)?,
        )),
        None => None,
    };
    let started = std::time::Instant::now();
    let (out, truth) = run_dataset(
        &args.dataset,
        args.profile,
        !args.no_vision,
        !args.no_gnss,
        |p| {
            writeln!(csv, "{}", csv_row(p))?;
            if let Some(t) = tum.as_mut() {
                writeln!(t, "{}", tum_line(p))?;
            }
            Ok(())
        },
    )?;
    csv.flush().map_err(CliError::runtime)?;
    if let Some(t) = tum.as_mut() {
        t.flush().map_err(CliError::runtime)?;
    }
    eprintln!(
        "uavnav: {} poses in {:.2} s ({} inputs refused) -> {}",
        out.poses.len(),
        started.elapsed().as_secs_f64(),
        out.rejected,
        args.out.display()
    );
    if let Some(dir) = &args.report {
        let Some(truth) = truth else {
            return Err(CliError::input(anyhow::anyhow!(
                "--report needs truth, and {} has none",
                args.dataset.display()
            )));
        };
        crate::estimate_report::write(dir, &args, &out, &truth)?;
    }
    Ok(())
}
