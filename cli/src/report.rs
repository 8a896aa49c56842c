//! The load test report: a ghz-like JSON document (durations in ns) and a text table.
//!
//! ghz fields and their meaning here: `count` = messages sent; `total` = length of the send phase;
//! `rps` = `count / total`; `average`, `fastest`, `slowest` and `latencyDistribution` = ingest-to-pose
//! latency of the poses received (coordinated-omission correct, see [`crate::load`]);
//! `statusCodeDistribution` = ingest acks by status (`OK` = accepted); `errorDistribution` =
//! transport errors by message. Our own fields are under `uavnav`.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use crate::load::{LoadOutcome, ServiceCounters, Thresholds};

/// Percentiles reported.
pub const PERCENTILES: [f64; 6] = [50.0, 75.0, 90.0, 95.0, 99.0, 99.9];

/// One point of the latency distribution.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LatencyPoint {
    /// Percentile, %.
    pub percentage: f64,
    /// Latency at it, ns.
    pub latency: u64,
}

/// The JSON report of one run.
#[derive(Debug, Clone, Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Report {
    /// Messages sent.
    pub count: u64,
    /// Send phase length, ns.
    pub total: u64,
    /// Mean latency, ns.
    pub average: u64,
    /// Smallest latency, ns.
    pub fastest: u64,
    /// Largest latency, ns.
    pub slowest: u64,
    /// Messages per second.
    pub rps: f64,
    /// Latency percentiles.
    pub latency_distribution: Vec<LatencyPoint>,
    /// Acks by status.
    pub status_code_distribution: BTreeMap<String, u64>,
    /// Transport errors by message.
    pub error_distribution: BTreeMap<String, u64>,
    /// uavnav-specific fields.
    pub uavnav: Extra,
}

/// Our fields.
#[derive(Debug, Clone, Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Extra {
    /// Target URL.
    pub target: String,
    /// Vehicles driven.
    pub vehicles: usize,
    /// Requested duration, s.
    pub duration_s: f64,
    /// Camera frames included.
    pub camera: bool,
    /// Messages scheduled.
    pub scheduled: u64,
    /// Bytes sent.
    pub bytes_sent: u64,
    /// Megabits per second sent.
    pub mbps: f64,
    /// Poses received (latency samples).
    pub poses: u64,
    /// Poses per second received.
    pub poses_per_s: f64,
    /// Pose watch decimation.
    pub decimation: u32,
    /// Vehicles with at least one pose.
    pub vehicles_with_poses: usize,
    /// Vehicles whose poses ended behind their inputs.
    pub vehicles_behind: usize,
    /// Send lag percentiles, ns.
    pub send_lag_distribution: Vec<LatencyPoint>,
    /// Sent but never acknowledged.
    pub unacked: u64,
    /// Acks `PERMISSION_DENIED` by the service's reason (also counted in the status codes).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub permission_denied: BTreeMap<String, u64>,
    /// Errors over messages sent.
    pub error_rate: f64,
    /// The service's counters (from health).
    pub service: ServiceCounters,
    /// Whether the service kept up with real time within the thresholds.
    pub kept_up: bool,
    /// Why not.
    pub failures: Vec<String>,
}

fn percentiles(h: &hdrhistogram::Histogram<u64>) -> Vec<LatencyPoint> {
    PERCENTILES
        .iter()
        .map(|p| LatencyPoint {
            percentage: *p,
            latency: if h.is_empty() {
                0
            } else {
                h.value_at_percentile(*p)
            },
        })
        .collect()
}

impl Report {
    /// Builds the report of `o`.
    pub fn new(o: &LoadOutcome, target: &str, camera: bool, t: &Thresholds) -> Self {
        let h = &o.latency_ns;
        let send_s = o.send_elapsed.as_secs_f64().max(1e-9);
        let failures = o.failures(t);
        Report {
            count: o.sent,
            total: o.send_elapsed.as_nanos() as u64,
            average: if h.is_empty() {
                0
            } else {
                h.mean().round() as u64
            },
            fastest: if h.is_empty() { 0 } else { h.min() },
            slowest: if h.is_empty() { 0 } else { h.max() },
            rps: o.rps(),
            latency_distribution: percentiles(h),
            status_code_distribution: o.statuses.clone(),
            error_distribution: o.errors.clone(),
            uavnav: Extra {
                target: target.to_string(),
                vehicles: o.params.vehicles,
                duration_s: o.params.duration.as_secs_f64(),
                camera,
                scheduled: o.scheduled,
                bytes_sent: o.bytes,
                mbps: o.bytes as f64 * 8.0 / send_s / 1e6,
                poses: o.poses,
                poses_per_s: o.poses as f64 / o.elapsed.as_secs_f64().max(1e-9),
                decimation: o.params.decimation,
                vehicles_with_poses: o.vehicles_with_poses,
                vehicles_behind: o.vehicles_behind,
                send_lag_distribution: percentiles(&o.send_lag_ns),
                unacked: o.unacked,
                permission_denied: o.permission_denied.clone(),
                error_rate: o.error_rate(),
                service: o.service.clone(),
                kept_up: failures.is_empty(),
                failures,
            },
        }
    }

    /// The human-readable table.
    pub fn table(&self) -> String {
        let ms = |ns: u64| format!("{:.2} ms", ns as f64 / 1e6);
        let x = &self.uavnav;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "Summary ({} vehicles, {:.1} s, {}, camera {}):",
            x.vehicles,
            x.duration_s,
            x.target,
            if x.camera { "on" } else { "off" }
        );
        let _ = writeln!(
            s,
            "  Messages sent:     {} of {} scheduled ({:.1} msg/s, {:.2} Mbit/s)",
            self.count, x.scheduled, self.rps, x.mbps
        );
        let _ = writeln!(
            s,
            "  Poses received:    {} ({:.1}/s, decimation {})",
            x.poses,
            x.poses_per_s,
            x.decimation.max(1)
        );
        let _ = writeln!(
            s,
            "  Vehicles w/ poses: {} of {} ({} behind at the end)",
            x.vehicles_with_poses, x.vehicles, x.vehicles_behind
        );
        let _ = writeln!(
            s,
            "  Latency (ingest to pose): fastest {}  average {}  slowest {}",
            ms(self.fastest),
            ms(self.average),
            ms(self.slowest)
        );
        let _ = writeln!(s, "  {:>8}  {:>12}  {:>12}", "pct", "latency", "send lag");
        for (l, g) in self
            .latency_distribution
            .iter()
            .zip(&x.send_lag_distribution)
        {
            let _ = writeln!(
                s,
                "  {:>7}%  {:>12}  {:>12}",
                l.percentage,
                ms(l.latency),
                ms(g.latency)
            );
        }
        let _ = writeln!(
            s,
            "  Status codes: {}",
            fmt_map(&self.status_code_distribution)
        );
        let _ = writeln!(
            s,
            "  Errors:       {} (unacked {}, error rate {:.4})",
            fmt_map(&self.error_distribution),
            x.unacked,
            x.error_rate
        );
        if !x.permission_denied.is_empty() {
            let _ = writeln!(s, "  Permission denied: {}", fmt_map(&x.permission_denied));
        }
        let c = &x.service;
        let _ = writeln!(
            s,
            "  Service (health of {} vehicles): accepted {}  rejected {}  late {}  shed {}  dropped {}",
            c.vehicles_reporting, c.accepted, c.rejected, c.late, c.shed, c.dropped
        );
        if x.kept_up {
            let _ = writeln!(s, "  Verdict: kept up with real time");
        } else {
            let _ = writeln!(s, "  Verdict: FELL BEHIND: {}", x.failures.join("; "));
        }
        s
    }
}

fn fmt_map(m: &BTreeMap<String, u64>) -> String {
    if m.is_empty() {
        return "none".into();
    }
    m.iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect::<Vec<_>>()
        .join(" ")
}
