//! The accuracy tables: `accuracy.json` (the estimator's [`AccuracyReport::to_json`] per run,
//! plus run metadata) and `accuracy.md`.

use serde_json::{Map, Value, json};
use uavnav_core::{Mode, PoseOutput};

use crate::accuracy::{AccuracyReport, SETTLE_NS};

use crate::error::ReportError;

/// Every mode, in a fixed order (deterministic output).
const MODES: [Mode; 6] = [
    Mode::Initialising,
    Mode::Nominal,
    Mode::GnssDeniedVision,
    Mode::InertialOnly,
    Mode::Diverged,
    Mode::AttitudeOnly,
];

/// Metadata of one run: span, time share of each mode, and the final health counters.
fn run_metadata(outputs: &[PoseOutput]) -> Value {
    let n = outputs.len();
    let (start, end) = match (outputs.first(), outputs.last()) {
        (Some(a), Some(b)) => (Some(a.t_ns), Some(b.t_ns)),
        _ => (None, None),
    };
    let mut fractions = Map::new();
    for mode in MODES {
        let count = outputs.iter().filter(|o| o.health.mode == mode).count();
        let share = if n > 0 { count as f64 / n as f64 } else { 0.0 };
        fractions.insert(mode.as_str().into(), json!(share));
    }
    let last = outputs.last().map(|o| o.health);
    json!({
        "outputs": n,
        "start_ns": start,
        "end_ns": end,
        "duration_s": start.zip(end).map(|(a, b)| (b - a) as f64 * 1e-9),
        "mode_fraction": fractions,
        "final_mode": last.map(|h| h.mode.as_str()),
        "inputs_rejected": last.map(|h| h.inputs_rejected),
        "late_dropped": last.map(|h| h.late_dropped),
        "vision_no_clone": last.map(|h| h.vision_no_clone),
        "gnss_resets": last.map(|h| h.gnss_resets),
    })
}

/// `accuracy.json`: an array with one object per run — the fields of
/// [`AccuracyReport::to_json`] plus `"run"` (metadata), `"outage_windows_ns"`, `"settle_s"` and
/// `"scored_against"` (`"truth"`, or the reference's name).
pub fn accuracy_json(
    reports: &[AccuracyReport],
    outputs: &[&[PoseOutput]],
    outages: &[(i64, i64)],
    against: &str,
) -> Result<String, ReportError> {
    let mut runs = Vec::with_capacity(reports.len());
    for (report, outs) in reports.iter().zip(outputs) {
        let mut obj: Map<String, Value> = serde_json::from_str(&report.to_json())?;
        obj.insert("run".into(), run_metadata(outs));
        obj.insert("outage_windows_ns".into(), json!(outages));
        obj.insert("settle_s".into(), json!(SETTLE_NS as f64 * 1e-9));
        obj.insert("scored_against".into(), json!(against));
        runs.push(Value::Object(obj));
    }
    Ok(serde_json::to_string_pretty(&Value::Array(runs))?)
}

/// `accuracy.md`: the accuracy table, the outage windows, and links to the figures.
pub fn accuracy_markdown(
    reports: &[AccuracyReport],
    outages: &[(i64, i64)],
    t0_ns: i64,
    figures: &[(&str, &str)],
    against: &str,
) -> String {
    let mut md = String::from("# Accuracy report\n\n");
    md.push_str(&format!("Scored against: **{against}**."));
    if against != "truth" {
        // Another estimator's output: the figures are differences between two estimates.
        md.push_str(" This is not ground truth: errors below are differences from it.");
    }
    md.push_str("\n\n");
    md.push_str(&format!(
        "Attitude RMSE and consistency after the first {:.0} s; outage drift is the horizontal \
         error at the end of each GNSS outage as a percentage of the distance flown in it.\n\n",
        SETTLE_NS as f64 * 1e-9
    ));
    md.push_str(AccuracyReport::markdown_header());
    md.push('\n');
    for r in reports {
        md.push_str(&r.markdown_row());
        md.push('\n');
    }
    md.push_str("\n## GNSS outages\n\n");
    if outages.is_empty() {
        md.push_str("None.\n");
    }
    for (k, &(a, b)) in outages.iter().enumerate() {
        md.push_str(&format!(
            "{}. {:.2} s – {:.2} s ({:.1} s long; seconds since the first output)\n",
            k + 1,
            (a - t0_ns) as f64 * 1e-9,
            (b - t0_ns) as f64 * 1e-9,
            (b - a) as f64 * 1e-9
        ));
    }
    md.push_str("\n## Figures\n\n");
    for (file, caption) in figures {
        md.push_str(&format!("### {caption}\n\n![{caption}]({file})\n\n"));
    }
    md
}
