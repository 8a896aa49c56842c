//! `uavnav estimate --report DIR`: the accuracy table and the paper-style figures.
//!
//! The paper's figures compare IMU+GNSS with IMU+GNSS+video, so when the requested run uses vision
//! a second, GNSS-only run of the same profile is made for the comparison.

use std::path::Path;

use uavnav_core::{LocalFrame, TruthSample};
use uavnav_report::{DEFAULT_MIN_GAP_NS, Run, gnss_outages, write_report};
use uavnav_runner::PoseOutput;

use crate::common::{CliError, CliResult};
use crate::estimate::{Args, RunOutput, run_dataset};

fn label(args: &Args, vision: bool) -> String {
    let sensors = match (args.no_gnss, vision) {
        (false, true) => "IMU+GNSS+video",
        (false, false) => "IMU+GNSS",
        (true, true) => "IMU+video",
        (true, false) => "IMU only",
    };
    format!("{}, {sensors}", args.profile.as_str())
}

/// The poses with their NED position re-expressed in the truth's local frame (the estimator's
/// frame starts at the first GNSS fix; the truth's at the dataset origin).
fn in_truth_frame(poses: &[PoseOutput], frame: Option<&LocalFrame>) -> Vec<PoseOutput> {
    let Some(frame) = frame else {
        return poses.to_vec();
    };
    poses
        .iter()
        .map(|p| PoseOutput {
            pos_ned_m: frame.lla_to_ned(&p.lla),
            ..*p
        })
        .collect()
}

/// Writes the report of `out` (and of a GNSS-only comparison run when `out` used vision).
pub fn write(dir: &Path, args: &Args, out: &RunOutput, truth: &[TruthSample]) -> CliResult {
    let outages = gnss_outages(&out.gnss_t_ns, DEFAULT_MIN_GAP_NS);
    let frame = out.origin.map(LocalFrame::new);
    let main = in_truth_frame(&out.poses, frame.as_ref());
    let mut runs = vec![Run {
        label: label(args, !args.no_vision),
        outputs: &main,
    }];
    let comparison;
    if !args.no_vision {
        let (c, _) = run_dataset(
            &args.dataset,
            args.profile,
            false,
            !args.no_gnss,
            |_| Ok(()),
        )?;
        comparison = in_truth_frame(&c.poses, frame.as_ref());
        runs.push(Run {
            label: label(args, false),
            outputs: &comparison,
        });
    }
    let summary = write_report(dir, &runs, truth, &outages).map_err(CliError::runtime)?;
    println!(
        "{}",
        uavnav_estimator::accuracy::AccuracyReport::markdown_header()
    );
    for r in &summary.reports {
        println!("{}", r.markdown_row());
    }
    eprintln!(
        "uavnav: report written to {} ({} files)",
        dir.display(),
        summary.files.len()
    );
    Ok(())
}
