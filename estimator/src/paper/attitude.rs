//! VIDEO-IMU(1): Euler-angle attitude propagated with the gyro rates (paper eq. 31,
//! `[φ̇ θ̇ ψ̇]ᵀ = J(φ,θ) ω_nb`) and corrected by the video pseudo-attitude (eq. 34): the video
//! delta-attitudes accumulated from an initial known attitude.
//!
//! As in the paper there is no gyro-bias state. The covariance uses `F ≈ I` (the attitude
//! dependence of `J ω` is neglected over a sample) and grows with the gyro noise. The video is late;
//! its innovation is formed against the attitude history at the frame time and applied now.
//!
//! The pseudo-attitude of eq. (34) is a running sum: its error is the error of its starting value
//! plus every video delta's error so far, i.e. a random walk shared by all the pseudo-attitudes of
//! one chain, not white noise. Fusing each one as an independent measurement (the first reading)
//! re-uses the same error at every frame and makes the filter overconfident. Here that error is a
//! state `c` (the textbook augmentation for time-correlated measurement noise), so the state is
//! `[δφ δθ δψ | c]` (6), the pseudo-attitude is `z = e + c` exactly, `c` starts as minus the
//! filter's own error at the chain's start (the "initial known value" is the filter's estimate)
//! and grows by each video delta's covariance.

use std::collections::VecDeque;

use nalgebra::{Isometry3, Matrix3, Rotation3, SMatrix, UnitQuaternion, Vector3};
use uavnav_core::Egomotion;
use uavnav_core::rotation::wrap_pi;

use crate::aid_sources::{InnovDiag, chi2_gate};
use crate::output::euler_rate_matrix;

/// History kept for late video, ns.
const HISTORY_NS: i64 = 2_000_000_000;
/// Variance added to the (otherwise exact) pseudo-attitude measurement for numerical stability,
/// rad².
const PSEUDO_FLOOR_VAR: f64 = 1e-12;

/// 6×6 covariance of `[δe; c]`.
pub type AttCov = SMatrix<f64, 6, 6>;

/// The attitude filter.
#[derive(Debug, Clone, PartialEq)]
pub struct AttitudeEkf {
    /// Roll, pitch, yaw, rad.
    pub euler: Vector3<f64>,
    /// Covariance of `[δe; c]`: Euler-angle error (rad²) and the pseudo-attitude chain error.
    pub p: AttCov,
    /// Time of validity, ns.
    pub t_ns: i64,
    hist: VecDeque<(i64, Vector3<f64>)>,
    /// The video pseudo-attitude (eq. 34) and the frame time it refers to.
    pseudo: Option<(i64, UnitQuaternion<f64>)>,
    /// Estimate of the pseudo-attitude chain's error `c` (Euler angles, rad).
    chain: Vector3<f64>,
}

fn wrap3(v: Vector3<f64>) -> Vector3<f64> {
    v.map(wrap_pi)
}

impl AttitudeEkf {
    /// Starts at `euler` with 1-σ `sigma`.
    pub fn new(euler: Vector3<f64>, sigma: Vector3<f64>, t_ns: i64) -> Self {
        let mut p = AttCov::zeros();
        p.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::from_diagonal(&sigma.component_mul(&sigma)));
        Self {
            euler,
            p,
            t_ns,
            hist: VecDeque::new(),
            pseudo: None,
            chain: Vector3::zeros(),
        }
    }

    /// Covariance of the Euler angles, rad².
    pub fn p_euler(&self) -> Matrix3<f64> {
        self.p.fixed_view::<3, 3>(0, 0).into_owned()
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
        let q = j * j.transpose() * (gyro_psd * dt_s);
        let mut pee = self.p.fixed_view_mut::<3, 3>(0, 0);
        pee += q;
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

    /// Gated EKF update of a 3-D measurement with innovation `y`, Jacobian `h` w.r.t. `[δe; c]`
    /// and noise `r`. Returns whether it was fused.
    fn update(
        &mut self,
        y: &Vector3<f64>,
        h: &SMatrix<f64, 3, 6>,
        r: &Matrix3<f64>,
        gate: f64,
        t_ns: i64,
        diag: &mut InnovDiag,
    ) -> bool {
        let pht = self.p * h.transpose();
        let s = h * pht + r;
        let Some(s_inv) = s.try_inverse() else {
            return false;
        };
        let nis = (y.transpose() * s_inv * y)[(0, 0)];
        diag.innov = [y.x, y.y, y.z];
        diag.innov_var = [s[(0, 0)], s[(1, 1)], s[(2, 2)]];
        diag.test_ratio = nis / chi2_gate(3, gate);
        if diag.test_ratio > 1.0 {
            diag.rejected += 1;
            diag.consecutive_rejects += 1;
            return false;
        }
        let k = pht * s_inv;
        let dx = k * y;
        self.euler = wrap3(self.euler + dx.fixed_rows::<3>(0));
        self.chain += dx.fixed_rows::<3>(3);
        self.p -= k * pht.transpose();
        self.p = (self.p + self.p.transpose()) * 0.5;
        diag.fused += 1;
        diag.consecutive_rejects = 0;
        diag.last_fused_t_ns = t_ns;
        true
    }

    /// Fuses an Euler-angle measurement `z` (1-σ `sigma`, independent of the filter) whose
    /// innovation is taken against the attitude at `t_ns` and applied now.
    pub fn update_euler(
        &mut self,
        z: &Vector3<f64>,
        sigma: &Vector3<f64>,
        gate: f64,
        t_ns: i64,
        diag: &mut InnovDiag,
    ) {
        let pred = self.euler_at(t_ns).unwrap_or(self.euler);
        let y = wrap3(z - pred);
        let mut h = SMatrix::<f64, 3, 6>::zeros();
        h.fixed_view_mut::<3, 3>(0, 0).fill_with_identity();
        let r = Matrix3::from_diagonal(&sigma.component_mul(sigma));
        self.update(&y, &h, &r, gate, t_ns, diag);
    }

    /// Joint part of a GNSS update (eqs. 32–33 through the lever arm, see `posvel`): the attitude
    /// correction `K_e y` with `K_e = P[:, e] H_eᵀ S⁻¹` for an innovation `y` whose covariance `s_inv`
    /// (inverse) the caller formed. Cross-covariances with the position/velocity filter are not
    /// kept (the paper's filters are separate).
    pub fn apply_joint(&mut self, h_e: &Matrix3<f64>, s_inv: &Matrix3<f64>, y: &Vector3<f64>) {
        let pht: SMatrix<f64, 6, 3> = self.p.fixed_columns::<3>(0) * h_e.transpose();
        let k = pht * s_inv;
        let dx = k * y;
        self.euler = wrap3(self.euler + dx.fixed_rows::<3>(0));
        self.chain += dx.fixed_rows::<3>(3);
        self.p -= k * pht.transpose();
        self.p = (self.p + self.p.transpose()) * 0.5;
    }

    /// Whether a pseudo-attitude chain is running.
    pub fn video_active(&self) -> bool {
        self.pseudo.is_some()
    }

    /// Eq. (34): accumulates the video delta-attitude into the pseudo-attitude (restarting from the
    /// filter's attitude at frame 0 when the chain of frames breaks) and fuses it as `z = e + c`.
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
        let base = match self.pseudo {
            Some((t, q)) if t == m.t0_ns => Some(q),
            _ => {
                // A new chain starts from the filter's attitude at frame 0 (the "initial known
                // value"), once the filter is aligned: c = ê − e = −δe, so cov(c) = P_ee and
                // cov(δe, c) = −P_ee (the process noise since frame 0 is neglected).
                self.pseudo = None;
                let pee = self.p_euler();
                if pee.diagonal().max() > start_sigma_rad.powi(2) {
                    return;
                }
                let Some(e0) = self.euler_at(m.t0_ns) else {
                    return;
                };
                self.chain = Vector3::zeros();
                self.p.fixed_view_mut::<3, 3>(3, 3).copy_from(&pee);
                self.p.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-pee));
                self.p.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-pee));
                Some(UnitQuaternion::from_euler_angles(e0.x, e0.y, e0.z))
            }
        };
        let Some(q0) = base else { return };
        // nav_from_b1 = nav_from_b0 · b0_from_b1. A small error δθ of the video rotation (camera
        // axes) perturbs q1 by R_bc δθ in body-1 axes, i.e. the Euler angles by J(φ,θ) R_bc δθ.
        let q1 = q0 * b1_from_b0.inverse();
        let (r, p, y) = q1.euler_angles();
        let z = Vector3::new(r, p, y);
        let rbc = r_bc.to_rotation_matrix().into_inner();
        let j = euler_rate_matrix(r, p);
        // `cov_scale`: the allowance for the egomotion errors' time correlation (see
        // `EstimatorParams::vision_cov_scale`): the chain sums them, so its variance grows by the
        // long-run (not the per-frame) variance of each delta.
        let q_c = j * rbc * m.rot_cov * rbc.transpose() * j.transpose() * cov_scale;
        let mut pcc = self.p.fixed_view_mut::<3, 3>(3, 3);
        pcc += q_c;
        self.pseudo = Some((m.t1_ns, q1));
        let pred = self.euler_at(m.t1_ns).unwrap_or(self.euler);
        let y = wrap3(z - pred - self.chain);
        let mut h = SMatrix::<f64, 3, 6>::zeros();
        h.fixed_view_mut::<3, 3>(0, 0).fill_with_identity();
        h.fixed_view_mut::<3, 3>(0, 3).fill_with_identity();
        let r = Matrix3::identity() * PSEUDO_FLOOR_VAR;
        if !self.update(&y, &h, &r, gate, m.t1_ns, diag) {
            // The chain now carries an error its covariance does not describe: start a new one.
            self.pseudo = None;
        }
    }
}

/// `∂(C(φ,θ,ψ) u)/∂(φ,θ,ψ)` for a body vector `u`, with `C = R_z(ψ) R_y(θ) R_x(φ)`:
/// `∂/∂φ = C (x̂ × u)`, `∂/∂θ = R_z R_y (ŷ × R_x u)`, `∂/∂ψ = ẑ × (C u)`.
/// The lever-arm terms of eqs. (32) (`u = r`) and (33) (`u = ω × r`) linearized in the attitude.
pub fn lever_jacobian(euler: &Vector3<f64>, u: &Vector3<f64>) -> Matrix3<f64> {
    let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), euler.x);
    let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), euler.y);
    let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), euler.z);
    let c = rz * ry * rx;
    let d_roll = c * Vector3::x().cross(u);
    let d_pitch = rz * ry * Vector3::y().cross(&(rx * u));
    let d_yaw = Vector3::z().cross(&(c * u));
    Matrix3::from_columns(&[d_roll, d_pitch, d_yaw])
}
