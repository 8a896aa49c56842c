//! GNSS antenna position (paper eq. 32): `p_ant = p + C r + e_gnss + n`, where `e_gnss` is the
//! first-order Gauss–Markov GNSS error state and `n` white noise.
//!
//! Logic: fuse when the gate passes; reject glitches; when rejected continuously for longer than
//! `gnss_reset_timeout_ns` (e.g. recovery after a long outage with a drifted solution), inflate the
//! position covariance by the squared innovation and fuse, so the state moves by no more than its
//! stated (inflated) uncertainty instead of jumping.

use nalgebra::{Matrix3, SMatrix, Vector3};
use uavnav_core::rotation::skew;

use super::{InnovDiag, UpdateOutcome, gated_update};
use crate::state::{Cov, ErrVec, IGM, IP, ITH, N, Nominal};

/// One GNSS fix in the local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssMeas {
    /// Time of validity, ns.
    pub t_ns: i64,
    /// Antenna position, local NED, m.
    pub pos_ned_m: Vector3<f64>,
    /// Antenna velocity, NED, m/s, when the receiver gave all three components (fixes without
    /// velocity, or without its vertical component, are fused for position only).
    pub vel_ned_mps: Option<Vector3<f64>>,
    /// Reported 1-σ horizontal position, m.
    pub sigma_h_m: f64,
    /// Reported 1-σ vertical position, m.
    pub sigma_v_m: f64,
    /// Reported 1-σ velocity per axis, m/s (meaningless without `vel_ned_mps`).
    pub sigma_vel_mps: f64,
}

impl GnssMeas {
    /// The measurement of one fix in the local frame `frame`.
    pub fn from_fix(fix: &uavnav_core::GnssFix, pos_ned_m: Vector3<f64>) -> Self {
        Self {
            t_ns: fix.t_ns,
            pos_ned_m,
            vel_ned_mps: fix.velocity.and_then(|v| v.ned_mps()),
            sigma_h_m: fix.sigma_h_m,
            sigma_v_m: fix.sigma_v_m,
            sigma_vel_mps: fix.velocity.map_or(f64::INFINITY, |v| v.sigma_mps),
        }
    }
}

/// Predicted antenna position, its residual and Jacobian `H` (w.r.t. the error state).
pub fn model(
    x: &Nominal,
    lever_b: &Vector3<f64>,
    z: &Vector3<f64>,
) -> (Vector3<f64>, SMatrix<f64, 3, N>) {
    let c = x.q.to_rotation_matrix();
    let cr = c * lever_b;
    let pred = x.p + cr + x.gm;
    let mut h = SMatrix::<f64, 3, N>::zeros();
    h.fixed_view_mut::<3, 3>(0, IP)
        .copy_from(&Matrix3::identity());
    h.fixed_view_mut::<3, 3>(0, ITH).copy_from(&(-skew(&cr)));
    h.fixed_view_mut::<3, 3>(0, IGM)
        .copy_from(&Matrix3::identity());
    (z - pred, h)
}

/// The GNSS position aiding source.
#[derive(Debug, Clone, PartialEq)]
pub struct GnssPosSource {
    /// Diagnostics.
    pub diag: InnovDiag,
    /// Resets performed (inflate-and-fuse).
    pub resets: u32,
}

impl Default for GnssPosSource {
    fn default() -> Self {
        Self {
            diag: InnovDiag::new(),
            resets: 0,
        }
    }
}

/// The white part of the measurement noise given the reported σ and the correlated fraction.
pub fn white_noise(meas: &GnssMeas, correlated_fraction: f64, floor_m: f64) -> Matrix3<f64> {
    let wf = (1.0 - correlated_fraction).max(0.0);
    let h = (wf * meas.sigma_h_m.powi(2)).max(floor_m * floor_m);
    let v = (wf * meas.sigma_v_m.powi(2)).max(floor_m * floor_m);
    Matrix3::from_diagonal(&Vector3::new(h, h, v))
}

impl GnssPosSource {
    /// Fuses one fix; returns the correction to inject, if any.
    #[allow(clippy::too_many_arguments)]
    pub fn fuse(
        &mut self,
        x: &Nominal,
        p: &mut Cov,
        lever_b: &Vector3<f64>,
        meas: &GnssMeas,
        r: &Matrix3<f64>,
        gate_sigma: f64,
        reset_timeout_ns: i64,
    ) -> Option<ErrVec> {
        let (y, h) = model(x, lever_b, &meas.pos_ned_m);
        let stuck = self.diag.consecutive_rejects > 0
            && meas.t_ns - self.diag.first_reject_t_ns >= reset_timeout_ns;
        if stuck {
            // Inflate rather than jump: the covariance grows to cover the innovation first.
            for k in 0..3 {
                p[(IP + k, IP + k)] += y[k] * y[k];
            }
            self.resets += 1;
        }
        match gated_update(p, &h, r, &y, gate_sigma, meas.t_ns, stuck, &mut self.diag) {
            UpdateOutcome::Fused(dx) => Some(dx),
            _ => None,
        }
    }
}
