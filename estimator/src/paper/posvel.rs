//! The paper's position/velocity EKFs. GPS-IMU: `r̈ = C f + g` (eq. 29, plus the Earth-rate
//! Coriolis term of our rotating frame), `ṙ = v` (eq. 30), with GNSS position and velocity through
//! the lever arm (eqs. 32–33; the attitude comes from VIDEO-IMU(1) and is not a state here).
//! VIDEO-IMU(2) is the same filter started from GPS-IMU at an outage and corrected by the video
//! velocity of eq. (35).

use nalgebra::{Matrix3, SMatrix, Vector3};

use crate::aid_sources::gnss_pos::GnssMeas;
use crate::aid_sources::{InnovDiag, chi2_gate};

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

    /// Gated 3-D update of the block at `off` (0 = position, 3 = velocity) with measurement `z`
    /// of that block and noise `r`. Returns whether it was fused.
    #[allow(clippy::too_many_arguments)]
    fn update_block(
        &mut self,
        off: usize,
        z: &Vector3<f64>,
        r: &Matrix3<f64>,
        gate: f64,
        t_ns: i64,
        force: bool,
        diag: &mut InnovDiag,
    ) -> bool {
        let pred = if off == 0 { self.x } else { self.v };
        let y = z - pred;
        let s = self.p.fixed_view::<3, 3>(off, off).into_owned() + r;
        let Some(s_inv) = s.try_inverse() else {
            return false;
        };
        let nis = (y.transpose() * s_inv * y)[(0, 0)];
        diag.innov = [y.x, y.y, y.z];
        diag.innov_var = [s[(0, 0)], s[(1, 1)], s[(2, 2)]];
        diag.test_ratio = nis / chi2_gate(3, gate);
        if !force && diag.test_ratio > 1.0 {
            if diag.consecutive_rejects == 0 {
                diag.first_reject_t_ns = t_ns;
            }
            diag.rejected += 1;
            diag.consecutive_rejects += 1;
            return false;
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
        true
    }

    /// GNSS position (eq. 32) and velocity (eq. 33) through the lever arm with the given attitude.
    #[allow(clippy::too_many_arguments)]
    pub fn update_gnss(
        &mut self,
        m: &GnssMeas,
        c: &Matrix3<f64>,
        lever_b: &Vector3<f64>,
        w_nb: &Vector3<f64>,
        gate: f64,
        reset_timeout_ns: i64,
        diag_pos: &mut InnovDiag,
        diag_vel: &mut InnovDiag,
    ) {
        let rp = Matrix3::from_diagonal(&Vector3::new(
            m.sigma_h_m.powi(2),
            m.sigma_h_m.powi(2),
            m.sigma_v_m.powi(2),
        ));
        let z = m.pos_ned_m - c * lever_b;
        let stuck = diag_pos.consecutive_rejects > 0
            && m.t_ns - diag_pos.first_reject_t_ns >= reset_timeout_ns;
        if stuck {
            let y = z - self.x;
            for k in 0..3 {
                self.p[(k, k)] += y[k] * y[k];
            }
        }
        self.update_block(0, &z, &rp, gate, m.t_ns, stuck, diag_pos);
        let zv = m.vel_ned_mps - c * w_nb.cross(lever_b);
        let rv = Matrix3::identity() * m.sigma_vel_mps.powi(2);
        let stuck = diag_vel.consecutive_rejects > 0
            && m.t_ns - diag_vel.first_reject_t_ns >= reset_timeout_ns;
        if stuck {
            let y = zv - self.v;
            for k in 0..3 {
                self.p[(3 + k, 3 + k)] += y[k] * y[k];
            }
        }
        self.update_block(3, &zv, &rv, gate, m.t_ns, stuck, diag_vel);
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
        self.update_block(3, v_meas, &r, gate, t_ns, false, diag);
    }
}
