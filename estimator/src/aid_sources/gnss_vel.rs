//! GNSS antenna velocity (paper eq. 33): `v_ant = v + C (ω_nb × r)`; the `ω × r` term makes the
//! attitude and the gyro bias enter through the lever arm.
//!
//! The gyro in `ω × r` carries its white noise into the prediction. It is the mean of the
//! samples around the fix ([`lever_gyro`]); with a σ_ω per axis (PSD / interval / samples) the
//! predicted antenna velocity has the covariance `σ_ω² C [r]× [r]×ᵀ Cᵀ = σ_ω² (|r|² I − C r rᵀ
//! Cᵀ)`, added to the receiver's (eq. 33n). One sample of a consumer-grade gyro (0.028 rad/s at
//! 200 Hz) on an 8 m lever arm gives 0.23 m/s, four times a receiver's velocity σ: left out, the
//! filter read that noise as attitude and velocity information (simulated, GNSS only: 90 % of
//! the samples within 3σ, now 99.9 %).
//!
//! Logic as for the position: gate, and after `gnss_reset_timeout_ns` of continuous rejection
//! inflate the velocity covariance by the squared innovation and fuse.

use nalgebra::{Matrix3, SMatrix, Vector3};
use uavnav_core::ImuSample;
use uavnav_core::rotation::skew;

use super::gnss_consistency::{ConsistencyParams, VelConsistency};
use super::gnss_pos::GnssMeas;
use super::{InnovDiag, UpdateOutcome, gated_update_considering};
use crate::state::{Cov, ErrVec, IBG, ITH, IV, N, Nominal};

/// Half-width of the window of gyro samples averaged for the lever-arm term, ns. The rate of a
/// flying vehicle changes over tenths of a second and more; the gyro's white noise averages down
/// as `1/n` in variance (21 samples at 200 Hz: σ_ω / 4.6). The window is centred on the fix (the
/// filter keeps the samples just behind its horizon for it): an offset window would turn the
/// rate's change into a velocity bias in turn entries.
pub const LEVER_GYRO_HALF_WINDOW_NS: i64 = 50_000_000;

/// The mean gyro sample within [`LEVER_GYRO_HALF_WINDOW_NS`] of `t_ns`, and how many samples it
/// averages; `None` when none lies in the window.
pub fn lever_gyro<'a>(
    samples: impl IntoIterator<Item = &'a ImuSample>,
    t_ns: i64,
) -> Option<(Vector3<f64>, usize)> {
    let (sum, n) = samples
        .into_iter()
        .filter(|s| (s.t_ns - t_ns).abs() <= LEVER_GYRO_HALF_WINDOW_NS)
        .fold((Vector3::zeros(), 0usize), |(sum, n), s| {
            (sum + s.gyro_radps, n + 1)
        });
    (n > 0).then(|| (sum / n as f64, n))
}

/// Covariance of the predicted lever-arm velocity from the gyro sample's white noise (eq. 33n).
pub fn lever_noise_cov(x: &Nominal, lever_b: &Vector3<f64>, gyro_var_radps2: f64) -> Matrix3<f64> {
    let r_n = x.q * lever_b;
    (Matrix3::identity() * r_n.norm_squared() - r_n * r_n.transpose()) * gyro_var_radps2.max(0.0)
}

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

    /// Fuses one fix's velocity, with the variance of [`VelConsistency::velocity_var`] and that of
    /// the lever-arm term ([`lever_noise_cov`], `gyro_var_radps2` per axis for the sample
    /// `gyro_b`); returns the correction to inject, if any.
    #[allow(clippy::too_many_arguments)]
    pub fn fuse(
        &mut self,
        x: &Nominal,
        p: &mut Cov,
        lever_b: &Vector3<f64>,
        gyro_b: &Vector3<f64>,
        gyro_var_radps2: f64,
        w_ie: &Vector3<f64>,
        meas: &GnssMeas,
        gate_sigma: f64,
        reset_timeout_ns: i64,
        consider: &[usize],
    ) -> Option<ErrVec> {
        let v_meas = meas.vel_ned_mps?;
        let (y, h) = model(x, lever_b, gyro_b, w_ie, &v_meas);
        let var = self.consistency.velocity_var(meas.sigma_vel_mps);
        let r = Matrix3::from_diagonal(&var.map(|v| v.max(1e-6)))
            + lever_noise_cov(x, lever_b, gyro_var_radps2);
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

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t_ns: i64, z: f64) -> ImuSample {
        ImuSample {
            t_ns,
            gyro_radps: Vector3::new(0.0, 0.0, z),
            accel_mps2: Vector3::zeros(),
        }
    }

    #[test]
    fn the_lever_gyro_is_the_mean_of_the_samples_around_the_fix_only() {
        // 200 Hz; the rate is the sample's time in ms, so the mean tells which were taken.
        let s: Vec<_> = (0..100)
            .map(|k| sample(k * 5_000_000, k as f64 * 5.0))
            .collect();
        let (g, n) = lever_gyro(&s, 200_000_000).unwrap();
        assert_eq!(n, 21); // 150..=250 ms
        assert!((g.z - 200.0).abs() < 1e-9);
        assert!(lever_gyro(&s, 2_000_000_000).is_none());
    }

    #[test]
    fn the_lever_noise_lies_across_the_lever_and_scales_with_its_square() {
        let x = Nominal {
            t_ns: 0,
            p: Vector3::zeros(),
            v: Vector3::zeros(),
            q: nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, 0.5),
            bg: Vector3::zeros(),
            ba: Vector3::zeros(),
            gm: Vector3::zeros(),
            clone: None,
        };
        let r = Vector3::new(0.0, 8.0, 0.0);
        let c = lever_noise_cov(&x, &r, 1e-4);
        let r_n = x.q * r;
        assert!((c * r_n).norm() < 1e-12, "no noise along the lever");
        assert!((c.trace() - 2.0 * 64.0 * 1e-4).abs() < 1e-12);
        assert_eq!(lever_noise_cov(&x, &r, -1.0), Matrix3::zeros());
    }
}
