//! Wire poses → the `uavnav estimate` CSV columns (plus `vehicle_id`) and TUM lines, through the
//! wire conversion of `uavnav-proto` and the formatters of `uavnav-dataset`, so the columns stay
//! identical to the offline ones.
//!
//! The service's compact pose does not carry the per-pose innovation summary: the test-ratio and
//! rejection columns are then 0 in `watch` output (they are on the health stream instead).

use uavnav_core::{LocalFrame, PoseOutput};

use uavnav_client::pb;

/// The CSV header: the `estimate` columns, then `vehicle_id`.
pub fn csv_header() -> String {
    format!("{},vehicle_id", uavnav_dataset::poses::csv_header())
}

/// The estimator output a wire pose stands for; `frame` gives the local NED position (TUM) when the
/// pose does not carry it. `None` for a pose that does not convert (no position or attitude, a
/// non-finite value).
pub fn to_output(p: &pb::PoseEstimate, frame: Option<&LocalFrame>) -> Option<PoseOutput> {
    let mut o = PoseOutput::try_from(p).ok()?;
    if p.pos_ned_m.is_none()
        && let Some(f) = frame
    {
        o.pos_ned_m = f.lla_to_ned(&o.lla);
    }
    Some(o)
}

/// One CSV row (no newline), or `None` for a pose that does not convert.
pub fn csv_row(p: &pb::PoseEstimate) -> Option<String> {
    let o = to_output(p, None)?;
    Some(format!(
        "{},{}",
        uavnav_dataset::poses::csv_row(&o),
        p.vehicle_id
    ))
}

/// One TUM line in the local NED frame `frame` (no newline); `None` also for an attitude-only
/// pose.
pub fn tum_line(p: &pb::PoseEstimate, frame: &LocalFrame) -> Option<String> {
    to_output(p, Some(frame)).and_then(|o| uavnav_dataset::poses::tum_line(&o))
}
