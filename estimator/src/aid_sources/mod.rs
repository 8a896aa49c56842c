//! Aiding sources of the error-state EKF, one file each (as PX4 EKF2 `aid_sources/`), sharing the
//! gated Kalman update and a uniform innovation diagnostics record.
//!
//! | module | measurement |
//! |---|---|
//! | [`baro_height`] | barometric height (ISA, eq. B1) with a drifting offset; holds the height without GNSS |
//! | [`gnss_consistency`] | not a measurement: the receiver's velocities against its positions (eq. V1), which sets how far its velocities are trusted |
//! | [`gnss_pos`] | antenna position through the lever arm (paper eq. 32) + Gauss–Markov error |
//! | [`gnss_vel`] | antenna velocity with the `C(ω×r)` term (paper eq. 33) |
//! | [`mag_calibration`] | not fused into the filter: the compass's hard-iron offset and its own field from the 3-axis field and the tilt (eq. M2), applied by `mag_heading` |
//! | [`mag_heading`] | magnetometer heading against the WMM2025 declination (eq. M1) |
//! | [`position_hold`] | not a sensor: the hold point that bounds a filter without position aiding (eq. H1) |
//! | [`vision`] | relative rotation and direction of travel / metric translation between frames |

pub mod baro_height;
pub mod gnss_consistency;
pub mod gnss_pos;
pub mod gnss_vel;
pub mod mag_calibration;
pub mod mag_heading;
pub mod position_hold;
pub mod vision;

use nalgebra::{SMatrix, SVector};

use crate::prediction::symmetrize;
use crate::state::{Cov, ErrVec, N};

/// Innovation diagnostics of one aiding source (returned in every [`crate::Health`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct InnovDiag {
    /// Last innovation (measurement − prediction), up to 3 components (unused are 0).
    pub innov: [f64; 3],
    /// Last innovation variances (diagonal of S).
    pub innov_var: [f64; 3],
    /// Last test ratio NIS / gate (> 1 = rejected).
    pub test_ratio: f64,
    /// Measurements fused.
    pub fused: u64,
    /// Measurements rejected by the gate.
    pub rejected: u64,
    /// Rejections in a row (reset by a fusion).
    pub consecutive_rejects: u32,
    /// Time of the last fusion, ns (`i64::MIN` = never).
    pub last_fused_t_ns: i64,
    /// Time of the first rejection of the current run of rejections, ns.
    pub first_reject_t_ns: i64,
}

impl InnovDiag {
    /// A fresh record (never fused).
    pub fn new() -> Self {
        Self {
            last_fused_t_ns: i64::MIN,
            first_reject_t_ns: i64::MIN,
            ..Default::default()
        }
    }

    /// Whether this source was fused within `timeout_ns` of `t_ns`.
    pub fn active(&self, t_ns: i64, timeout_ns: i64) -> bool {
        self.last_fused_t_ns != i64::MIN && t_ns - self.last_fused_t_ns <= timeout_ns
    }
}

/// The chi-square gate for `dof` degrees of freedom at the normal quantile `z`
/// (Wilson–Hilferty approximation, within 3 % of the exact quantile for dof ≥ 1 and z ≈ 3).
pub fn chi2_gate(dof: usize, z: f64) -> f64 {
    let k = dof as f64;
    let c = 2.0 / (9.0 * k);
    k * (1.0 - c + z * c.sqrt()).powi(3)
}

/// `P Hᵀ` skipping the all-zero 3-column blocks of `H` (measurement Jacobians touch 2–4 of 8).
pub fn p_ht<const M: usize>(p: &Cov, h: &SMatrix<f64, M, N>) -> SMatrix<f64, N, M> {
    let mut out = SMatrix::<f64, N, M>::zeros();
    for b in 0..N / 3 {
        let hb = h.fixed_columns::<3>(3 * b);
        if hb.iter().any(|x| *x != 0.0) {
            out += p.fixed_columns::<3>(3 * b) * hb.transpose();
        }
    }
    out
}

/// Outcome of a gated update.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum UpdateOutcome {
    /// Fused; the correction to inject.
    Fused(ErrVec),
    /// Rejected by the innovation gate.
    Rejected,
    /// Numerically unusable (S not positive definite).
    Singular,
}

/// A gated Kalman update of dimension `M`: computes `S = H P Hᵀ + R`, the test ratio
/// `yᵀ S⁻¹ y / χ²_gate(M)`, and, when it passes (or `force`), `K = P Hᵀ S⁻¹`, `P ← P − K S Kᵀ`.
/// Diagnostics are written to `diag`; `P` is untouched on rejection.
#[allow(clippy::too_many_arguments)]
pub fn gated_update<const M: usize>(
    p: &mut Cov,
    h: &SMatrix<f64, M, N>,
    r: &SMatrix<f64, M, M>,
    y: &SVector<f64, M>,
    gate_sigma: f64,
    t_ns: i64,
    force: bool,
    diag: &mut InnovDiag,
) -> UpdateOutcome {
    gated_update_considering(p, h, r, y, gate_sigma, t_ns, force, diag, &[])
}

/// [`gated_update`], with the error states `consider` left uncorrected (a Schmidt update):
/// used for a state the measurement cannot honestly tell (the heading seen through a hovering
/// vehicle's velocity).
#[allow(clippy::too_many_arguments)]
pub fn gated_update_considering<const M: usize>(
    p: &mut Cov,
    h: &SMatrix<f64, M, N>,
    r: &SMatrix<f64, M, M>,
    y: &SVector<f64, M>,
    gate_sigma: f64,
    t_ns: i64,
    force: bool,
    diag: &mut InnovDiag,
    consider: &[usize],
) -> UpdateOutcome {
    let pht = p_ht(p, h);
    let s = h * pht + r;
    let Some(chol) = s.cholesky() else {
        return UpdateOutcome::Singular;
    };
    let s_inv_y = chol.solve(y);
    let nis = y.dot(&s_inv_y);
    diag.innov = [0.0; 3];
    diag.innov_var = [0.0; 3];
    for k in 0..M.min(3) {
        diag.innov[k] = y[k];
        diag.innov_var[k] = s[(k, k)];
    }
    diag.test_ratio = nis / chi2_gate(M, gate_sigma);
    if !force && (diag.test_ratio > 1.0 || !nis.is_finite()) {
        diag.rejected += 1;
        if diag.consecutive_rejects == 0 {
            diag.first_reject_t_ns = t_ns;
        }
        diag.consecutive_rejects += 1;
        return UpdateOutcome::Rejected;
    }
    // K = P Hᵀ S⁻¹  ⇔  Kᵀ = S⁻¹ H P.
    let kt = chol.solve(&pht.transpose());
    let mut k = kt.transpose();
    if consider.is_empty() {
        *p -= k * pht.transpose();
    } else {
        // Schmidt ("consider") update: the considered states keep their estimate, their
        // uncertainty still shapes the gain of the others, and the covariance stays that of the
        // gain actually applied. Joseph form, valid for any gain, expanded so that it costs
        // N²·M instead of two N³ products: (I − KH) P (I − KH)ᵀ + K R Kᵀ
        // = P − K (PHᵀ)ᵀ − PHᵀ Kᵀ + K S Kᵀ, with S = H P Hᵀ + R (P symmetric).
        for &i in consider {
            k.row_mut(i).fill(0.0);
        }
        let ks = k * s;
        *p -= k * pht.transpose() + pht * k.transpose() - ks * k.transpose();
    }
    let dx = k * y;
    symmetrize(p);
    diag.fused += 1;
    diag.consecutive_rejects = 0;
    diag.last_fused_t_ns = t_ns;
    UpdateOutcome::Fused(dx)
}

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix3, Vector3};

    use super::*;
    use crate::state::{ITH, IV};

    /// A covariance with the velocity correlated to the yaw (as after a manoeuvre), and a
    /// velocity measurement.
    fn setup() -> (Cov, SMatrix<f64, 3, N>, Matrix3<f64>, Vector3<f64>) {
        let mut p = Cov::identity() * 0.04;
        p[(ITH + 2, ITH + 2)] = 0.09;
        p[(IV, ITH + 2)] = 0.03;
        p[(ITH + 2, IV)] = 0.03;
        let mut h = SMatrix::<f64, 3, N>::zeros();
        for k in 0..3 {
            h[(k, IV + k)] = 1.0;
        }
        (
            p,
            h,
            Matrix3::identity() * 0.01,
            Vector3::new(0.3, -0.1, 0.05),
        )
    }

    fn fuse(consider: &[usize]) -> (ErrVec, Cov) {
        let (mut p, h, r, y) = setup();
        let mut diag = InnovDiag::new();
        let UpdateOutcome::Fused(dx) =
            gated_update_considering(&mut p, &h, &r, &y, 1e3, 0, false, &mut diag, consider)
        else {
            panic!("not fused")
        };
        (dx, p)
    }

    #[test]
    fn a_considered_state_is_not_corrected_and_keeps_an_honest_covariance() {
        let (dx_all, p_all) = fuse(&[]);
        let (dx, p) = fuse(&[ITH + 2]);
        assert!(dx_all[ITH + 2].abs() > 0.1, "the yaw is corrected normally");
        assert_eq!(dx[ITH + 2], 0.0, "the considered yaw is not corrected");
        // The other states get the same correction (their gain is the optimal one).
        for i in (0..N).filter(|&i| i != ITH + 2) {
            assert!((dx[i] - dx_all[i]).abs() < 1e-12, "state {i}");
        }
        // The yaw keeps its variance; the others shrink as in the optimal update; the result is
        // symmetric positive definite.
        assert!((p[(ITH + 2, ITH + 2)] - 0.09).abs() < 1e-12);
        for i in (0..N).filter(|&i| i != ITH + 2) {
            assert!((p[(i, i)] - p_all[(i, i)]).abs() < 1e-12, "state {i}");
        }
        assert!(p.cholesky().is_some());
        assert!((p - p.transpose()).abs().max() < 1e-15);
    }
}
