//! `uavnav estimate --report DIR`: the accuracy table and the paper-style figures.
//!
//! The paper's figures compare IMU+GNSS with IMU+GNSS+video, so when the requested run fused
//! vision a second, vision-free run of the same profile is made for the comparison.
//!
//! Each run is labelled with the sources it actually fused (not the ones asked for): a dataset
//! without a camera is never labelled "+video". What the runs are scored against is named: truth,
//! or a reference such as a flight log's autopilot estimate, which is not truth.

use std::path::Path;

use uavnav_core::{FilterProfile, LocalFrame};
use uavnav_report::{Against, DEFAULT_MIN_GAP_NS, PlotParams, Run, gnss_outages};
use uavnav_runner::PoseOutput;

use crate::common::{CliError, CliResult};
use crate::estimate::{Args, Comparison, RunOutput, run_dataset};

/// The sources a run fused, from the estimator's own counters (the last pose's health): e.g.
/// `IMU+GNSS+mag`. Sensors that were read and accepted but never fused (a barometer while GNSS
/// gives the height, a magnetometer under the `paper` profile) are named apart.
pub fn sources_label(out: &RunOutput) -> String {
    let h = out.poses.last().map(|p| p.health);
    let fed = [out.fed.gnss, out.fed.mag, out.fed.baro, out.fed.camera];
    let mut used = vec!["IMU"];
    let mut unused = Vec::new();
    for ((name, was_fused), fed) in fused_sources(h.as_ref()).into_iter().zip(fed) {
        if was_fused {
            used.push(name);
        } else if fed > 0 {
            unused.push(name);
        }
    }
    let mut label = used.join("+");
    if used.len() == 1 {
        label.push_str(" only");
    }
    if !unused.is_empty() {
        label.push_str(&format!(" ({} read, not fused)", unused.join(", ")));
    }
    label
}

/// GNSS, mag, baro and video, each with whether the estimator's counters say it was fused.
pub fn fused_sources(h: Option<&uavnav_estimator::PoseHealth>) -> [(&'static str, bool); 4] {
    let fused = |f: fn(&uavnav_estimator::PoseHealth) -> u64| h.map_or(0, f) > 0;
    [
        ("GNSS", fused(|h| h.gnss_pos.fused + h.gnss_vel.fused)),
        ("mag", fused(|h| h.mag.fused)),
        ("baro", fused(|h| h.baro.fused)),
        (
            "video",
            fused(|h| h.vision_rot.fused + h.vision_trans.fused),
        ),
    ]
}

fn label(profile: FilterProfile, out: &RunOutput) -> String {
    format!("{}, {}", profile.as_str(), sources_label(out))
}

/// Whether a run fused vision.
fn fused_vision(out: &RunOutput) -> bool {
    out.poses
        .last()
        .is_some_and(|p| p.health.vision_rot.fused + p.health.vision_trans.fused > 0)
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

/// Writes the report of `out` (and of a vision-free comparison run when `out` fused vision)
/// against `against` (truth, or a named reference).
pub fn write(dir: &Path, args: &Args, out: &RunOutput, against: &Comparison) -> CliResult {
    let outages = gnss_outages(&out.gnss_t_ns, DEFAULT_MIN_GAP_NS);
    let frame = out.origin.map(LocalFrame::new);
    let main = in_truth_frame(&out.poses, frame.as_ref());
    let mut runs = vec![Run {
        label: label(args.profile, out),
        outputs: &main,
    }];
    let comparison;
    let comparison_out;
    if fused_vision(out) {
        (comparison_out, _) = run_dataset(
            &args.dataset,
            &args.read.options(),
            crate::estimate::RunChoice {
                use_vision: false,
                ..crate::estimate::RunChoice::from_args(args)
            },
            |_| Ok(()),
        )?;
        comparison = in_truth_frame(&comparison_out.poses, frame.as_ref());
        runs.push(Run {
            label: label(args.profile, &comparison_out),
            outputs: &comparison,
        });
    }
    let against = Against {
        short: against.short,
        name: &against.name,
        samples: &against.samples,
    };
    let summary =
        uavnav_report::write_report_against(dir, &runs, against, &outages, &PlotParams::default())
            .map_err(CliError::runtime)?;
    println!("Scored against: {}", against.name);
    println!(
        "{}",
        uavnav_report::accuracy::AccuracyReport::markdown_header()
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
