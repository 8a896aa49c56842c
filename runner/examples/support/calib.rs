//! Calibration diagnostics for `paper_run`: the vision measurement errors against their stated
//! covariance (per eigen-direction, per component, time correlation), the estimator's innovation
//! statistics (NIS) of the vision source, and attitude errors by flight segment.
//!
//! Why per eigen-direction: the plane solver's rotation and translation errors are correlated
//! (|ρ| ≈ 0.99), so the joint covariance has a few "thin" directions; a mean NEES can look fine
//! while those thin directions — the ones a joint update relies on — are badly over- or
//! under-stated.

use nalgebra::{Matrix3, Matrix6, SMatrix, SymmetricEigen, Vector3, Vector6};
use uavnav_core::TruthSample;
use uavnav_core::rotation::euler_error;
use uavnav_core::truth::truth_at;
use uavnav_estimator::PoseOutput;
use uavnav_estimator::aid_sources::chi2_gate;

/// Accumulates `(whitened error)²` per eigen-direction of the joint 6×6 covariance and the
/// empirical against the stated covariance.
#[derive(Default)]
pub struct JointCalib {
    n: usize,
    /// Σ (vₖᵀe)²/λₖ, eigenvalues ascending (each mean should be 1).
    eig_sq: [f64; 6],
    /// Σ e eᵀ.
    emp: Matrix6<f64>,
    /// Σ C.
    stated: Matrix6<f64>,
    /// 5-dof NEES [δθ; direction tangent] (5 expected).
    nees5: Vec<f64>,
    /// Whitened joint errors (C^{-1/2} e), for the lag-1 autocorrelation.
    white: Vec<Vector6<f64>>,
    /// Raw errors (µrad, mm).
    raw: Vec<Vector6<f64>>,
    /// Relative scale error (|t| − |t_true|)/|t_true|.
    scale: Vec<f64>,
    /// Frame-0 time of each scale error, ns.
    scale_t0_ns: Vec<i64>,
    /// Frame-0 time of each raw error, ns.
    raw_t0_ns: Vec<i64>,
    /// Error in the eigenbasis of its covariance, unit variance expected, thin → thick.
    eig_z: Vec<Vector6<f64>>,
}

fn inv_sqrt(c: &Matrix6<f64>) -> Option<(Matrix6<f64>, SymmetricEigen<f64, nalgebra::U6>)> {
    let eig = SymmetricEigen::new(*c);
    if eig.eigenvalues.iter().any(|&l| l <= 0.0 || !l.is_finite()) {
        return None;
    }
    let d = Matrix6::from_diagonal(&eig.eigenvalues.map(|l| 1.0 / l.sqrt()));
    Some((eig.eigenvectors * d * eig.eigenvectors.transpose(), eig))
}

impl JointCalib {
    /// Adds one metric measurement: `e = [δθ; t − t_true]`, its joint covariance `c`, the true `t`.
    pub fn add(&mut self, t0_ns: i64, e: &Vector6<f64>, c: &Matrix6<f64>, t_true: &Vector3<f64>) {
        let Some((w, eig)) = inv_sqrt(c) else { return };
        let mut idx: Vec<usize> = (0..6).collect();
        idx.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        let mut z = Vector6::zeros();
        for (k, &i) in idx.iter().enumerate() {
            let v = eig.eigenvectors.column(i);
            // sign fixed by the largest component so consecutive eigenvectors agree
            let (imax, _) = v.iamax_full();
            let sgn = v[imax].signum();
            z[k] = sgn * v.dot(e) / eig.eigenvalues[i].sqrt();
            self.eig_sq[k] += v.dot(e).powi(2) / eig.eigenvalues[i];
        }
        self.eig_z.push(z);
        self.emp += e * e.transpose();
        self.stated += c;
        self.white.push(w * e);
        self.raw.push(e * 1e6);
        self.raw_t0_ns.push(t0_ns);
        self.raw
            .last_mut()
            .unwrap()
            .fixed_rows_mut::<3>(3)
            .scale_mut(1e-3);
        self.n += 1;
        // direction: tangent-plane error of the unit vector, J = (I − uuᵀ)/|t|
        let t_meas = t_true + e.fixed_rows::<3>(3);
        let n = t_true.norm();
        if n > 1e-6 {
            self.scale.push((t_meas.norm() - n) / n);
            self.scale_t0_ns.push(t0_ns);
            let u = t_true / n;
            let b = tangent_basis(&u);
            let j = b.transpose() * (Matrix3::identity() - u * u.transpose()) / n;
            let mut a = SMatrix::<f64, 5, 6>::zeros();
            a.fixed_view_mut::<3, 3>(0, 0)
                .copy_from(&Matrix3::identity());
            a.fixed_view_mut::<2, 3>(3, 3).copy_from(&j);
            let e5 = a * e;
            let c5 = a * c * a.transpose();
            if let Some(inv) = c5.try_inverse() {
                self.nees5.push((e5.transpose() * inv * e5)[0]);
            }
        }
    }

    /// A printable summary.
    pub fn summary(&self) -> String {
        if self.n == 0 {
            return "joint calibration: no metric measurement".into();
        }
        let n = self.n as f64;
        let eig: Vec<String> = self
            .eig_sq
            .iter()
            .map(|s| format!("{:.2}", s / n))
            .collect();
        let emp = self.emp / n;
        let st = self.stated / n;
        let ratio: Vec<String> = (0..6)
            .map(|i| format!("{:.2}", (emp[(i, i)] / st[(i, i)]).sqrt()))
            .collect();
        let corr =
            |m: &Matrix6<f64>, i: usize, j: usize| m[(i, j)] / (m[(i, i)] * m[(j, j)]).sqrt();
        let pairs = [(0, 4), (1, 3), (0, 3), (1, 4), (2, 3), (2, 4)];
        let corr_s: Vec<String> = pairs
            .iter()
            .map(|&(i, j)| {
                format!(
                    "({i},{j}) emp {:+.3} stated {:+.3}",
                    corr(&emp, i, j),
                    corr(&st, i, j)
                )
            })
            .collect();
        let lag1: Vec<String> = (0..6)
            .map(|k| {
                let (mut num, mut den) = (0.0, 0.0);
                for w in self.white.windows(2) {
                    num += w[0][k] * w[1][k];
                    den += w[0][k] * w[0][k];
                }
                format!("{:+.2}", num / den.max(1e-300))
            })
            .collect();
        let mut mean = Vector6::zeros();
        for r in &self.raw {
            mean += r / n;
        }
        let raw_s: Vec<String> = (0..6)
            .map(|k| {
                let sd = (self
                    .raw
                    .iter()
                    .map(|r| (r[k] - mean[k]).powi(2))
                    .sum::<f64>()
                    / n)
                    .sqrt();
                let (mut num, mut den) = (0.0, 0.0);
                for w in self.raw.windows(2) {
                    num += (w[0][k] - mean[k]) * (w[1][k] - mean[k]);
                    den += (w[0][k] - mean[k]).powi(2);
                }
                format!("{:+.1}±{:.1} ρ1 {:+.2}", mean[k], sd, num / den.max(1e-300))
            })
            .collect();
        let nees5 = self.nees5.iter().sum::<f64>() / self.nees5.len().max(1) as f64;
        let sc_mean = self.scale.iter().sum::<f64>() / self.scale.len().max(1) as f64;
        let sc_sd = (self
            .scale
            .iter()
            .map(|s| (s - sc_mean).powi(2))
            .sum::<f64>()
            / self.scale.len().max(1) as f64)
            .sqrt();
        format!(
            "joint calibration ({} metric measurements; components [δθx δθy δθz tx ty tz], camera-1):\n  \
             mean (vₖᵀe)²/λₖ by eigenvalue, thin → thick (1 expected): [{}]\n  \
             empirical/stated σ per component: [{}]\n  \
             correlations: {}\n  \
             lag-1 autocorrelation of the whitened error: [{}]\n  \
             raw error mean±sd (µrad, mm) and lag-1 autocorrelation: [{}]\n  \
             5-dof [δθ; direction] NEES mean {:.2} (5 expected); scale error mean {:+.4} sd {:.4}",
            self.n,
            eig.join(" "),
            ratio.join(" "),
            corr_s.join("; "),
            lag1.join(" "),
            raw_s.join("; "),
            nees5,
            sc_mean,
            sc_sd
        )
    }
}

impl JointCalib {
    /// Mean raw error per window of `win_s` (µrad, mm): slowly varying biases show here.
    pub fn windowed_means(&self, win_s: f64) -> String {
        let Some(&t_first) = self.raw_t0_ns.first() else {
            return String::new();
        };
        let mut out =
            String::from("vision error means per window [δθx δθy δθz] µrad, [tx ty tz] mm:");
        let win_ns = (win_s * 1e9) as i64;
        let mut k = 0;
        while k < self.raw.len() {
            let w = (self.raw_t0_ns[k] - t_first) / win_ns;
            let mut sum = Vector6::zeros();
            let mut n = 0.0;
            while k < self.raw.len() && (self.raw_t0_ns[k] - t_first) / win_ns == w {
                sum += self.raw[k];
                n += 1.0;
                k += 1;
            }
            let m = sum / n;
            out += &format!(
                "\n  {:>4}s: [{:+.1} {:+.1} {:+.1}] [{:+.2} {:+.2} {:+.2}]",
                w * (win_ns / 1_000_000_000),
                m[0],
                m[1],
                m[2],
                m[3],
                m[4],
                m[5]
            );
        }
        out
    }

    /// Variance of the window means of the whitened eigen-components, times the window size:
    /// 1 for white errors, larger when the errors are time-correlated (then their long-run
    /// average carries that much less information than the filter assumes).
    pub fn long_run_inflation(&self, n_win: usize) -> String {
        let mut acc = [0.0; 6];
        let mut w = 0.0f64;
        for chunk in self.eig_z.chunks_exact(n_win) {
            let m: Vector6<f64> = chunk.iter().sum::<Vector6<f64>>() / n_win as f64;
            for k in 0..6 {
                acc[k] += m[k] * m[k] * n_win as f64;
            }
            w += 1.0;
        }
        let v: Vec<String> = acc
            .iter()
            .map(|a| format!("{:.1}", a / w.max(1.0)))
            .collect();
        format!(
            "long-run variance inflation per eigen-direction (windows of {n_win} frames, thin → thick, 1 = white): [{}]",
            v.join(" ")
        )
    }

    /// How much of the scale error the filter's own height error explains: the plane solver takes
    /// the ground distance from the filter, so `|t_meas|/|t_true| − 1 ≈ (ĥ − h)/h`.
    pub fn scale_vs_height(
        &self,
        poses: &[PoseOutput],
        truth: &[TruthSample],
        terrain_m: f64,
        frame: &uavnav_core::LocalFrame,
    ) -> String {
        let (mut sxy, mut sxx, mut syy, mut sres, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0f64);
        for (&t0, &sc) in self.scale_t0_ns.iter().zip(&self.scale) {
            let i = poses.partition_point(|p| p.t_ns < t0);
            let (Some(p), Some(t)) = (poses.get(i), truth_at(truth, t0)) else {
                continue;
            };
            let h_true = frame.ned_to_lla(&t.pos_ned_m).alt_m - terrain_m;
            let pred = (p.lla.alt_m - terrain_m) / h_true - 1.0;
            sxy += sc * pred;
            sxx += pred * pred;
            syy += sc * sc;
            sres += (sc - pred).powi(2);
            n += 1.0;
        }
        format!(
            "scale error vs the filter's height error: corr {:.2}, rms {:.4} → {:.4} after removing it (n {})",
            sxy / (sxx * syy).sqrt().max(1e-300),
            (syy / n.max(1.0)).sqrt(),
            (sres / n.max(1.0)).sqrt(),
            n
        )
    }
}

fn tangent_basis(u: &Vector3<f64>) -> SMatrix<f64, 3, 2> {
    let helper = if u.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let b1 = u.cross(&helper).normalize();
    let b2 = u.cross(&b1);
    SMatrix::<f64, 3, 2>::from_columns(&[b1, b2])
}

/// The estimator's NIS of each vision update, read from the health of the outputs.
#[derive(Default)]
pub struct NisTracker {
    last_rot: u64,
    last_trans: u64,
    rot: Vec<f64>,
    trans: Vec<f64>,
    gate_sigma: f64,
}

impl NisTracker {
    /// A tracker for the gate the estimator uses.
    pub fn new(gate_sigma: f64) -> Self {
        Self {
            gate_sigma,
            ..Self::default()
        }
    }

    /// Records the NIS of a vision update that happened since the previous output.
    /// `rot_dof`/`trans_dof`: the update dimensions.
    pub fn observe(&mut self, p: &PoseOutput, rot_dof: usize, trans_dof: usize) {
        let h = &p.health;
        if h.vision_rot.fused > self.last_rot {
            self.rot
                .push(h.vision_rot.test_ratio * chi2_gate(rot_dof, self.gate_sigma));
        }
        if h.vision_trans.fused > self.last_trans {
            self.trans
                .push(h.vision_trans.test_ratio * chi2_gate(trans_dof, self.gate_sigma));
        }
        self.last_rot = h.vision_rot.fused;
        self.last_trans = h.vision_trans.fused;
    }

    /// Mean NIS and the fraction above the 95 % χ² quantile, per source.
    pub fn summary(&self, rot_dof: usize, trans_dof: usize) -> String {
        let stat = |v: &[f64], dof: usize| {
            let q95 = chi2_gate(dof, 1.645);
            let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
            let above = v.iter().filter(|&&x| x > q95).count() as f64 / v.len().max(1) as f64;
            format!(
                "mean {mean:.2} ({dof} expected), {:.1} % above χ²₉₅ (5 % expected), n {}",
                100.0 * above,
                v.len()
            )
        };
        format!(
            "estimator vision NIS: rotation {}; translation {}",
            stat(&self.rot, rot_dof),
            stat(&self.trans, trans_dof)
        )
    }
}

/// Attitude error (mean, RMS, mean stated σ; deg) over `[from_s, to_s)` after the first output.
pub fn segment_errors(
    poses: &[PoseOutput],
    truth: &[TruthSample],
    t0_ns: i64,
    segments: &[(f64, f64)],
) -> String {
    let mut out = String::from("attitude error by segment (roll, pitch, yaw; deg):");
    for &(a, b) in segments {
        let (lo, hi) = (t0_ns + (a * 1e9) as i64, t0_ns + (b * 1e9) as i64);
        let (mut sum, mut sq, mut sig, mut n) =
            (Vector3::zeros(), Vector3::zeros(), Vector3::zeros(), 0usize);
        for p in poses.iter().filter(|p| p.t_ns >= lo && p.t_ns < hi) {
            let Some(t) = truth_at(truth, p.t_ns) else {
                continue;
            };
            let e = euler_error(&p.nav_from_body, &t.nav_from_body).map(f64::to_degrees);
            sum += e;
            sq += e.component_mul(&e);
            sig += p.sigma_att_rad.map(f64::to_degrees);
            n += 1;
        }
        let k = n.max(1) as f64;
        let (m, r, s) = (sum / k, (sq / k).map(f64::sqrt), sig / k);
        out += &format!(
            "\n  {a:>5.0}–{b:<5.0} s: mean [{:+.4} {:+.4} {:+.4}] rms [{:.4} {:.4} {:.4}] σ [{:.4} {:.4} {:.4}]",
            m.x, m.y, m.z, r.x, r.y, r.z, s.x, s.y, s.z
        );
    }
    out
}

/// The poses one every `step_s` of flight from `t0_ns`, each with its time (s) and the truth then.
fn sampled<'a>(
    poses: &'a [PoseOutput],
    truth: &'a [TruthSample],
    t0_ns: i64,
    step_s: f64,
) -> impl Iterator<Item = (f64, &'a PoseOutput, TruthSample)> + 'a {
    let mut next = 0.0;
    poses.iter().filter_map(move |p| {
        let t_s = (p.t_ns - t0_ns) as f64 * 1e-9;
        if t_s < next {
            return None;
        }
        next += step_s;
        truth_at(truth, p.t_ns).map(|t| (t_s, p, t))
    })
}

/// Roll, pitch and yaw errors (deg) every `step_s`: where the RMSE comes from.
pub fn attitude_series(
    poses: &[PoseOutput],
    truth: &[TruthSample],
    t0_ns: i64,
    step_s: f64,
) -> String {
    let mut out = format!("attitude error (roll, pitch, yaw) every {step_s} s, deg:");
    for (t_s, p, t) in sampled(poses, truth, t0_ns, step_s) {
        let e = euler_error(&p.nav_from_body, &t.nav_from_body).map(f64::to_degrees);
        out += &format!(" {t_s:.0}:{:+.3},{:+.3},{:+.3}", e.x, e.y, e.z);
    }
    out
}

/// Yaw error and stated yaw σ (deg), gyro z-bias error and body-frame velocity error every
/// `step_s`, for a quick look at drifts and jumps.
pub fn yaw_series(poses: &[PoseOutput], truth: &[TruthSample], t0_ns: i64, step_s: f64) -> String {
    let mut out = format!("yaw error (σ) every {step_s} s, deg:");
    for (t_s, p, t) in sampled(poses, truth, t0_ns, step_s) {
        let e = euler_error(&p.nav_from_body, &t.nav_from_body).map(f64::to_degrees);
        // gyro z-bias error, µrad/s (est − truth; truth in body axes)
        let db = (p.gyro_bias_radps.z - t.gyro_bias_radps.z) * 1e6;
        // velocity error in the true body frame (forward, right), mm/s
        let dv = t.nav_from_body.inverse() * (p.vel_ned_mps - t.vel_ned_mps) * 1e3;
        out += &format!(
            " {t_s:.0}:{:+.3}({:.3})b{:+.0}v{:+.0},{:+.0}",
            e.z,
            p.sigma_att_rad.z.to_degrees(),
            db,
            dv.x,
            dv.y
        );
    }
    out
}
