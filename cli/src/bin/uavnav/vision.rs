//! `uavnav vision DATASET`: the vision front end on every consecutive frame pair, one CSV row each,
//! with error statistics against truth when the dataset has it.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use uavnav_core::truth::truth_at;
use uavnav_core::{MotionPrior, SensorEvent, TruthSample};
use uavnav_estimator::{Estimator, EstimatorParams};
use uavnav_vision::{
    CSV_HEADER, FrontEnd, Method, PairError, VisionParams, csv_row, error_stats, pair_error,
};

use crate::common::{CliError, CliResult};

/// Arguments of `uavnav vision`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// An ASL folder (with `mav0/cam0`) or an `.mcap` recording.
    pub dataset: PathBuf,
    /// Do not predict the flow from the IMU and the Earth-surface model (plain pyramidal KLT).
    #[arg(long)]
    pub no_imu_aid: bool,
    /// Egomotion solver: `essential` (the paper's), `plane` (ground-plane aware) or `auto`.
    #[arg(long, default_value = "auto", value_parser = parse_method)]
    pub method: Method,
    /// Output CSV, one row per consecutive frame pair.
    #[arg(long)]
    pub out: PathBuf,
}

fn parse_method(s: &str) -> Result<Method, String> {
    s.parse()
}

/// Runs the command.
pub fn run(args: Args) -> CliResult {
    let ds = uavnav_dataset::Dataset::open(&args.dataset).map_err(CliError::input)?;
    let config = ds.config().clone();
    let Some(camera) = config.camera.clone() else {
        return Err(CliError::input(anyhow::anyhow!(
            "{} has no camera (mav0/cam0)",
            args.dataset.display()
        )));
    };
    let mut params = VisionParams {
        imu_aid: !args.no_imu_aid,
        ..VisionParams::default()
    };
    params.solve.method = args.method;
    let mut frontend = FrontEnd::new(&camera.model, camera.body_from_cam, params);
    let epoch = std::time::Instant::now();
    frontend.set_clock(Box::new(move || epoch.elapsed().as_micros() as u64));
    // The prior comes from an IMU(+GNSS) estimator without vision, as in the service.
    let mut estimator = Estimator::new(&config, EstimatorParams::default(), ds.origin());
    let truth = ds.truth().map(|t| t.to_vec());
    let file = std::fs::File::create(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))
        .map_err(CliError::runtime)?;
    let mut out = std::io::BufWriter::new(file);
    writeln!(out, "{CSV_HEADER}").map_err(CliError::runtime)?;
    let mut errors: Vec<PairError> = Vec::new();
    let (mut pairs, mut measured) = (0usize, 0usize);
    for ev in ds.events().map_err(CliError::input)? {
        match ev.map_err(CliError::input)? {
            SensorEvent::Imu(s) => {
                let _ = estimator.push_imu(&s);
            }
            SensorEvent::Gnss(g) => {
                let _ = estimator.push_gnss(&g);
            }
            SensorEvent::Mag(_) | SensorEvent::Baro(_) => {}
            SensorEvent::Camera(f) => {
                let prior = match (args.no_imu_aid, frontend.reference_t_ns()) {
                    (false, Some(t0)) => estimator.motion_prior(t0, f.t_ns),
                    _ => MotionPrior::default(),
                };
                let r = frontend.process(f.t_ns, f.format, &f.data, &prior);
                let Some(t0) = r.t0_ns else { continue };
                pairs += 1;
                writeln!(out, "{}", csv_row(&r)).map_err(CliError::runtime)?;
                if let Ok(ego) = &r.outcome {
                    measured += 1;
                    if let Some(truth) = &truth
                        && let Some((rt, tt)) =
                            true_motion(truth, &camera.body_from_cam, t0, r.t1_ns)
                    {
                        errors.push(pair_error(ego, &rt, &tt));
                    }
                }
            }
        }
    }
    out.flush().map_err(CliError::runtime)?;
    println!(
        "pairs: {pairs}, measured: {measured}, written to {}",
        args.out.display()
    );
    if !errors.is_empty() {
        let s = error_stats(&errors);
        println!(
            "rotation error (deg): median {:.4}, p95 {:.4}, max {:.4} over {} pairs",
            s.rot_median_deg, s.rot_p95_deg, s.rot_max_deg, s.rot_count
        );
        println!(
            "translation direction error (deg): median {:.3}, p95 {:.3}, max {:.3} over {} pairs; {} off by > 90 deg",
            s.t_median_deg, s.t_p95_deg, s.t_max_deg, s.t_count, s.t_over_90
        );
    }
    Ok(())
}

/// True `cam1_from_cam0` and `t` (x1 = R x0 + t, camera 1) between two times, from body truth.
fn true_motion(
    truth: &[TruthSample],
    body_from_cam: &Isometry3<f64>,
    t0_ns: i64,
    t1_ns: i64,
) -> Option<(UnitQuaternion<f64>, Vector3<f64>)> {
    let a = truth_at(truth, t0_ns)?;
    let b = truth_at(truth, t1_ns)?;
    let nav_from_cam0 = a.nav_from_body * body_from_cam.rotation;
    let nav_from_cam1 = b.nav_from_body * body_from_cam.rotation;
    let p_cam0 = a.pos_ned_m + a.nav_from_body * body_from_cam.translation.vector;
    let p_cam1 = b.pos_ned_m + b.nav_from_body * body_from_cam.translation.vector;
    let r = nav_from_cam1.inverse() * nav_from_cam0;
    let t = nav_from_cam1.inverse() * (p_cam0 - p_cam1);
    Some((r, t))
}
