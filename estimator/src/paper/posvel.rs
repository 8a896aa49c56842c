//! The paper's position/velocity EKFs. GPS-IMU: `r̈ = C f + g` (eq. 29, plus the Earth-rate
//! Coriolis term of our rotating frame), `ṙ = v` (eq. 30), with GNSS position and velocity through
//! the lever arm (eqs. 32–33). The attitude is not a state here but VIDEO-IMU(1)'s: the lever-arm
//! terms `C r` and `C (ω × r)` depend on it, so a GNSS update is one EKF update of both filters'
//! states (`H = [I | ∂(C u)/∂e]`) with the cross-covariance between them not kept. This is where
//! the GNSS makes the attitude observable, through the lever arm only (section VI: "observability
//! is guaranteed by the lever arm"). VIDEO-IMU(2) is the same filter started from GPS-IMU at an
//! outage and corrected by the video velocity of eq. (35).

use nalgebra::{Matrix3, SMatrix, Vector3};

use super::attitude::{AttitudeEkf, lever_jacobian};
use crate::aid_sources::gnss_pos::GnssMeas;
use crate::aid_sources::{InnovDiag, chi2_gate};

/// Variance of a velocity component the receiver does not give, (m/s)² (σ 1 km/s): fused with a
/// zero innovation, it changes nothing.
const UNMEASURED_VAR: f64 = 1e6;

/// Position/velocity EKF (6 states).
#[derive(Debug, Clone, PartialEq)]
pub struct PosVelEkf {
    /// Position NED, m.
    pub x: Vector3<f64>,
    /// Velocity NED, m/s.
    pub v: Vector3<f64>,
    /// Covariance of [p; v].
    pub p: SMatrix<f64, 6, 6>,
}

impl PosVelEkf {
    /// Starts at (`x`, `v`) with σ.
    pub fn new(x: Vector3<f64>, v: Vector3<f64>, sig_pos: Vector3<f64>, sig_vel: f64) -> Self {
        let mut p = SMatrix::<f64, 6, 6>::zeros();
        for k in 0..3 {
            p[(k, k)] = sig_pos[k].powi(2);
            p[(3 + k, 3 + k)] = sig_vel.powi(2).max(1e-4);
        }
        Self { x, v, p }
    }

    /// Eqs. (29)–(30) over `dt_s`; `q_acc` is the acceleration noise PSD (accelerometer noise plus
    /// the attitude uncertainty seen through the specific force).
    pub fn predict(
        &mut self,
        c: &Matrix3<f64>,
        f_b: &Vector3<f64>,
        g: &Vector3<f64>,
        w_ie: &Vector3<f64>,
        dt_s: f64,
        q_acc: f64,
    ) {
        let a = c * f_b + g - 2.0 * w_ie.cross(&self.v);
        self.x += self.v * dt_s + a * (0.5 * dt_s * dt_s);
        self.v += a * dt_s;
        let mut f = SMatrix::<f64, 6, 6>::identity();
        f.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(Matrix3::identity() * dt_s));
        self.p = f * self.p * f.transpose();
        for k in 0..3 {
            self.p[(3 + k, 3 + k)] += q_acc * dt_s;
        }
    }

    /// Gated 3-D update of the block at `off` (0 = position, 3 = velocity) with innovation `y`
    /// and noise `r` (measurement noise plus any other filter's uncertainty seen through the
    /// measurement). Returns `S⁻¹` when fused.
    #[allow(clippy::too_many_arguments)]
    fn update_block(
        &mut self,
        off: usize,
        y: &Vector3<f64>,
        r: &Matrix3<f64>,
        gate: f64,
        t_ns: i64,
        force: bool,
        dof: usize,
        diag: &mut InnovDiag,
    ) -> Option<Matrix3<f64>> {
        let y = *y;
        let s = self.p.fixed_view::<3, 3>(off, off).into_owned() + r;
        let s_inv = s.try_inverse()?;
        let nis = (y.transpose() * s_inv * y)[(0, 0)];
        diag.innov = [y.x, y.y, y.z];
        diag.innov_var = [s[(0, 0)], s[(1, 1)], s[(2, 2)]];
        diag.test_ratio = nis / chi2_gate(dof, gate);
        if !force && diag.test_ratio > 1.0 {
            if diag.consecutive_rejects == 0 {
                diag.first_reject_t_ns = t_ns;
            }
            diag.rejected += 1;
            diag.consecutive_rejects += 1;
            return None;
        }
        let pht: SMatrix<f64, 6, 3> = self.p.fixed_columns::<3>(off).into_owned();
        let k = pht * s_inv;
        let dx = k * y;
        self.x += dx.fixed_rows::<3>(0);
        self.v += dx.fixed_rows::<3>(3);
        self.p -= k * pht.transpose();
        self.p = (self.p + self.p.transpose()) * 0.5;
        diag.fused += 1;
        diag.consecutive_rejects = 0;
        diag.last_fused_t_ns = t_ns;
        Some(s_inv)
    }

    /// GNSS position (eq. 32) and velocity (eq. 33) through the lever arm: updates this filter
    /// and the attitude of `att` (see the module doc). `w_nb` is the body rate.
    #[allow(clippy::too_many_arguments)]
    pub fn update_gnss(
        &mut self,
        m: &GnssMeas,
        att: &mut AttitudeEkf,
        lever_b: &Vector3<f64>,
        w_nb: &Vector3<f64>,
        gate: f64,
        reset_timeout_ns: i64,
        diag_pos: &mut InnovDiag,
        diag_vel: &mut InnovDiag,
    ) {
        // Eq. (32): p_GPS = p_cg + C r. Its attitude part ∂(C r)/∂e is NOT fused: the GNSS position
        // error is time-correlated (Gauss–Markov, metres over minutes) while this filter takes it
        // as white, so the residuals follow that slow error, and read through a lever arm of
        // metres they become attitude errors of tenths of a degree (measured: roll/pitch/yaw RMSE
        // 2–3× worse with a 10 m lever arm). The position is corrected with the current `C r`.
        let rp = Matrix3::from_diagonal(&Vector3::new(
            m.sigma_h_m.powi(2),
            m.sigma_h_m.powi(2),
            m.sigma_v_m.powi(2),
        ));
        let y = m.pos_ned_m - (self.x + att.rotation() * lever_b);
        let stuck = diag_pos.consecutive_rejects > 0
            && m.t_ns - diag_pos.first_reject_t_ns >= reset_timeout_ns;
        if stuck {
            for k in 0..3 {
                self.p[(k, k)] += y[k] * y[k];
            }
        }
        self.update_block(0, &y, &rp, gate, m.t_ns, stuck, 3, diag_pos);
        // Eq. (33): v_GPS = v_cg + C (ω × r), fused into both filters. The GNSS velocity error is
        // white, and in turns `ω × r` is metres per second for a 10 m lever arm (a tenth of that
        // for 2 m), which is what makes the attitude observable (section VI).
        let c = att.rotation();
        let u = w_nb.cross(lever_b);
        let h_e = lever_jacobian(&att.euler, &u);
        // A receiver that gives ground speed and course only (MAVLink's `GPS_RAW_INT`, NMEA's
        // RMC) measures the horizontal velocity: its vertical row is taken as unmeasured (a zero
        // innovation of variance `UNMEASURED_VAR`, which leaves the filter as it was) and the
        // gate counts two degrees of freedom.
        let (v_meas, vertical) = match (m.vel_ned_mps, m.vel_h_mps) {
            (Some(v), _) => (v, true),
            (None, Some(h)) => (Vector3::new(h.x, h.y, self.v.z + (c * u).z), false),
            (None, None) => return,
        };
        let y = v_meas - (self.v + c * u);
        let mut rv = Matrix3::identity() * m.sigma_vel_mps.powi(2);
        if !vertical {
            rv[(2, 2)] = UNMEASURED_VAR;
        }
        let stuck = diag_vel.consecutive_rejects > 0
            && m.t_ns - diag_vel.first_reject_t_ns >= reset_timeout_ns;
        if stuck {
            for k in 0..3 {
                self.p[(3 + k, 3 + k)] += y[k] * y[k];
            }
        }
        let r = rv + h_e * att.p_euler() * h_e.transpose();
        let dof = if vertical { 3 } else { 2 };
        if let Some(s_inv) = self.update_block(3, &y, &r, gate, m.t_ns, stuck, dof, diag_vel) {
            att.apply_joint(&h_e, &s_inv, &y, m.t_ns);
        }
    }

    /// Keeps the velocity variance along the unit vector `u` at least `var`, by adding the
    /// difference along `u` only (a rank-1 positive term: the covariance stays positive
    /// definite).
    pub fn floor_velocity_along(&mut self, u: &Vector3<f64>, var: f64) {
        let pv = self.p.fixed_view::<3, 3>(3, 3).into_owned();
        let have = (u.transpose() * pv * u)[(0, 0)];
        if have < var {
            let add = u * u.transpose() * (var - have);
            let mut block = self.p.fixed_view_mut::<3, 3>(3, 3);
            block += add;
        }
    }

    /// Keeps the variance of each position axis `k` at least `var[k]` (diagonal terms raised:
    /// the covariance stays positive definite).
    pub fn floor_position(&mut self, var: &Vector3<f64>) {
        for k in 0..3 {
            if self.p[(k, k)] < var[k] {
                self.p[(k, k)] = var[k];
            }
        }
    }

    /// Eq. (35): a velocity measurement from the video direction times the last valid speed.
    pub fn update_velocity(
        &mut self,
        v_meas: &Vector3<f64>,
        sigma_mps: f64,
        t_ns: i64,
        gate: f64,
        diag: &mut InnovDiag,
    ) {
        let r = Matrix3::identity() * sigma_mps.powi(2);
        let y = v_meas - self.v;
        self.update_block(3, &y, &r, gate, t_ns, false, 3, diag);
    }
}
