//! Pure pieces for the `uavnav vision` CLI: the CSV row layout and error statistics against
//! ground truth. Degrees appear only here (an edge).

use std::fmt::{self, Write as _};

use nalgebra::{UnitQuaternion, Vector3};
use uavnav_core::Egomotion;

use crate::frontend::FrameResult;

/// CSV header; the first 14 columns are fixed by the CLI contract.
pub const CSV_HEADER: &str = "t0_ns,t1_ns,tracked,inliers,qw,qx,qy,qz,tx,ty,tz,decode_us,track_us,solve_us,solver,quality,reason,t_m_x,t_m_y,t_m_z,rot_sigma_deg";

/// Formats one CSV row (no newline) for a frame result. `q` is NaN for no measurement; `t` is
/// the unit translation, `0,0,0` when undetermined (rotation-only or no measurement);
/// `t0_ns` is empty when there was no reference frame; metric columns are empty when unknown.
pub fn csv_row(r: &FrameResult) -> String {
    let mut s = String::with_capacity(200);
    let t0 = r.t0_ns.map(|t| t.to_string()).unwrap_or_default();
    let tm = &r.timings;
    match &r.outcome {
        Ok(e) => {
            let q = e.cam1_from_cam0.quaternion();
            let t = e
                .t_dir_cam1
                .map(|u| u.into_inner())
                .unwrap_or_else(Vector3::zeros);
            let _ = write!(
                s,
                "{t0},{},{},{},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},",
                r.t1_ns, r.tracked, e.inliers, q.w, q.i, q.j, q.k, t.x, t.y, t.z
            );
            let _ = write!(
                s,
                "{},{},{},{},{:.4},,",
                tm.decode_us,
                tm.track_us,
                tm.solve_us,
                e.solver.as_str(),
                e.quality
            );
            if let Some(m) = e.t_cam1_m {
                let _ = write!(s, "{:.6},{:.6},{:.6},", m.x, m.y, m.z);
            } else {
                s.push_str(",,,");
            }
            let sig = e.rot_cov.trace().max(0.0).sqrt().to_degrees();
            let _ = write!(s, "{sig:.6}");
        }
        Err(nm) => {
            let _ = write!(s, "{t0},{},{},0,NaN,NaN,NaN,NaN,0,0,0,", r.t1_ns, r.tracked);
            let _ = write!(
                s,
                "{},{},{},none,0,{},,,,",
                tm.decode_us,
                tm.track_us,
                tm.solve_us,
                nm.tag()
            );
        }
    }
    s
}

/// Error of one measured pair against truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairError {
    /// Angle of `R_meas · R_trueᵀ`, rad.
    pub rot_err_rad: f64,
    /// Angle between the measured and true translation directions, rad (`None` when either is
    /// undetermined or the true translation is ~0).
    pub t_dir_err_rad: Option<f64>,
}

/// Compares a measurement with the true `cam1_from_cam0` and `t` (`x1 = R x0 + t`, camera 1).
pub fn pair_error(
    est: &Egomotion,
    true_r: &UnitQuaternion<f64>,
    true_t: &Vector3<f64>,
) -> PairError {
    let rot_err_rad = (est.cam1_from_cam0 * true_r.inverse()).angle();
    let t_dir_err_rad = match est.t_dir_cam1 {
        Some(u) if true_t.norm() > 1e-9 => Some(u.into_inner().angle(&true_t.normalize())),
        _ => None,
    };
    PairError {
        rot_err_rad,
        t_dir_err_rad,
    }
}

/// Summary statistics of a run, degrees.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ErrorStats {
    /// Pairs with a rotation error.
    pub rot_count: usize,
    /// Median rotation error, deg.
    pub rot_median_deg: f64,
    /// 95th percentile rotation error, deg.
    pub rot_p95_deg: f64,
    /// Largest rotation error, deg.
    pub rot_max_deg: f64,
    /// Pairs with a translation-direction error.
    pub t_count: usize,
    /// Median translation-direction error, deg.
    pub t_median_deg: f64,
    /// 95th percentile, deg.
    pub t_p95_deg: f64,
    /// Largest, deg.
    pub t_max_deg: f64,
    /// Pairs whose translation direction is off by more than 90°.
    pub t_over_90: usize,
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let k = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[k.min(sorted.len() - 1)]
}

/// Median, 95th percentile, maximum and the count above 90°.
pub fn error_stats(errors: &[PairError]) -> ErrorStats {
    let mut rot: Vec<f64> = errors.iter().map(|e| e.rot_err_rad.to_degrees()).collect();
    let mut tr: Vec<f64> = errors
        .iter()
        .filter_map(|e| e.t_dir_err_rad.map(f64::to_degrees))
        .collect();
    rot.sort_by(f64::total_cmp);
    tr.sort_by(f64::total_cmp);
    ErrorStats {
        rot_count: rot.len(),
        rot_median_deg: percentile(&rot, 0.5),
        rot_p95_deg: percentile(&rot, 0.95),
        rot_max_deg: rot.last().copied().unwrap_or(f64::NAN),
        t_count: tr.len(),
        t_median_deg: percentile(&tr, 0.5),
        t_p95_deg: percentile(&tr, 0.95),
        t_max_deg: tr.last().copied().unwrap_or(f64::NAN),
        t_over_90: tr.iter().filter(|&&a| a > 90.0).count(),
    }
}

impl fmt::Display for ErrorStats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "rotation error (deg, n={}): median {:.4}  p95 {:.4}  max {:.4}",
            self.rot_count, self.rot_median_deg, self.rot_p95_deg, self.rot_max_deg
        )?;
        write!(
            f,
            "translation direction error (deg, n={}): median {:.3}  p95 {:.3}  max {:.3}  >90°: {}",
            self.t_count, self.t_median_deg, self.t_p95_deg, self.t_max_deg, self.t_over_90
        )
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::frontend::{NoMeasurement, StageTimings};

    #[test]
    fn csv_columns() {
        assert!(CSV_HEADER.starts_with(
            "t0_ns,t1_ns,tracked,inliers,qw,qx,qy,qz,tx,ty,tz,decode_us,track_us,solve_us,"
        ));
        let n = CSV_HEADER.split(',').count();
        let r = FrameResult {
            t0_ns: None,
            t1_ns: 5,
            outcome: Err(NoMeasurement::NoReference),
            timings: StageTimings::default(),
            tracked: 0,
        };
        let row = csv_row(&r);
        assert_eq!(row.split(',').count(), n, "{row}");
        assert!(row.contains("NaN,NaN,NaN,NaN,0,0,0"));
        assert!(row.contains("no_reference"));
    }

    #[test]
    fn stats() {
        let e: Vec<PairError> = (0..100)
            .map(|i| PairError {
                rot_err_rad: f64::from(i).to_radians(),
                t_dir_err_rad: Some(f64::from(i * 2).to_radians()),
            })
            .collect();
        let s = error_stats(&e);
        assert!((s.rot_median_deg - 50.0).abs() < 1.0);
        assert_eq!(s.t_over_90, 54);
        assert!((s.rot_max_deg - 99.0).abs() < 1e-9);
    }
}
