//! GNSS antenna velocity (paper eq. 33): `v_ant = v + C (ω_nb × r)`; the `ω × r` term makes the
//! attitude and the gyro bias enter through the lever arm.
//!
//! Logic as for the position: gate, and after `gnss_reset_timeout_ns` of continuous rejection
//! inflate the velocity covariance by the squared innovation and fuse.

use nalgebra::{Matrix3, SMatrix, Vector3};
use uavnav_core::rotation::skew;

use super::gnss_consistency::{ConsistencyParams, VelConsistency};
use super::gnss_pos::GnssMeas;
use super::{InnovDiag, UpdateOutcome, gated_update_considering};
use crate::state::{Cov, ErrVec, IBG, ITH, IV, N, Nominal};

/// Residual and Jacobian of the antenna velocity; `gyro_b` is the raw gyro (ω_ib) at the fix time.
pub fn model(
    x: &Nominal,
    lever_b: &Vector3<f64>,
    gyro_b: &Vector3<f64>,
    w_ie: &Vector3<f64>,
    z: &Vector3<f64>,
) -> (Vector3<f64>, SMatrix<f64, 3, N>) {
    let c = x.q.to_rotation_matrix();
    let w_nb = gyro_b - x.bg - c.transpose() * w_ie;
    let lever_vel_n = c * w_nb.cross(lever_b);
    let pred = x.v + lever_vel_n;
    let mut h = SMatrix::<f64, 3, N>::zeros();
    h.fixed_view_mut::<3, 3>(0, IV)
        .copy_from(&Matrix3::identity());
    // The attitude enters twice: rotating the lever velocity, and through ω_nb = ω_ib − Cᵀ ω_ie.
    let c_r_ct = c.matrix() * skew(lever_b) * c.matrix().transpose();
    h.fixed_view_mut::<3, 3>(0, ITH)
        .copy_from(&(-skew(&lever_vel_n) + c_r_ct * skew(w_ie)));
    h.fixed_view_mut::<3, 3>(0, IBG)
        .copy_from(&(c.matrix() * skew(lever_b)));
    (z - pred, h)
}

/// The GNSS velocity aiding source.
#[derive(Debug, Clone, PartialEq)]
pub struct GnssVelSource {
    /// Diagnostics.
    pub diag: InnovDiag,
    /// Resets performed.
    pub resets: u32,
    /// The receiver's velocities against its own positions (eq. V1): what they are fused with.
    pub consistency: VelConsistency,
}

impl Default for GnssVelSource {
    fn default() -> Self {
        Self {
            diag: InnovDiag::new(),
            resets: 0,
            consistency: VelConsistency::default(),
        }
    }
}

impl GnssVelSource {
    /// Takes every fix (fused or not) into the consistency monitor, in time order.
    pub fn observe(&mut self, meas: &GnssMeas, params: &ConsistencyParams) {
        self.consistency.push(meas, params);
    }

    /// Fuses one fix's velocity, with the variance of [`VelConsistency::velocity_var`]; returns the correction to inject, if any.
    #[allow(clippy::too_many_arguments)]
    pub fn fuse(
        &mut self,
        x: &Nominal,
        p: &mut Cov,
        lever_b: &Vector3<f64>,
        gyro_b: &Vector3<f64>,
        w_ie: &Vector3<f64>,
        meas: &GnssMeas,
        gate_sigma: f64,
        reset_timeout_ns: i64,
        consider: &[usize],
    ) -> Option<ErrVec> {
        let v_meas = meas.vel_ned_mps?;
        let (y, h) = model(x, lever_b, gyro_b, w_ie, &v_meas);
        let var = self.consistency.velocity_var(meas.sigma_vel_mps);
        let r = Matrix3::from_diagonal(&var.map(|v| v.max(1e-6)));
        let stuck = self.diag.consecutive_rejects > 0
            && meas.t_ns - self.diag.first_reject_t_ns >= reset_timeout_ns;
        if stuck {
            for k in 0..3 {
                p[(IV + k, IV + k)] += y[k] * y[k];
            }
            self.resets += 1;
        }
        match gated_update_considering(
            p,
            &h,
            &r,
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
