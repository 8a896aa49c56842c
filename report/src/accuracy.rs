//! Accuracy figures against truth, as pure functions over (outputs, truth): attitude RMSE, the
//! horizontal drift at the end of a GNSS outage as a percentage of the distance flown in it, and
//! the 3σ / NEES consistency. The CLI's `--report` writes [`AccuracyReport`] as JSON and Markdown.

use nalgebra::Vector3;
pub use uavnav_core::rotation::euler_error;
pub use uavnav_core::truth::truth_at;
use uavnav_core::{PoseOutput, TruthSample};

/// Attitude RMSE (roll, pitch, yaw; rad) over outputs at or after `from_ns`.
pub fn attitude_rmse(
    outputs: &[PoseOutput],
    truth: &[TruthSample],
    from_ns: i64,
) -> Option<Vector3<f64>> {
    let mut sum = Vector3::zeros();
    let mut n = 0usize;
    for o in outputs.iter().filter(|o| o.t_ns >= from_ns) {
        let Some(t) = truth_at(truth, o.t_ns) else {
            continue;
        };
        let e = euler_error(&o.nav_from_body, &t.nav_from_body);
        sum += e.component_mul(&e);
        n += 1;
    }
    (n > 0).then(|| (sum / n as f64).map(f64::sqrt))
}

/// Drift at the end of a GNSS outage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutageDrift {
    /// Horizontal position error at the last output inside the outage, m.
    pub horizontal_error_m: f64,
    /// Horizontal distance flown during the outage (truth), m.
    pub distance_m: f64,
    /// Error as % of the distance.
    pub percent: f64,
    /// Stated 1-σ horizontal uncertainty at that output, m (√(σN² + σE²)).
    pub stated_sigma_h_m: f64,
}

/// The horizontal error at the end of the outage `[start_ns, end_ns)` relative to the distance
/// flown in it.
pub fn outage_drift(
    outputs: &[PoseOutput],
    truth: &[TruthSample],
    start_ns: i64,
    end_ns: i64,
) -> Option<OutageDrift> {
    let last = outputs
        .iter()
        .rev()
        .find(|o| o.t_ns < end_ns && o.t_ns >= start_ns && o.health.mode.has_position())?;
    let t = truth_at(truth, last.t_ns)?;
    let err = (last.pos_ned_m - t.pos_ned_m).xy().norm();
    let inside: Vec<&TruthSample> = truth
        .iter()
        .filter(|s| s.t_ns >= start_ns && s.t_ns <= last.t_ns)
        .collect();
    let distance: f64 = inside
        .windows(2)
        .map(|w| (w[1].pos_ned_m - w[0].pos_ned_m).xy().norm())
        .sum();
    if distance <= 0.0 {
        return None;
    }
    Some(OutageDrift {
        horizontal_error_m: err,
        distance_m: distance,
        percent: 100.0 * err / distance,
        stated_sigma_h_m: last.sigma_pos_ned_m.xy().norm(),
    })
}

/// Consistency of the stated uncertainty.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Consistency {
    /// Fraction of (sample, axis) position errors within 3σ (over the samples with a position).
    pub pos_within_3sigma: f64,
    /// Same for velocity.
    pub vel_within_3sigma: f64,
    /// Same for roll/pitch/yaw.
    pub att_within_3sigma: f64,
    /// Over all nine axes.
    pub all_within_3sigma: f64,
    /// Mean NEES of position with the diagonal σ (expected ≈ 3 when consistent).
    pub mean_nees_pos: f64,
    /// Mean NEES of attitude with the diagonal σ (expected ≈ 3).
    pub mean_nees_att: f64,
    /// Samples evaluated.
    pub samples: usize,
    /// Of those, the samples with a position and velocity (not [`uavnav_core::Mode::AttitudeOnly`]).
    pub position_samples: usize,
}

/// 3σ fractions and mean (diagonal) NEES over outputs at or after `from_ns`.
pub fn consistency(outputs: &[PoseOutput], truth: &[TruthSample], from_ns: i64) -> Consistency {
    let mut c = Consistency::default();
    let (mut in_p, mut in_v, mut in_a) = (0usize, 0usize, 0usize);
    let (mut nees_p, mut nees_a) = (0.0, 0.0);
    for o in outputs.iter().filter(|o| o.t_ns >= from_ns) {
        let Some(t) = truth_at(truth, o.t_ns) else {
            continue;
        };
        let ea = euler_error(&o.nav_from_body, &t.nav_from_body);
        for k in 0..3 {
            in_a += usize::from(ea[k].abs() <= 3.0 * o.sigma_att_rad[k]);
            nees_a += (ea[k] / o.sigma_att_rad[k].max(1e-12)).powi(2);
        }
        c.samples += 1;
        if !o.health.mode.has_position() {
            continue;
        }
        let ep = o.pos_ned_m - t.pos_ned_m;
        let ev = o.vel_ned_mps - t.vel_ned_mps;
        for k in 0..3 {
            in_p += usize::from(ep[k].abs() <= 3.0 * o.sigma_pos_ned_m[k]);
            in_v += usize::from(ev[k].abs() <= 3.0 * o.sigma_vel_mps[k]);
            nees_p += (ep[k] / o.sigma_pos_ned_m[k].max(1e-12)).powi(2);
        }
        c.position_samples += 1;
    }
    if c.samples > 0 {
        let n = 3.0 * c.samples as f64;
        let n_pv = 3.0 * c.position_samples as f64;
        if c.position_samples > 0 {
            c.pos_within_3sigma = in_p as f64 / n_pv;
            c.vel_within_3sigma = in_v as f64 / n_pv;
            c.mean_nees_pos = nees_p / c.position_samples as f64;
        }
        c.att_within_3sigma = in_a as f64 / n;
        c.all_within_3sigma = (in_p + in_v + in_a) as f64 / (n + 2.0 * n_pv);
        c.mean_nees_att = nees_a / c.samples as f64;
    }
    c
}

/// The accuracy table of one run.
#[derive(Debug, Clone, PartialEq)]
pub struct AccuracyReport {
    /// Run label (e.g. "eskf, all sensors").
    pub label: String,
    /// Attitude RMSE after the settling time, deg (roll, pitch, yaw).
    pub att_rmse_deg: Option<Vector3<f64>>,
    /// Drift at the end of each outage.
    pub outages: Vec<OutageDrift>,
    /// Consistency after the settling time.
    pub consistency: Consistency,
}

/// Settling time excluded from the attitude and consistency figures, ns (the targets' "after 30 s"),
/// counted from the first output with a position (else the first output) or the truth's start,
/// whichever is earlier.
pub const SETTLE_NS: i64 = 30_000_000_000;

impl AccuracyReport {
    /// Computes the report; `outages` are `[start, end)` windows in ns.
    pub fn compute(
        label: &str,
        outputs: &[PoseOutput],
        truth: &[TruthSample],
        outages: &[(i64, i64)],
    ) -> Self {
        // From the first output with a position when there is one: a filter that ran attitude
        // only before GNSS came settles from there, as one that waited for it.
        let t0 = outputs
            .iter()
            .find(|o| o.health.mode.has_position())
            .or(outputs.first())
            .map(|o| o.t_ns)
            .unwrap_or(0)
            .min(truth.first().map(|t| t.t_ns).unwrap_or(0));
        let from = t0 + SETTLE_NS;
        Self {
            label: label.to_string(),
            att_rmse_deg: attitude_rmse(outputs, truth, from).map(|v| v.map(f64::to_degrees)),
            outages: outages
                .iter()
                .filter_map(|&(a, b)| outage_drift(outputs, truth, a, b))
                .collect(),
            consistency: consistency(outputs, truth, from),
        }
    }

    /// JSON object (hand-written: no serde in this pure crate).
    pub fn to_json(&self) -> String {
        let att = self
            .att_rmse_deg
            .map(|v| {
                format!(
                    "{{\"roll\":{:.5},\"pitch\":{:.5},\"yaw\":{:.5}}}",
                    v.x, v.y, v.z
                )
            })
            .unwrap_or_else(|| "null".into());
        let outs: Vec<String> = self
            .outages
            .iter()
            .map(|o| {
                format!(
                    "{{\"horizontal_error_m\":{:.3},\"distance_m\":{:.1},\"percent\":{:.4},\"stated_sigma_h_m\":{:.3}}}",
                    o.horizontal_error_m, o.distance_m, o.percent, o.stated_sigma_h_m
                )
            })
            .collect();
        let c = &self.consistency;
        format!(
            "{{\"label\":{:?},\"attitude_rmse_deg\":{},\"outages\":[{}],\"consistency\":{{\"pos_within_3sigma\":{:.4},\"vel_within_3sigma\":{:.4},\"att_within_3sigma\":{:.4},\"all_within_3sigma\":{:.4},\"mean_nees_pos\":{:.3},\"mean_nees_att\":{:.3},\"samples\":{},\"position_samples\":{}}}}}",
            self.label,
            att,
            outs.join(","),
            c.pos_within_3sigma,
            c.vel_within_3sigma,
            c.att_within_3sigma,
            c.all_within_3sigma,
            c.mean_nees_pos,
            c.mean_nees_att,
            c.samples,
            c.position_samples
        )
    }

    /// One Markdown table row: label | roll | pitch | yaw RMSE (°) | outage drift % | within 3σ.
    pub fn markdown_row(&self) -> String {
        // A flight shorter than the settling time has nothing to score after it: a dash, not NaN
        // or 0 %.
        let (r, p, y, within) = match self.att_rmse_deg {
            Some(v) => (
                format!("{:.3}", v.x),
                format!("{:.3}", v.y),
                format!("{:.3}", v.z),
                format!("{:.1} %", 100.0 * self.consistency.all_within_3sigma),
            ),
            None => {
                let dash = || "–".to_string();
                (dash(), dash(), dash(), dash())
            }
        };
        let drift = self
            .outages
            .iter()
            .map(|o| format!("{:.2} % ({:.1} m)", o.percent, o.horizontal_error_m))
            .collect::<Vec<_>>()
            .join(", ");
        format!(
            "| {} | {r} | {p} | {y} | {} | {within} |",
            self.label,
            if drift.is_empty() {
                "–".into()
            } else {
                drift
            },
        )
    }

    /// The Markdown table header matching [`Self::markdown_row`].
    pub fn markdown_header() -> &'static str {
        "| run | roll RMSE ° | pitch RMSE ° | yaw RMSE ° | outage drift | within 3σ |\n|---|---|---|---|---|---|"
    }
}
