//! # uavnav-report
//!
//! The accuracy report of `uavnav estimate --report DIR`: given one or more runs of the
//! estimator over a dataset with truth, [`write_report`] writes into `DIR` (or, for a dataset
//! with only a reference such as a flight log's autopilot EKF, [`write_report_against`] with the
//! reference named for what it is: legends, captions and tables then say "reference", never
//! "truth")
//!
//! | file | content |
//! |---|---|
//! | `accuracy.json` | one object per run: the estimator's `AccuracyReport` plus run metadata |
//! | `accuracy.md` | the same as a Markdown table, the outage windows and the figures |
//! | `attitude.png` | roll, pitch, yaw against truth (the paper's Figs. 2–3) |
//! | `attitude_error.png` | roll, pitch, yaw errors with the stated ±3σ |
//! | `velocity_ned.png` | north, east, down velocity against truth (Fig. 4) |
//! | `position_down.png` | down position against truth, zoomed on each outage (Fig. 5) |
//! | `horizontal_error.png` | horizontal position error with the stated 3σ |
//!
//! Time axes are seconds since the first output; GNSS outages are shaded grey.
//!
//! | module | what it holds |
//! |---|---|
//! | [`accuracy`] | attitude RMSE, outage drift, 3σ consistency: [`accuracy::AccuracyReport`] |
//! | [`outages`] | [`gnss_outages`]: outage windows derived from the GNSS fix times |
//! | [`reference`] | [`reference::screen`]: a reference's samples far from the GNSS fixes left out before scoring |
//! | [`tables`] | `accuracy.json` and `accuracy.md` |
//! | [`figures`] | plot-ready series and the panels of each figure |
//! | [`plot`] | the stacked-panel PNG renderer (embedded font, no system fonts) |
//! | [`series`] | time base, yaw unwrapping, decimation, axis ranges, clipping |
//! | [`error`] | [`ReportError`] |

pub mod accuracy;
pub mod error;
pub mod figures;
pub mod outages;
pub mod plot;
pub mod reference;
pub mod series;
pub mod tables;

use std::path::{Path, PathBuf};

use uavnav_core::PoseOutput;
use uavnav_core::TruthSample;

use crate::accuracy::AccuracyReport;

pub use error::ReportError;
pub use outages::{DEFAULT_MIN_GAP_NS, gnss_outages};
pub use plot::PlotParams;

/// One estimator run to report on.
#[derive(Debug, Clone)]
pub struct Run<'a> {
    /// Legend and table label, e.g. `"eskf, IMU+GNSS+video"`.
    pub label: String,
    /// Its outputs, in time order.
    pub outputs: &'a [PoseOutput],
}

/// What the runs are scored against.
#[derive(Debug, Clone, Copy)]
pub struct Against<'a> {
    /// Short name for legends and captions: `"truth"`, `"reference"`.
    pub short: &'a str,
    /// Full name for the tables: `"truth"`, `"reference (autopilot estimate, EKF1)"`.
    pub name: &'a str,
    /// The samples, sorted by time.
    pub samples: &'a [TruthSample],
}

impl<'a> Against<'a> {
    /// Ground truth.
    pub fn truth(samples: &'a [TruthSample]) -> Self {
        Against {
            short: "truth",
            name: "truth",
            samples,
        }
    }
}

/// What [`write_report`] computed and wrote.
#[derive(Debug, Clone)]
pub struct ReportSummary {
    /// The accuracy figures, one per run, in run order.
    pub reports: Vec<AccuracyReport>,
    /// Every file written, in writing order.
    pub files: Vec<PathBuf>,
}

/// The PNGs, with the captions used in `accuracy.md`.
const FIGURES: [(&str, &str); 5] = [
    ("attitude.png", "Roll, pitch and yaw against truth"),
    ("attitude_error.png", "Attitude errors with the stated ±3σ"),
    ("velocity_ned.png", "NED velocity against truth"),
    (
        "position_down.png",
        "Down position against truth, zoom on the GNSS outages",
    ),
    (
        "horizontal_error.png",
        "Horizontal position error with the stated 3σ",
    ),
];

/// Writes the report of `runs` against `truth` (sorted by time) into `dir` (created if needed),
/// with `outages` as `[start, end)` windows in ns (e.g. from [`gnss_outages`]).
pub fn write_report(
    dir: &Path,
    runs: &[Run],
    truth: &[TruthSample],
    outages: &[(i64, i64)],
) -> Result<ReportSummary, ReportError> {
    write_report_with(dir, runs, truth, outages, &PlotParams::default())
}

/// [`write_report`] with explicit plot size and density.
pub fn write_report_with(
    dir: &Path,
    runs: &[Run],
    truth: &[TruthSample],
    outages: &[(i64, i64)],
    params: &PlotParams,
) -> Result<ReportSummary, ReportError> {
    write_report_against(dir, runs, Against::truth(truth), outages, params)
}

/// [`write_report_with`] against truth or a named reference: the figures' legends and captions
/// use `against.short`, the tables state `against.name`.
pub fn write_report_against(
    dir: &Path,
    runs: &[Run],
    against: Against,
    outages: &[(i64, i64)],
    params: &PlotParams,
) -> Result<ReportSummary, ReportError> {
    let truth = against.samples;
    if truth.is_empty() {
        return Err(ReportError::Empty("no truth or reference samples"));
    }
    let t0_ns = runs
        .iter()
        .filter_map(|r| r.outputs.first())
        .map(|o| o.t_ns)
        .min();
    let t_end_ns = runs
        .iter()
        .filter_map(|r| r.outputs.last())
        .map(|o| o.t_ns)
        .max();
    let (Some(t0_ns), Some(t_end_ns)) = (t0_ns, t_end_ns) else {
        return Err(ReportError::Empty("no run with outputs"));
    };
    std::fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;

    let reports: Vec<AccuracyReport> = runs
        .iter()
        .map(|r| AccuracyReport::compute(&r.label, r.outputs, truth, outages))
        .collect();
    let outputs: Vec<&[PoseOutput]> = runs.iter().map(|r| r.outputs).collect();
    let mut files = Vec::new();
    let json = tables::accuracy_json(&reports, &outputs, outages, against.name)?;
    files.push(write_text(dir, "accuracy.json", &json)?);
    let captions: Vec<(&str, String)> = FIGURES
        .iter()
        .map(|(file, caption)| (*file, caption.replace("truth", against.short)))
        .collect();
    let captions: Vec<(&str, &str)> = captions.iter().map(|(f, c)| (*f, c.as_str())).collect();
    let md = tables::accuracy_markdown(&reports, outages, t0_ns, &captions, against.name);
    files.push(write_text(dir, "accuracy.md", &md)?);

    let data =
        figures::FigureData::new(runs, truth, outages, t0_ns, t_end_ns).against(against.short);
    let panels = [
        data.attitude(),
        data.attitude_error(),
        data.velocity(),
        data.position_down(),
        data.horizontal_error(),
    ];
    for ((file, _), panels) in FIGURES.iter().zip(panels) {
        let path = dir.join(file);
        plot::render(&path, &panels, params)?;
        files.push(path);
    }
    Ok(ReportSummary { reports, files })
}

fn write_text(dir: &Path, name: &str, text: &str) -> Result<PathBuf, ReportError> {
    let path = dir.join(name);
    std::fs::write(&path, text).map_err(|source| ReportError::Io {
        path: path.clone(),
        source,
    })?;
    Ok(path)
}
