//! GNSS antenna position (paper eq. 32): `p_ant = p + C r + e_gnss + n`, where `e_gnss` is the
//! first-order Gauss–Markov GNSS error state and `n` white noise.
//!
//! Logic: fuse when the gate passes; reject glitches; when rejected continuously for longer than
//! `gnss_reset_timeout_ns` (e.g. recovery after a long outage with a drifted solution), inflate the
//! position covariance by the squared innovation and fuse, so the state moves by no more than its
//! stated (inflated) uncertainty instead of jumping.

use nalgebra::{Matrix3, SMatrix, Vector3};
use uavnav_core::rotation::skew;

use super::{InnovDiag, UpdateOutcome, gated_update_considering};
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
    /// Horizontal antenna velocity (north, east), m/s, whenever the receiver gives one, also
    /// without a vertical component (ground speed and course): the yaw bank and the alignment
    /// need no more.
    pub vel_h_mps: Option<nalgebra::Vector2<f64>>,
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
            vel_h_mps: fix.velocity.map(|v| v.horizontal_mps()),
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
    /// The 1-σ of the correlated GNSS error the filter currently models (N, E, D), m: the
    /// correlated share of the receiver's reported accuracy, see [`Self::follow_accuracy`].
    pub gm_sigma_m: Option<Vector3<f64>>,
}

impl Default for GnssPosSource {
    fn default() -> Self {
        Self {
            diag: InnovDiag::new(),
            resets: 0,
            gm_sigma_m: None,
        }
    }
}

/// The correlated share of a fix's reported accuracy, 1-σ per NED axis, m.
pub fn correlated_sigma(meas: &GnssMeas, correlated_fraction: f64) -> Vector3<f64> {
    let f = correlated_fraction.clamp(0.0, 1.0).sqrt();
    Vector3::new(f * meas.sigma_h_m, f * meas.sigma_h_m, f * meas.sigma_v_m)
}

/// The process-noise PSD per axis that keeps a first-order Gauss–Markov state of correlation
/// time `tau_s` at the 1-σ `sigma_m` (`q = 2 σ² / τ`), m²/s.
pub fn gm_psd(sigma_m: &Vector3<f64>, tau_s: f64) -> [f64; 3] {
    let q = |s: f64| 2.0 * s * s / tau_s.max(1e-3);
    [q(sigma_m.x), q(sigma_m.y), q(sigma_m.z)]
}

/// The white part of the measurement noise given the reported σ and the correlated fraction.
pub fn white_noise(meas: &GnssMeas, correlated_fraction: f64, floor_m: f64) -> Matrix3<f64> {
    let wf = (1.0 - correlated_fraction).max(0.0);
    let h = (wf * meas.sigma_h_m.powi(2)).max(floor_m * floor_m);
    let v = (wf * meas.sigma_v_m.powi(2)).max(floor_m * floor_m);
    Matrix3::from_diagonal(&Vector3::new(h, h, v))
}

impl GnssPosSource {
    /// Makes the Gauss–Markov error state follow the receiver's reported accuracy; returns the
    /// process-noise PSD per axis that keeps it at that size, m²/s.
    ///
    /// The correlated GNSS error is modelled as `e = s(t) u`, `u` a unit-variance first-order
    /// Gauss–Markov process and `s(t)` the correlated share of the reported σ. A receiver's σ
    /// shrinks as its solution converges (7.2 m → 1.6 m over the first minutes on a real plane),
    /// and the error with it: the state and its rows of `P` are scaled by `s₁/s₀` (the linear
    /// change of variables `P ← T P Tᵀ`). Fixing `s` at the first fix's σ let the state carry
    /// up to 12 m of "GNSS error" there for the rest of the flight. The scaling is the same in
    /// both directions, so a σ that jitters from fix to fix neither pumps variance into the state
    /// nor drains it (adding `s₁² − s₀²` on every rise did: 0.95 → 1.70 m from the fixes on a
    /// real copter whose σ jitters by 1 %).
    pub fn follow_accuracy(
        &mut self,
        x: &mut Nominal,
        p: &mut Cov,
        meas: &GnssMeas,
        correlated_fraction: f64,
        tau_s: f64,
    ) -> [f64; 3] {
        let s1 = correlated_sigma(meas, correlated_fraction);
        if let Some(s0) = self.gm_sigma_m {
            for k in 0..3 {
                if s0[k] > 0.0 && s1[k] > 0.0 && s1[k] != s0[k] {
                    let (i, r) = (IGM + k, s1[k] / s0[k]);
                    x.gm[k] *= r;
                    for j in 0..N {
                        p[(i, j)] *= r;
                        p[(j, i)] *= r;
                    }
                }
            }
        }
        self.gm_sigma_m = Some(s1);
        gm_psd(&s1, tau_s)
    }

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
        consider: &[usize],
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
        match gated_update_considering(
            p,
            &h,
            r,
            &y,
            gate_sigma,
            meas.t_ns,
            stuck,
            &mut self.diag,
            consider,
        ) {
            UpdateOutcome::Fused(dx) => Some(dx),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meas(sigma_h_m: f64, sigma_v_m: f64) -> GnssMeas {
        GnssMeas {
            t_ns: 0,
            pos_ned_m: Vector3::zeros(),
            vel_ned_mps: None,
            vel_h_mps: None,
            sigma_h_m,
            sigma_v_m,
            sigma_vel_mps: 0.1,
        }
    }

    fn state() -> (Nominal, Cov) {
        let x = Nominal {
            t_ns: 0,
            p: Vector3::zeros(),
            v: Vector3::zeros(),
            q: nalgebra::UnitQuaternion::identity(),
            bg: Vector3::zeros(),
            ba: Vector3::zeros(),
            gm: Vector3::new(1.0, -2.0, 3.0),
            clone: None,
        };
        let mut p = Cov::identity() * 0.5;
        p[(IP, IGM)] = -0.3;
        p[(IGM, IP)] = -0.3;
        (x, p)
    }

    #[test]
    fn the_error_state_shrinks_with_the_reported_accuracy() {
        let (mut x, mut p) = state();
        let mut s = GnssPosSource::default();
        s.follow_accuracy(&mut x, &mut p, &meas(4.0, 6.0), 0.5, 300.0);
        assert_eq!(
            x.gm,
            Vector3::new(1.0, -2.0, 3.0),
            "the first fix only sets the size"
        );
        let q = s.follow_accuracy(&mut x, &mut p, &meas(2.0, 6.0), 0.5, 300.0);
        assert!(
            (x.gm - Vector3::new(0.5, -1.0, 3.0)).norm() < 1e-12,
            "{}",
            x.gm
        );
        assert!((p[(IGM, IGM)] - 0.125).abs() < 1e-12);
        assert!((p[(IP, IGM)] + 0.15).abs() < 1e-12);
        assert!((p[(IGM + 2, IGM + 2)] - 0.5).abs() < 1e-12);
        // PSD 2 s² / τ with s² = 0.5 σ².
        assert!((q[0] - 2.0 * 2.0 / 300.0).abs() < 1e-12, "{q:?}");
    }

    #[test]
    fn a_jittering_accuracy_pumps_nothing() {
        let (mut x, mut p) = state();
        let (x0, p0) = (x, p);
        let mut s = GnssPosSource::default();
        s.follow_accuracy(&mut x, &mut p, &meas(2.0, 3.0), 0.5, 300.0);
        for k in 0..1000 {
            let j = if k % 2 == 0 { 2.05 } else { 1.97 };
            s.follow_accuracy(&mut x, &mut p, &meas(j, 3.0 * j / 2.0), 0.5, 300.0);
        }
        s.follow_accuracy(&mut x, &mut p, &meas(2.0, 3.0), 0.5, 300.0);
        assert!((x.gm - x0.gm).norm() < 1e-9, "{}", x.gm);
        assert!((p - p0).norm() < 1e-9);
    }
}
