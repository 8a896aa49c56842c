//! VIDEO-IMU(1): Euler-angle attitude propagated with the gyro rates (paper eq. 31,
//! `[φ̇ θ̇ ψ̇]ᵀ = J(φ,θ) ω_nb`) and corrected by the video pseudo-attitude (eq. 34): the video
//! delta-attitudes accumulated from an initial known attitude.
//!
//! As in the paper there is no gyro-bias state. The covariance uses `F ≈ I` (the attitude
//! dependence of `J ω` is neglected over a sample) and grows with the gyro noise. The video is late;
//! its innovation is formed against the attitude history at the frame time and applied now.

use std::collections::VecDeque;

use nalgebra::{Isometry3, Matrix3, Rotation3, UnitQuaternion, Vector3};
use uavnav_core::Egomotion;
use uavnav_core::rotation::wrap_pi;

use crate::aid_sources::{InnovDiag, chi2_gate};
use crate::output::euler_rate_matrix;

/// History kept for late video, ns.
const HISTORY_NS: i64 = 2_000_000_000;

/// The attitude filter.
#[derive(Debug, Clone, PartialEq)]
pub struct AttitudeEkf {
    /// Roll, pitch, yaw, rad.
    pub euler: Vector3<f64>,
    /// Covariance of the Euler angles, rad².
    pub p: Matrix3<f64>,
    /// Time of validity, ns.
    pub t_ns: i64,
    hist: VecDeque<(i64, Vector3<f64>)>,
    /// The video pseudo-attitude (eq. 34) and the frame time it refers to.
    pseudo: Option<(i64, UnitQuaternion<f64>)>,
    /// Accumulated variance of the pseudo-attitude per axis, rad².
    pseudo_var: f64,
}

fn wrap3(v: Vector3<f64>) -> Vector3<f64> {
    v.map(wrap_pi)
}

impl AttitudeEkf {
    /// Starts at `euler` with 1-σ `sigma`.
    pub fn new(euler: Vector3<f64>, sigma: Vector3<f64>, t_ns: i64) -> Self {
        Self {
            euler,
            p: Matrix3::from_diagonal(&sigma.component_mul(&sigma)),
            t_ns,
            hist: VecDeque::new(),
            pseudo: None,
            pseudo_var: 0.0,
        }
    }

    /// `nav_from_body` from the Euler angles.
    pub fn quaternion(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_euler_angles(self.euler.x, self.euler.y, self.euler.z)
    }

    /// `C_b^n` as a matrix.
    pub fn rotation(&self) -> Matrix3<f64> {
        Rotation3::from_euler_angles(self.euler.x, self.euler.y, self.euler.z).into_inner()
    }

    /// Eq. (31) over `dt_s` with the mean raw gyro (Earth rate removed).
    pub fn predict(
        &mut self,
        gyro: &Vector3<f64>,
        w_ie: &Vector3<f64>,
        dt_s: f64,
        gyro_psd: f64,
        t_ns: i64,
    ) {
        let w_nb = gyro - self.rotation().transpose() * w_ie;
        let j = euler_rate_matrix(self.euler.x, self.euler.y);
        self.euler += j * w_nb * dt_s;
        self.euler.z = wrap_pi(self.euler.z);
        self.euler.x = wrap_pi(self.euler.x);
        self.p += j * j.transpose() * (gyro_psd * dt_s);
        self.t_ns = t_ns;
        self.hist.push_back((t_ns, self.euler));
        while self.hist.front().is_some_and(|h| t_ns - h.0 > HISTORY_NS) {
            self.hist.pop_front();
        }
    }

    /// Euler angles at `t_ns` from the history (nearest sample at or before).
    pub fn euler_at(&self, t_ns: i64) -> Option<Vector3<f64>> {
        let idx = self.hist.partition_point(|h| h.0 <= t_ns);
        if idx == 0 {
            None
        } else {
            Some(self.hist[idx - 1].1)
        }
    }

    /// `C_b^n` at `t_ns`.
    pub fn rotation_at(&self, t_ns: i64) -> Option<Matrix3<f64>> {
        self.euler_at(t_ns)
            .map(|e| Rotation3::from_euler_angles(e.x, e.y, e.z).into_inner())
    }

    /// Fuses an Euler-angle measurement `z` (1-σ `sigma`) whose innovation is taken against
    /// the attitude at `t_ns` and applied now.
    pub fn update_euler(
        &mut self,
        z: &Vector3<f64>,
        sigma: &Vector3<f64>,
        gate: f64,
        t_ns: i64,
        diag: &mut InnovDiag,
    ) {
        let Some(pred) = self.euler_at(t_ns).or(Some(self.euler)) else {
            return;
        };
        let y = wrap3(z - pred);
        let s = self.p + Matrix3::from_diagonal(&sigma.component_mul(sigma));
        let Some(s_inv) = s.try_inverse() else { return };
        let nis = (y.transpose() * s_inv * y)[(0, 0)];
        diag.innov = [y.x, y.y, y.z];
        diag.innov_var = [s[(0, 0)], s[(1, 1)], s[(2, 2)]];
        diag.test_ratio = nis / chi2_gate(3, gate);
        if diag.test_ratio > 1.0 {
            diag.rejected += 1;
            diag.consecutive_rejects += 1;
            return;
        }
        let k = self.p * s_inv;
        self.euler = wrap3(self.euler + k * y);
        self.p = (Matrix3::identity() - k) * self.p;
        self.p = (self.p + self.p.transpose()) * 0.5;
        diag.fused += 1;
        diag.consecutive_rejects = 0;
        diag.last_fused_t_ns = t_ns;
    }

    /// Eq. (34): accumulates the video delta-attitude into the pseudo-attitude (restarting from the
    /// filter's attitude at frame 0 when the chain of frames breaks) and fuses it.
    pub fn video_update(
        &mut self,
        m: &Egomotion,
        body_from_cam: &Isometry3<f64>,
        gate: f64,
        start_sigma_rad: f64,
        cov_scale: f64,
        diag: &mut InnovDiag,
    ) {
        let r_bc = body_from_cam.rotation;
        let b1_from_b0 = r_bc * m.cam1_from_cam0 * r_bc.inverse();
        // `cov_scale`: the allowance for the egomotion errors' time correlation (see
        // `EstimatorParams::vision_cov_scale`); the pseudo-attitude accumulates them.
        let rot_var = m.rot_cov.trace() / 3.0 * cov_scale;
        let base = match self.pseudo {
            Some((t, q)) if t == m.t0_ns => Some(q),
            _ => {
                if self.p.diagonal().max() > start_sigma_rad.powi(2) {
                    return;
                }
                let e0 = self.euler_at(m.t0_ns);
                self.pseudo_var = self.p.trace() / 3.0;
                e0.map(|e| UnitQuaternion::from_euler_angles(e.x, e.y, e.z))
            }
        };
        let Some(q0) = base else { return };
        let q1 = q0 * b1_from_b0.inverse();
        self.pseudo = Some((m.t1_ns, q1));
        self.pseudo_var += rot_var;
        let (r, p, y) = q1.euler_angles();
        let sigma = Vector3::repeat(self.pseudo_var.sqrt());
        self.update_euler(&Vector3::new(r, p, y), &sigma, gate, m.t1_ns, diag);
    }
}
