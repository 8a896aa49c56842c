//! `uavnav estimate DATASET`: offline poses at IMU rate from an ASL folder, an MCAP recording or
//! a flight log.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use uavnav_core::{FilterProfile, Lla, LocalFrame, SensorEvent, TruthSample};
use uavnav_dataset::poses::{csv_header, csv_row, tum_line};
use uavnav_report::reference::{FixNed, ScreenParams, screen};
use uavnav_runner::{PoseOutput, RunnerParams, VehicleRunner};

use crate::common::{CliError, CliResult};

/// Arguments of `uavnav estimate`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// An ASL folder (with `mav0/`), an `.mcap` recording, or a flight log (ArduPilot DataFlash
    /// `.BIN`, PX4 ULog `.ulg`, MAVLink telemetry `.tlog`).
    pub dataset: PathBuf,
    /// Filter profile: `eskf` (default) or `paper` (the paper's three EKFs).
    #[arg(long, default_value = "eskf", value_parser = parse_profile)]
    pub profile: FilterProfile,
    /// Do not use the camera.
    #[arg(long)]
    pub no_vision: bool,
    /// Do not use GNSS. Both profiles then start once level and report attitude only (mode
    /// `attitude_only`: the position, velocity and position-σ columns are empty); `paper` has no
    /// heading then (it reads no compass).
    #[arg(long)]
    pub no_gnss: bool,
    /// Do not use the magnetometer (the heading then comes from the yaw-hypothesis bank).
    #[arg(long)]
    pub no_mag: bool,
    /// Do not use the barometer.
    #[arg(long)]
    pub no_baro: bool,
    /// Output CSV: one row per IMU sample once initialised.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the trajectory in the TUM format (time s, NED position from the first fix, qx qy qz qw).
    #[arg(long)]
    pub tum: Option<PathBuf>,
    /// Write an accuracy table (JSON, Markdown) and PNG plots here, scored against the dataset's
    /// truth or, without truth, against its reference (a flight log's autopilot estimate, named
    /// as such and never called truth). Each run is labelled with the sources it fused.
    #[arg(long)]
    pub report: Option<PathBuf>,
    #[command(flatten)]
    pub read: crate::common::ReadArgs,
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
    /// The dataset's truth origin, if any (the frame of its truth or reference).
    pub origin: Option<uavnav_core::Lla>,
    /// Inputs the estimator accepted, per sensor.
    pub fed: Fed,
    /// The reader's notes (a flight log's import notes).
    pub notes: Vec<String>,
    /// The GNSS delay the dataset states, and the GNSS velocity's delay the estimator ended
    /// with (`eskf` learns it from the data), s.
    pub gnss_delay_s: Option<(f64, f64)>,
    /// Where the heading came from at the end, the compass's state, and the heading resets.
    pub heading: (uavnav_core::output::HeadingHealth, u32),
    /// The IMU's measured noise over its configured (gyro, accelerometer σ ratios), sampled
    /// once a second of sensor time (`eskf`; empty for `paper`).
    pub imu_noise: Vec<[f64; 2]>,
    /// IMU gaps the estimator bridged instead of restarting.
    pub imu_gaps_bridged: u64,
}

/// Inputs the estimator accepted, per sensor.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Fed {
    /// IMU samples.
    pub imu: u64,
    /// GNSS fixes.
    pub gnss: u64,
    /// Magnetometer samples.
    pub mag: u64,
    /// Barometer samples.
    pub baro: u64,
    /// Camera frames.
    pub camera: u64,
}

impl Fed {
    fn count(&mut self, ev: &SensorEvent) {
        match ev {
            SensorEvent::Imu(_) => self.imu += 1,
            SensorEvent::Gnss(_) => self.gnss += 1,
            SensorEvent::Mag(_) => self.mag += 1,
            SensorEvent::Baro(_) => self.baro += 1,
            SensorEvent::Camera(_) => self.camera += 1,
        }
    }
}

/// What a run is scored against: ground truth, or a reference that is not truth.
#[derive(Debug, Clone)]
pub struct Comparison {
    /// `"truth"` or `"reference"` (legends and captions).
    pub short: &'static str,
    /// `"truth"` or the reference's label, e.g. `reference (autopilot estimate, EKF1)`.
    pub name: String,
    /// The samples.
    pub samples: Vec<TruthSample>,
}

/// What one offline run uses: the profile, the sources, the options.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunChoice {
    /// Filter profile.
    pub profile: FilterProfile,
    /// Camera frames.
    pub use_vision: bool,
    /// GNSS fixes.
    pub use_gnss: bool,
    /// Magnetometer samples.
    pub use_mag: bool,
    /// Barometer samples.
    pub use_baro: bool,
}

impl RunChoice {
    /// The choice the command line makes.
    pub fn from_args(args: &Args) -> Self {
        Self {
            profile: args.profile,
            use_vision: !args.no_vision,
            use_gnss: !args.no_gnss,
            use_mag: !args.no_mag,
            use_baro: !args.no_baro,
        }
    }
}

/// Runs one dataset through a [`VehicleRunner`] with vision inline; calls `sink` per pose.
pub fn run_dataset(
    path: &Path,
    read: &uavnav_dataset::ReadOptions,
    choice: RunChoice,
    mut sink: impl FnMut(&PoseOutput) -> anyhow::Result<()>,
) -> Result<(RunOutput, Option<Comparison>), CliError> {
    let ds = uavnav_dataset::Dataset::open_with(path, read).map_err(crate::common::open_error)?;
    let mut config = ds.config().clone();
    config.profile = choice.profile;
    let params = RunnerParams {
        use_vision: choice.use_vision,
        use_gnss: choice.use_gnss,
        use_mag: choice.use_mag,
        use_baro: choice.use_baro,
        ..RunnerParams::default()
    };
    // The local frame is fixed at the first GNSS fix, exactly as in the service, so that the same
    // input gives the same poses offline and online; the report maps poses into the truth frame.
    let stated_delay_s = config.gnss.map(|g| g.delay_ns as f64 * 1e-9);
    let mut runner = VehicleRunner::new(config, params, None);
    let mut out = RunOutput {
        origin: ds.origin(),
        notes: ds.notes().to_vec(),
        ..RunOutput::default()
    };
    let mut fixes = Vec::new();
    let mut next_noise_t_ns = i64::MIN;
    let fix_frame = ds.origin().map(LocalFrame::new);
    for ev in ds.events().map_err(CliError::input)? {
        let ev = ev.map_err(CliError::input)?;
        if let SensorEvent::Gnss(g) = &ev {
            out.gnss_t_ns.push(g.t_ns);
            if let Some(f) = &fix_frame {
                fixes.push(FixNed {
                    t_ns: g.t_ns,
                    pos_ned_m: f.lla_to_ned(&Lla::from_deg(g.lat_deg, g.lon_deg, g.alt_m)),
                    sigma_h_m: g.sigma_h_m,
                });
            }
        }
        // A source left out is not fed at all, so that the run's label does not list it as read.
        match &ev {
            SensorEvent::Mag(_) if !choice.use_mag => continue,
            SensorEvent::Baro(_) if !choice.use_baro => continue,
            _ => {}
        }
        // Counted only when the estimator accepts the input.
        let mut fed = out.fed;
        fed.count(&ev);
        let what = match &ev {
            SensorEvent::Imu(_) => "IMU sample",
            SensorEvent::Gnss(_) => "GNSS fix",
            SensorEvent::Mag(_) => "magnetometer sample",
            SensorEvent::Baro(_) => "barometer sample",
            SensorEvent::Camera(_) => "camera frame",
        };
        let t_ns = ev.t_ns();
        match runner.push_inline(ev) {
            Ok(poses) => {
                out.fed = fed;
                if t_ns >= next_noise_t_ns {
                    out.imu_noise.extend(runner.health().imu_noise_ratio);
                    next_noise_t_ns = t_ns.saturating_add(1_000_000_000);
                }
                for p in poses {
                    sink(&p).map_err(CliError::runtime)?;
                    out.poses.push(p);
                }
            }
            Err(e) => {
                out.rejected += 1;
                if out.rejected <= 5 {
                    eprintln!("uavnav: {what} at {t_ns} ns refused: {e}");
                }
            }
        }
    }
    let health = runner.health();
    if out.fed.gnss > 0 {
        out.gnss_delay_s = stated_delay_s.zip(health.gnss_velocity_delay_s);
    }
    out.heading = (health.heading, health.yaw_resets);
    out.imu_gaps_bridged = health.imu_gaps_bridged;
    // Truth first; a reference (another estimator's output) only where there is no truth, under
    // its own name, and screened against the fixes first (an autopilot's EKF that failed
    // outright must not be reported as our drift).
    let comparison = match (ds.truth(), ds.reference()) {
        (Some(t), _) => Some(Comparison {
            short: "truth",
            name: "truth".into(),
            samples: t.to_vec(),
        }),
        (None, Some(r)) => Some(screened(r.label(), &r.samples, &mut fixes)),
        (None, None) => None,
    };
    Ok((out, comparison))
}

/// The reference without its samples far from the GNSS fixes, named with what was left out.
fn screened(label: String, samples: &[TruthSample], fixes: &mut [FixNed]) -> Comparison {
    fixes.sort_by_key(|f| f.t_ns);
    let params = ScreenParams::default();
    let s = screen(samples, fixes, &params);
    let name = match s.note(&params) {
        Some(note) => {
            eprintln!("uavnav: reference: {note}");
            format!("{label}; {note}")
        }
        None => label,
    };
    Comparison {
        short: "reference",
        name,
        samples: s.kept,
    }
}

/// Runs the command.
pub fn run(args: Args) -> CliResult {
    let file = std::fs::File::create(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))
        .map_err(CliError::runtime)?;
    let mut csv = std::io::BufWriter::new(file);
    writeln!(csv, "{}", csv_header()).map_err(CliError::runtime)?;
    let mut tum = match &args.tum {
        Some(p) => Some(std::io::BufWriter::new(
            std::fs::File::create(p)
                .with_context(|| format!("cannot create {}", p.display()))
                .map_err(CliError::runtime)?,
        )),
        None => None,
    };
    let started = std::time::Instant::now();
    let (out, comparison) = run_dataset(
        &args.dataset,
        &args.read.options(),
        RunChoice::from_args(&args),
        |p| {
            writeln!(csv, "{}", csv_row(p))?;
            if let (Some(t), Some(line)) = (tum.as_mut(), tum_line(p)) {
                writeln!(t, "{line}")?;
            }
            Ok(())
        },
    )?;
    csv.flush().map_err(CliError::runtime)?;
    if let Some(t) = tum.as_mut() {
        t.flush().map_err(CliError::runtime)?;
    }
    for note in &out.notes {
        eprintln!("uavnav: {}: {note}", args.dataset.display());
    }
    eprintln!(
        "uavnav: {} poses in {:.2} s ({} inputs refused, {} dropped behind the fusion horizon; \
         fused {}) -> {}",
        out.poses.len(),
        started.elapsed().as_secs_f64(),
        out.rejected,
        out.poses.last().map_or(0, |p| p.health.late_dropped),
        crate::estimate_report::sources_label(&out),
        args.out.display()
    );
    if out.imu_gaps_bridged > 0 {
        eprintln!(
            "uavnav: {} IMU gaps of 0.5-5 s bridged (integrated across with a widened \
             covariance instead of restarting the estimator)",
            out.imu_gaps_bridged
        );
    }
    if let Some((stated, learnt)) = out.gnss_delay_s
        && (stated - learnt).abs() >= 1e-3
    {
        eprintln!(
            "uavnav: GNSS velocity delay learnt from the data: {learnt:.3} s (the dataset states \
             {stated:.3} s; positions keep it)"
        );
    }
    let (heading, yaw_resets) = out.heading;
    eprintln!(
        "uavnav: heading at the end: {}; compass {}, {} samples judged disturbed; {yaw_resets} \
         heading resets to the yaw bank",
        heading_source_words(heading.source),
        mag_status_words(heading.mag),
        heading.mag_disturbed
    );
    if heading.mag_calibration != uavnav_core::output::MagCalibrationStatus::Off {
        let [x, y, z] = heading.mag_offset_t.map(|v| v * 1e6);
        eprintln!(
            "uavnav: compass offset learnt in flight: [{x:.2}, {y:.2}, {z:.2}] µT (body axes), \
             {}; {} restarts (a changed compass, or a result that was not a compass in the \
             Earth's field)",
            if heading.mag_calibration == uavnav_core::output::MagCalibrationStatus::Applied {
                "applied"
            } else {
                "not applied (too small, not yet known well enough, or not plausible)"
            },
            heading.mag_calibration_restarts
        );
    }
    if !out.imu_noise.is_empty() {
        let [(g50, g95), (a50, a95)] = [0, 1].map(|k| {
            let mut v: Vec<f64> = out.imu_noise.iter().map(|r| r[k]).collect();
            v.sort_by(f64::total_cmp);
            let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
            (at(0.5), at(0.95))
        });
        eprintln!(
            "uavnav: IMU noise against its configuration (σ ratio, median / 95th percentile over \
             the run, once a second): gyro {g50:.1} / {g95:.1}, accelerometer {a50:.1} / \
             {a95:.1} (1 = as configured; the filter follows the larger)"
        );
    }
    if let Some(dir) = &args.report {
        let Some(comparison) = comparison else {
            return Err(CliError::input(anyhow::anyhow!(
                "--report needs truth or a reference, and {} has neither",
                args.dataset.display()
            )));
        };
        crate::estimate_report::write(dir, &args, &out, &comparison)?;
    }
    Ok(())
}

/// The heading's source in words (stderr diagnostics).
fn heading_source_words(s: uavnav_core::output::HeadingSource) -> &'static str {
    use uavnav_core::output::HeadingSource as H;
    match s {
        H::Unknown => "unknown",
        H::Magnetometer => "from the magnetometer",
        H::YawEstimator => "from the yaw bank (GNSS velocity and IMU)",
        H::Course => "from the GNSS course",
    }
}

/// The compass's state in words (stderr diagnostics).
fn mag_status_words(s: uavnav_core::output::MagStatus) -> &'static str {
    use uavnav_core::output::MagStatus as M;
    match s {
        M::Off => "off (none, or not read)",
        M::Active => "active",
        M::StoppedDead => "stopped (dead: it reads no field)",
        M::StoppedContradicted => "stopped (its heading contradicted the yaw bank)",
    }
}
