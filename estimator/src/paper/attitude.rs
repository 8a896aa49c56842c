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
//! one chain, not white noise. Fusing each one as an independent measurement re-uses the same error
//! at every frame and makes the filter overconfident, so that error is a state `η` (the textbook
//! augmentation for time-correlated measurement noise): the state is `[δφ δθ δψ | η]` (6).
//!
//! In which frame is the chain's error constant? The chain is `Ĉ_k = Ĉ_0 D̂_1 ⋯ D̂_k` with
//! `D̂_i = D_i Exp(ε_i)` (`D_i = C_{i−1}ᵀ C_i` the true body delta, `ε_i` its error in body-i axes)
//! and `Ĉ_0 = Exp(η_0) C_0`. Since `C_i Exp(ε_i) = Exp(C_i ε_i) C_i`, every error moves to the left:
//! `Ĉ_k = Exp(η_0) Exp(C_1 ε_1) ⋯ Exp(C_k ε_k) C_k ≈ Exp(η_k) C_k` with
//! `η_k = η_0 + Σ_i C_i ε_i` (eq. C1). So the error is a rotation vector fixed in the NAVIGATION
//! frame: it changes only by the new deltas' errors, not when the vehicle turns. Its Euler-angle
//! image is `δe = J(φ,θ) Cᵀ η` (eq. C2, the right perturbation `C Exp(β)` moves the Euler angles by
//! `J β` as a body rate does in eq. 31, and `β = Cᵀ η`): a heading change rotates a constant `η`
//! from roll into pitch. Keeping the error as constant Euler angles (the previous reading) ascribed
//! a tilt error made while flying north to roll even after a 90° turn, where it is pitch.
//!
//! For the same reason the filter's own Euler-angle error is propagated with the linearized eq. (31)
//! (`F = I + ∂(J ω)/∂e · dt`, eq. F1), not `F = I`: with error-free gyros `δe` obeys exactly that
//! equation, and it is what turns a roll error into a pitch error through a turn.

use std::collections::VecDeque;

use nalgebra::{Isometry3, Matrix3, Rotation3, SMatrix, SVector, UnitQuaternion, Vector2, Vector3};
use uavnav_core::Egomotion;
use uavnav_core::rotation::wrap_pi;

use crate::aid_sources::{InnovDiag, chi2_gate};
use crate::output::euler_rate_matrix;

/// History kept for late video, ns.
const HISTORY_NS: i64 = 2_000_000_000;
/// Variance added to the (otherwise exact) pseudo-attitude measurement for numerical stability,
/// rad².
const PSEUDO_FLOOR_VAR: f64 = 1e-12;

/// Largest 1-σ the gyro bias's share of an angle's error grows to, rad: that of an angle uniform
/// round the circle (π/√3), as for a heading not yet known.
const MAX_BIAS_SD_RAD: f64 = crate::init::UNALIGNED_YAW_SIGMA_RAD;

/// 6×6 covariance of `[δe; η]`.
pub type AttCov = SMatrix<f64, 6, 6>;

/// The attitude filter.
#[derive(Debug, Clone, PartialEq)]
pub struct AttitudeEkf {
    /// Roll, pitch, yaw, rad.
    pub euler: Vector3<f64>,
    /// Covariance of `[δe; η]`: Euler-angle error (rad²) and the pseudo-attitude chain error (NED
    /// rotation vector, rad²).
    pub p: AttCov,
    /// Time of validity, ns.
    pub t_ns: i64,
    hist: VecDeque<(i64, Vector3<f64>)>,
    /// The video pseudo-attitude (eq. 34) and the frame time it refers to.
    pseudo: Option<(i64, UnitQuaternion<f64>)>,
    /// Estimate of the pseudo-attitude chain's error `η` (rotation vector in NED, rad; eq. C1).
    chain: Vector3<f64>,
    /// 1-σ of the Euler-angle error the gyro's un-modelled bias has built up and no measurement
    /// has removed since, rad (see [`Self::predict`]).
    bias_sd: Vector3<f64>,
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
            bias_sd: Vector3::zeros(),
        }
    }

    /// Eq. (S2) after an update that took the Euler-angle variances from `before`.
    fn shrink_bias_sd(&mut self, before: &Vector3<f64>) {
        for i in 0..3 {
            let after = self.p[(i, i)];
            if before[i] > 0.0 && after.is_finite() {
                self.bias_sd[i] *= (after.max(0.0) / before[i]).sqrt().min(1.0);
            }
        }
    }

    /// Keeps each Euler angle's variance at most `max_var`, rad², by scaling that angle's row
    /// and column of the covariance (`D P D` with a positive diagonal `D`: it stays positive
    /// semi-definite and the correlations are kept). Near ±90° of pitch, roll and yaw lose their
    /// meaning and the propagation grows their variance without bound (10¹³ rad² on a tumbling
    /// copter without GNSS, where the next update then left negative variances).
    pub fn cap_euler_variance(&mut self, max_var: f64) {
        for i in 0..3 {
            let v = self.p[(i, i)];
            if v > max_var {
                let k = (max_var / v).sqrt();
                for j in 0..6 {
                    self.p[(i, j)] *= k;
                    self.p[(j, i)] *= k;
                }
            }
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

    /// Eq. (31) over `dt_s` with the mean raw gyro (Earth rate removed), covariance with eq. (F1).
    ///
    /// The process noise is the gyro's white noise `gyro_psd` and, our addition, what a gyro bias
    /// of 1-σ `gyro_bias_sigma_radps` per axis (the IMU's turn-on bias; 0 when not known) builds
    /// up. As in the paper there is no bias state, and white noise grows the variance as `t` where
    /// a constant bias grows the error as `t`: sized for a consumer gyro's bias (0.3 °/s) a white
    /// allowance (`paper_gyro_instability_psd`) would be five times too wide ten seconds into an
    /// outage, and too narrow after two minutes. A constant bias `b` adds `J(φ,θ) b dt` to the
    /// Euler-angle error at every step (eq. 31), fully correlated from step to step, so its 1-σ
    /// grows as `σ_b ‖J_i‖ dt` per angle `i` (eq. S1) and its variance by the difference of the
    /// squares, which is added to `P_ii`; a measurement that shrinks an angle's variance from
    /// `P⁻` to `P⁺` removes the same share of it, scaling that 1-σ by `√(P⁺ / P⁻)` (eq. S2).
    /// Simulated fixed wing with a consumer IMU (turn-on bias 0.29 °/s) through a 120 s GNSS
    /// outage, no video: attitude rows within 3σ 33.5 → 97.6 %, and yaw RMSE 106 → 17.5° (the
    /// course, gated out when GNSS returned against an attitude σ far too small, is taken).
    pub fn predict(
        &mut self,
        gyro: &Vector3<f64>,
        w_ie: &Vector3<f64>,
        dt_s: f64,
        gyro_psd: f64,
        gyro_bias_sigma_radps: f64,
        t_ns: i64,
    ) {
        let w_nb = gyro - self.rotation().transpose() * w_ie;
        let j = euler_rate_matrix(self.euler.x, self.euler.y);
        // Eq. (S1); ‖J_i‖ is unbounded only at ±90° pitch, where the Euler angles are anyway. It
        // stops at the σ of an angle uniform round the circle: an error cannot grow past that.
        let mut bias_var_growth = Vector3::zeros();
        for i in 0..3 {
            let sd = self.bias_sd[i];
            let next = (sd + gyro_bias_sigma_radps * j.row(i).norm() * dt_s).min(MAX_BIAS_SD_RAD);
            if next.is_finite() && next > sd {
                bias_var_growth[i] = next * next - sd * sd;
                self.bias_sd[i] = next;
            }
        }
        // Linearized at the attitude at the start of the step, like the mean-value propagation.
        let f = Matrix3::identity() + euler_rate_jacobian(&self.euler, &w_nb) * dt_s;
        self.euler += j * w_nb * dt_s;
        self.euler.z = wrap_pi(self.euler.z);
        self.euler.x = wrap_pi(self.euler.x);
        let q = j * j.transpose() * (gyro_psd * dt_s) + Matrix3::from_diagonal(&bias_var_growth);
        // η is constant between frames (eq. C1): only the δe rows change.
        let pee = f * self.p.fixed_view::<3, 3>(0, 0) * f.transpose() + q;
        let pec = f * self.p.fixed_view::<3, 3>(0, 3);
        self.p.fixed_view_mut::<3, 3>(0, 0).copy_from(&pee);
        self.p.fixed_view_mut::<3, 3>(0, 3).copy_from(&pec);
        self.p
            .fixed_view_mut::<3, 3>(3, 0)
            .copy_from(&pec.transpose());
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

    /// Applies the Euler-angle correction `de` of a measurement taken at `t_ns` to the current
    /// attitude AND to the history from `t_ns` on (from the entry `euler_at(t_ns)` returns). The
    /// measurement is late (the video arrives ~50 ms after its frame): the history after `t_ns` was
    /// propagated from the uncorrected attitude, and the next late measurement (the direction of
    /// eq. D1 at the same frame time, the next frame's chain restart at `t0`, VIDEO-IMU(2)'s
    /// rotation) is compared against it; left stale, its innovation would contain again the error
    /// this correction already removed. `de` is added as is: over the history's 2 s the Euler
    /// angles change little, so the correction's Euler image hardly does.
    fn correct(&mut self, de: &Vector3<f64>, t_ns: i64) {
        self.euler = wrap3(self.euler + de);
        let from = self.hist.partition_point(|h| h.0 <= t_ns).saturating_sub(1);
        for h in self.hist.iter_mut().skip(from) {
            h.1 = wrap3(h.1 + de);
        }
    }

    /// Gated EKF update of a `D`-dimensional measurement (D ≤ 3) with innovation `y`, Jacobian `h`
    /// w.r.t. `[δe; η]` and noise `r`, taken at `t_ns`. Returns whether it was fused.
    fn update<const D: usize>(
        &mut self,
        y: &SVector<f64, D>,
        h: &SMatrix<f64, D, 6>,
        r: &SMatrix<f64, D, D>,
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
        diag.innov = [0.0; 3];
        diag.innov_var = [0.0; 3];
        for k in 0..D.min(3) {
            diag.innov[k] = y[k];
            diag.innov_var[k] = s[(k, k)];
        }
        diag.test_ratio = nis / chi2_gate(D, gate);
        if diag.test_ratio > 1.0 {
            diag.rejected += 1;
            diag.consecutive_rejects += 1;
            return false;
        }
        let k = pht * s_inv;
        let dx = k * y;
        self.correct(&dx.fixed_rows::<3>(0).into_owned(), t_ns);
        self.chain += dx.fixed_rows::<3>(3);
        let before = self.p_euler().diagonal();
        self.p -= k * pht.transpose();
        self.p = (self.p + self.p.transpose()) * 0.5;
        self.shrink_bias_sd(&before);
        diag.fused += 1;
        diag.consecutive_rejects = 0;
        diag.last_fused_t_ns = t_ns;
        true
    }

    /// Fuses the measured angles of an Euler-angle measurement `z` (1-σ `sigma` per angle, `None`
    /// where the angle is not measured; independent of the filter) whose innovation is taken
    /// against the attitude at `t_ns` and applied now. Only the measured angles enter the
    /// update and its gate (a σ standing in for "not measured" would loosen the gate by its
    /// degrees of freedom).
    pub fn update_euler(
        &mut self,
        z: &Vector3<f64>,
        sigma: [Option<f64>; 3],
        gate: f64,
        t_ns: i64,
        diag: &mut InnovDiag,
    ) {
        let pred = self.euler_at(t_ns).unwrap_or(self.euler);
        let y = wrap3(z - pred);
        let axes: Vec<(usize, f64)> = (0..3).filter_map(|k| sigma[k].map(|s| (k, s))).collect();
        match axes.as_slice() {
            [a] => self.update_axes::<1>(&y, &[*a], gate, t_ns, diag),
            [a, b] => self.update_axes::<2>(&y, &[*a, *b], gate, t_ns, diag),
            [a, b, c] => self.update_axes::<3>(&y, &[*a, *b, *c], gate, t_ns, diag),
            _ => {}
        }
    }

    /// [`Self::update_euler`] on `D` chosen `(angle, σ)`.
    fn update_axes<const D: usize>(
        &mut self,
        y: &Vector3<f64>,
        axes: &[(usize, f64); D],
        gate: f64,
        t_ns: i64,
        diag: &mut InnovDiag,
    ) {
        let mut yd = SVector::<f64, D>::zeros();
        let mut h = SMatrix::<f64, D, 6>::zeros();
        let mut r = SMatrix::<f64, D, D>::zeros();
        for (i, &(k, s)) in axes.iter().enumerate() {
            yd[i] = y[k];
            h[(i, k)] = 1.0;
            r[(i, i)] = s * s;
        }
        self.update(&yd, &h, &r, gate, t_ns, diag);
    }

    /// Gated update of the GNSS-acceleration tilt measurement (eq. T1 of `gnss_tilt`): residual
    /// `y`, Jacobian `h_e` w.r.t. the Euler angles, noise `r`, taken now.
    pub fn update_tilt(
        &mut self,
        y: &Vector2<f64>,
        h_e: &SMatrix<f64, 2, 3>,
        r: &SMatrix<f64, 2, 2>,
        gate: f64,
        diag: &mut InnovDiag,
    ) -> bool {
        let mut h = SMatrix::<f64, 2, 6>::zeros();
        h.fixed_view_mut::<2, 3>(0, 0).copy_from(h_e);
        self.update(y, &h, r, gate, self.t_ns, diag)
    }

    /// Sets the yaw to `yaw` with 1-σ `sigma` (rad), independent of everything else (its
    /// cross-covariances cleared): a heading from another source. The history is turned by the
    /// same angle, so that late measurements compare against the new heading.
    pub fn set_yaw(&mut self, yaw: f64, sigma: f64) {
        let d = wrap_pi(yaw - self.euler.z);
        self.euler.z = wrap_pi(yaw);
        for h in self.hist.iter_mut() {
            h.1.z = wrap_pi(h.1.z + d);
        }
        for k in 0..6 {
            self.p[(2, k)] = 0.0;
            self.p[(k, 2)] = 0.0;
        }
        self.p[(2, 2)] = sigma * sigma;
        // The heading's σ is now the other source's, which the gyro's bias did not touch.
        self.bias_sd.z = 0.0;
    }

    /// Adds `var` (rad²) to the yaw variance: heading uncertainty the process model did not
    /// carry (see `paper::outage`).
    pub fn widen_yaw(&mut self, var: f64) {
        if var.is_finite() && var > 0.0 {
            self.p[(2, 2)] += var;
        }
    }

    /// Adds `var` (rad²) to the roll and pitch variances.
    pub fn widen_tilt(&mut self, var: f64) {
        self.p[(0, 0)] += var;
        self.p[(1, 1)] += var;
    }

    /// Joint part of a GNSS update (eqs. 32–33 through the lever arm, see `posvel`): the attitude
    /// correction `K_e y` with `K_e = P[:, e] H_eᵀ S⁻¹` for an innovation `y` whose covariance `s_inv`
    /// (inverse) the caller formed. Cross-covariances with the position/velocity filter are not
    /// kept (the paper's filters are separate).
    pub fn apply_joint(
        &mut self,
        h_e: &Matrix3<f64>,
        s_inv: &Matrix3<f64>,
        y: &Vector3<f64>,
        t_ns: i64,
    ) {
        let pht: SMatrix<f64, 6, 3> = self.p.fixed_columns::<3>(0) * h_e.transpose();
        let k = pht * s_inv;
        let dx = k * y;
        self.correct(&dx.fixed_rows::<3>(0).into_owned(), t_ns);
        self.chain += dx.fixed_rows::<3>(3);
        let before = self.p_euler().diagonal();
        self.p -= k * pht.transpose();
        self.p = (self.p + self.p.transpose()) * 0.5;
        self.shrink_bias_sd(&before);
    }

    /// Whether a pseudo-attitude chain is running.
    pub fn video_active(&self) -> bool {
        self.pseudo.is_some()
    }

    /// Eq. (34): accumulates the video delta-attitude into the pseudo-attitude (restarting from the
    /// filter's attitude at frame 0 when the chain of frames breaks) and fuses it as
    /// `z = Euler(Exp(η) C(e))` (eqs. C1–C2).
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
                // value"), once the filter is aligned. Its error is the filter's: in Euler angles
                // ê − e = −δe, as a NED rotation vector (inverse of eq. C2) η_0 = −T δe with
                // T = C J(φ,θ)⁻¹, so cov(η) = T P_ee Tᵀ and cov(δe, η) = −P_ee Tᵀ (the process
                // noise since frame 0 is neglected).
                self.pseudo = None;
                let pee = self.p_euler();
                if pee.diagonal().max() > start_sigma_rad.powi(2) {
                    return;
                }
                let Some(e0) = self.euler_at(m.t0_ns) else {
                    return;
                };
                let Some(j_inv) = euler_rate_matrix(e0.x, e0.y).try_inverse() else {
                    return;
                };
                let t = Rotation3::from_euler_angles(e0.x, e0.y, e0.z).into_inner() * j_inv;
                self.chain = Vector3::zeros();
                let pec = -pee * t.transpose();
                self.p
                    .fixed_view_mut::<3, 3>(3, 3)
                    .copy_from(&(t * pee * t.transpose()));
                self.p.fixed_view_mut::<3, 3>(0, 3).copy_from(&pec);
                self.p
                    .fixed_view_mut::<3, 3>(3, 0)
                    .copy_from(&pec.transpose());
                Some(UnitQuaternion::from_euler_angles(e0.x, e0.y, e0.z))
            }
        };
        let Some(q0) = base else { return };
        // nav_from_b1 = nav_from_b0 · b0_from_b1. A small error δθ of the video rotation (camera
        // axes) is the error R_bc δθ in body-1 axes (ε of eq. C1), i.e. C_1 R_bc δθ in NED.
        let q1 = q0 * b1_from_b0.inverse();
        let (r, p, y) = q1.euler_angles();
        let z = Vector3::new(r, p, y);
        let nav_from_cam =
            q1.to_rotation_matrix().into_inner() * r_bc.to_rotation_matrix().into_inner();
        // `cov_scale`: the allowance for the egomotion errors' time correlation (see
        // `EstimatorParams::paper_chain_cov_scale`): the chain sums them, so its variance grows
        // by the long-run (not the per-frame) variance of each delta. Eq. (C1): η grows by
        // C_1 R_bc δθ.
        let q_c = nav_from_cam * m.rot_cov * nav_from_cam.transpose() * cov_scale;
        let mut pcc = self.p.fixed_view_mut::<3, 3>(3, 3);
        pcc += q_c;
        self.pseudo = Some((m.t1_ns, q1));
        // Predicted pseudo-attitude Exp(η̂) C(ê) at the frame time and its Jacobians: a change δe
        // is the body-axis perturbation J(ê)⁻¹ δe, which moves the Euler angles of the product by
        // J(ẑ) J(ê)⁻¹ δe; a change δη (NED, left) moves them by J(ẑ) C(ẑ)ᵀ δη (eq. C2; the left
        // Jacobian of Exp at the sub-degree η is taken as I).
        let pred = self.euler_at(m.t1_ns).unwrap_or(self.euler);
        let c_pred = Rotation3::from_euler_angles(pred.x, pred.y, pred.z);
        let z_pred_rot = Rotation3::new(self.chain) * c_pred;
        let (zr, zp, zy) = z_pred_rot.euler_angles();
        let z_pred = Vector3::new(zr, zp, zy);
        let Some(j_pred_inv) = euler_rate_matrix(pred.x, pred.y).try_inverse() else {
            return;
        };
        let j_z = euler_rate_matrix(zr, zp);
        let y = wrap3(z - z_pred);
        let mut h = SMatrix::<f64, 3, 6>::zeros();
        h.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(j_z * j_pred_inv));
        h.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(j_z * z_pred_rot.matrix().transpose()));
        let r = Matrix3::identity() * PSEUDO_FLOOR_VAR;
        if !self.update(&y, &h, &r, gate, m.t1_ns, diag) {
            // The chain now carries an error its covariance does not describe: start a new one.
            self.pseudo = None;
        }
    }
}

/// Inputs of the eq. (D1) direction-of-travel measurement (see [`AttitudeEkf::direction_update`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectionMeas {
    /// Frame times of the video pair, ns.
    pub t0_ns: i64,
    /// Frame time of the second frame, ns: the attitude the direction is rotated with.
    pub t1_ns: i64,
    /// The video's direction of travel of the camera in body-1 axes (unit), `−R_bc t̂`.
    pub dir_body: Vector3<f64>,
    /// Its covariance in body axes (tangent to the unit sphere), already inflated for the time
    /// correlation of the vision errors.
    pub dir_cov_body: Matrix3<f64>,
    /// The GNSS-IMU filter's mean velocity of the camera over `[t0, t1]`, NED, m/s.
    pub vel_ned_mps: Vector3<f64>,
    /// Its covariance, (m/s)².
    pub vel_cov: Matrix3<f64>,
}

/// Smallest ratio of horizontal to total length of a direction for eq. (D1): the course is
/// undefined when the motion is vertical.
const D1_MIN_HORIZONTAL_RATIO: f64 = 0.3;

impl AttitudeEkf {
    /// Eq. (D1), our addition to VIDEO-IMU(1) (not in the paper): the video's direction of travel
    /// rotated into NED with the attitude, against the direction of the GNSS-IMU velocity.
    ///
    /// The essential matrix of a frame pair gives the translation direction `t̂` in camera-1 axes
    /// (`x₁ = R x₀ + t`), so the camera moved along `c₁ − c₀ ∝ −C(e₁) R_bc t̂`: in body-1 axes
    /// `u = −R_bc t̂`, in NED `d(e) = C(e₁) u`, with `e₁` the Euler angles at frame 1. The GNSS-IMU
    /// filter knows the same direction in NED without the attitude: its mean velocity of the camera
    /// over the pair, `w`. Both point the same way; the length carries no attitude information, so
    /// two angles are compared, the course `χ(x) = atan2(x_E, x_N)` and the flight-path angle
    /// `γ(x) = atan2(−x_D, |x_NE|)`:
    ///
    /// `z = [χ(w); γ(w)]`, `h(e) = [χ(C(e) u); γ(C(e) u)]`                              (D1)
    ///
    /// With `h_x = |x_NE|` and `n = |x|`: `∂χ/∂x = [−x_E, x_N, 0] / h_x²`,
    /// `∂γ/∂x = [x_N x_D, x_E x_D, −h_x²] / (h_x n²)` (`A(x)`, [`course_path_angle`]), so
    /// `H_e = A(d) ∂(C u)/∂e` with `∂(C u)/∂e` the lever-arm Jacobian ([`lever_jacobian`]), and
    /// `H_η = 0`. Noise `R = A(w) P_w A(w)ᵀ + A(d) C Σ_u Cᵀ A(d)ᵀ` (GNSS-IMU velocity and video
    /// direction, independent). In straight level flight `χ(w) − χ(d)` is the heading error: the
    /// video measures the direction of travel in the body (sideslip and angle of attack) and the
    /// GNSS the course, which together make the heading observable with any lever arm (the paper's
    /// filter sees the heading only through the lever arm, weakly for 2 m); `γ` does the same for
    /// the pitch. The roll about the direction of travel stays unobserved by it. Returns whether
    /// it was fused.
    pub fn direction_update(&mut self, m: &DirectionMeas, gate: f64, diag: &mut InnovDiag) -> bool {
        let Some(e1) = self.euler_at(m.t1_ns) else {
            return false;
        };
        let c1 = Rotation3::from_euler_angles(e1.x, e1.y, e1.z).into_inner();
        let d = c1 * m.dir_body;
        let w = m.vel_ned_mps;
        let steep = |x: &Vector3<f64>| x.xy().norm() < D1_MIN_HORIZONTAL_RATIO * x.norm();
        if steep(&d) || steep(&w) || w.norm() <= 0.0 {
            return false;
        }
        let (z, a_w) = course_path_angle(&w);
        let (z_pred, h_e, a_d) = direction_model(&e1, &m.dir_body);
        let y = Vector2::new(wrap_pi(z.x - z_pred.x), z.y - z_pred.y);
        let mut h = SMatrix::<f64, 2, 6>::zeros();
        h.fixed_view_mut::<2, 3>(0, 0).copy_from(&h_e);
        let r = a_w * m.vel_cov * a_w.transpose()
            + a_d * c1 * m.dir_cov_body * c1.transpose() * a_d.transpose();
        self.update(&y, &h, &r, gate, m.t1_ns, diag)
    }
}

/// Eq. (D1)'s prediction `h(e) = [χ(C(e) u); γ(C(e) u)]` for the body direction `u`, its
/// Jacobian w.r.t. the Euler angles, `A(C u) ∂(C u)/∂e`, and `A(C u)` itself (for the noise).
pub fn direction_model(
    euler: &Vector3<f64>,
    u: &Vector3<f64>,
) -> (Vector2<f64>, SMatrix<f64, 2, 3>, SMatrix<f64, 2, 3>) {
    let d = Rotation3::from_euler_angles(euler.x, euler.y, euler.z) * u;
    let (ang, a) = course_path_angle(&d);
    (ang, a * lever_jacobian(euler, u), a)
}

/// Course and flight-path angle of a NED vector `x` and their Jacobian w.r.t. `x` (eq. D1):
/// `χ = atan2(x_E, x_N)`, `γ = atan2(−x_D, |x_NE|)`;
/// `∂χ/∂x = [−x_E, x_N, 0] / h²`, `∂γ/∂x = [x_N x_D, x_E x_D, −h²] / (h n²)`, `h = |x_NE|`,
/// `n = |x|`. Scale-free: the Jacobian of the angles of a velocity is that of its direction over
/// its length.
pub fn course_path_angle(x: &Vector3<f64>) -> (Vector2<f64>, SMatrix<f64, 2, 3>) {
    let h2 = x.x * x.x + x.y * x.y;
    let h = h2.sqrt();
    let n2 = h2 + x.z * x.z;
    let ang = Vector2::new(x.y.atan2(x.x), (-x.z).atan2(h));
    let a = SMatrix::<f64, 2, 3>::new(
        -x.y / h2,
        x.x / h2,
        0.0,
        x.x * x.z / (h * n2),
        x.y * x.z / (h * n2),
        -h / n2,
    );
    (ang, a)
}

/// Eq. (F1): `∂(J(φ,θ) ω)/∂(φ,θ,ψ)` of eq. (31). With `a = cφ ω_y − sφ ω_z` and
/// `b = sφ ω_y + cφ ω_z`, `J ω = [ω_x + b tθ, a, b / cθ]`, so the rows are
/// `[a tθ, b / cθ², 0]`, `[−b, 0, 0]`, `[a / cθ, b tθ / cθ, 0]` (no yaw dependence).
pub fn euler_rate_jacobian(euler: &Vector3<f64>, w: &Vector3<f64>) -> Matrix3<f64> {
    let (sr, cr) = euler.x.sin_cos();
    let (sp, cp) = euler.y.sin_cos();
    let tp = sp / cp;
    let a = cr * w.y - sr * w.z;
    let b = sr * w.y + cr * w.z;
    Matrix3::new(
        a * tp,
        b / (cp * cp),
        0.0,
        -b,
        0.0,
        0.0,
        a / cp,
        b * tp / cp,
        0.0,
    )
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A late measurement's correction reaches the history from its time on, so that the next
    /// measurement at (or after) that time is compared against the corrected attitude.
    #[test]
    fn a_late_correction_reaches_the_history_from_the_measurement_time_on() {
        let sigma = Vector3::repeat(0.01);
        let mut att = AttitudeEkf::new(Vector3::new(0.1, 0.05, 1.0), sigma, 0);
        let dt_ns = 5_000_000;
        for k in 1..=20 {
            att.predict(
                &Vector3::zeros(),
                &Vector3::zeros(),
                5e-3,
                1e-9,
                0.0,
                k * dt_ns,
            );
        }
        let before = att.euler_at(5 * dt_ns - 1);
        let z = att.euler + Vector3::new(0.0, 0.0, 0.01);
        let mut diag = InnovDiag::new();
        att.update_euler(&z, [Some(0.001); 3], 3.29, 10 * dt_ns, &mut diag);
        assert_eq!(diag.fused, 1);
        // No gyro rate: every entry from the measurement time on equals the corrected attitude,
        // the entries before it are untouched.
        for t in [10 * dt_ns, 15 * dt_ns, 20 * dt_ns] {
            assert_eq!(att.euler_at(t), Some(att.euler), "at {t} ns");
        }
        assert_eq!(att.euler_at(5 * dt_ns - 1), before);
        assert!(att.euler.z > 1.0 + 0.009);
    }

    /// Eqs. (S1)–(S2): with no white noise, an unmeasured angle's σ grows linearly with a gyro
    /// bias σ (as a constant bias's error does), a measurement removes its share of it, and it
    /// never grows past that of an angle uniform round the circle.
    #[test]
    fn the_gyro_bias_share_grows_linearly_shrinks_with_a_measurement_and_is_bounded() {
        let sigma_b = 1e-3;
        let mut att = AttitudeEkf::new(Vector3::zeros(), Vector3::zeros(), 0);
        let dt_s = 0.01;
        let mut t_ns = 0;
        let mut run = |att: &mut AttitudeEkf, seconds: f64| {
            for _ in 0..(seconds / dt_s).round() as usize {
                t_ns += 10_000_000;
                let zero = Vector3::zeros();
                att.predict(&zero, &zero, dt_s, 0.0, sigma_b, t_ns);
            }
        };
        run(&mut att, 50.0);
        let yaw_sd = |att: &AttitudeEkf| att.p_euler()[(2, 2)].sqrt();
        assert!((yaw_sd(&att) - 0.05).abs() < 1e-6, "{}", yaw_sd(&att));
        run(&mut att, 50.0);
        assert!((yaw_sd(&att) - 0.1).abs() < 1e-6, "{}", yaw_sd(&att));
        // A yaw measured to 0.01 rad: the posterior σ ≈ 0.00995; the bias's share shrinks by
        // the same factor, so 10 s later σ ≈ 0.00995 + 0.01 (both parts grow together).
        let mut diag = InnovDiag::new();
        let (z, now_ns) = (att.euler, att.t_ns);
        att.update_euler(&z, [None, None, Some(0.01)], 3.29, now_ns, &mut diag);
        assert_eq!(diag.fused, 1);
        let post = yaw_sd(&att);
        assert!((post - 0.01 / 1.01f64.sqrt()).abs() < 1e-6, "{post}");
        run(&mut att, 10.0);
        assert!(
            (yaw_sd(&att) - (post + 0.01)).abs() < 1e-4,
            "{}",
            yaw_sd(&att)
        );
        // A day unaided: bounded.
        run(&mut att, 3000.0);
        assert!(yaw_sd(&att) <= MAX_BIAS_SD_RAD + 1e-3, "{}", yaw_sd(&att));
    }
}
