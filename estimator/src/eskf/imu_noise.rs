//! The IMU's own noise, measured from its samples: what the covariance prediction takes as process
//! noise where it exceeds the configured densities (vibration, a logged IMU too slow for the
//! motion), clipped samples inflated, and the measured noise reported in health against the
//! configured (`Health::imu_noise_ratio`).

use uavnav_core::ImuSample;

use super::Eskf;
use crate::params::EstimatorParams;

/// 1-σ of the specific force a clipped accelerometer axis may have missed, m/s² (PX4 uses
/// 4.9 m/s² of accelerometer noise for bad-accelerometer intervals; clipping is worse).
pub const CLIP_ACCEL_SIGMA_MPS2: f64 = 10.0;
/// 1-σ of the rate a clipped gyro axis may have missed, rad/s.
pub const CLIP_GYRO_SIGMA_RADPS: f64 = 1.0;
/// Time constant of the IMU noise ratio reported in health (`Health::imu_noise_ratio`), s: one
/// 20 ms covariance interval holds four sample differences at 200 Hz, too few to report alone.
pub const IMU_NOISE_TAU_S: f64 = 1.0;

/// Whether the interval `a`–`b` has a clipped accelerometer / gyro axis: at or beyond the
/// configured clip level at `b`, or the same non-small reading repeated exactly (a saturated
/// axis reads its full-scale value; a live axis never repeats to the last bit above 2 g / 3 rad/s).
pub fn clipped(a: &ImuSample, b: &ImuSample, p: &EstimatorParams) -> (bool, bool) {
    let axis = |va: f64, vb: f64, clip: f64, plateau: f64| {
        vb.abs() >= clip || (vb == va && vb.abs() > plateau)
    };
    let accel = (0..3).any(|k| {
        axis(
            a.accel_mps2[k],
            b.accel_mps2[k],
            p.imu_accel_clip_mps2,
            2.0 * 9.81,
        )
    });
    let gyro = (0..3).any(|k| axis(a.gyro_radps[k], b.gyro_radps[k], p.imu_gyro_clip_radps, 3.0));
    (accel, gyro)
}

impl Eskf {
    /// Real IMUs are noisier in flight than their datasheets (vibration: 10–20× on the shared
    /// ArduPilot copters), and a logged 10 Hz IMU of a manoeuvring aircraft misses what happens
    /// between its samples. Both show in the change between consecutive samples: for white noise
    /// of σ per sample, `E|Δ|² = 2σ²` per axis; for a sampled signal, the integration error of one
    /// interval is of the order of `|Δ| dt / 2`. The per-axis variance `|Δ|² dt² / 6` of each
    /// interval is accumulated and used as the process noise where it exceeds the configured
    /// densities (`flush_cov`), so the filter's confidence follows the data it is given.
    pub(super) fn observed_imu_noise(&mut self, a: &ImuSample, b: &ImuSample, dt_s: f64) {
        if dt_s.is_nan() || dt_s <= 0.0 {
            return;
        }
        let (gyro_var, accel_var) = crate::prediction::interval_noise_var(a, b, dt_s);
        self.acc.gyro_var += gyro_var;
        self.acc.accel_var += accel_var;
        let (accel_clipped, gyro_clipped) = clipped(a, b, &self.params);
        if accel_clipped || gyro_clipped {
            self.imu_clipped += 1;
        }
        // What a clipped axis missed is unknown but large: PX4 and ArduPilot inflate the same way
        // rather than drop the sample (dropping loses the part that was measured).
        if accel_clipped {
            self.acc.accel_var += 3.0 * (CLIP_ACCEL_SIGMA_MPS2 * dt_s).powi(2);
        }
        if gyro_clipped {
            self.acc.gyro_var += 3.0 * (CLIP_GYRO_SIGMA_RADPS * dt_s).powi(2);
        }
    }

    /// Folds the accumulated interval's measured noise (`dt` s of it) into the reported ratio,
    /// an exponential average of the variance ratio over [`IMU_NOISE_TAU_S`].
    pub(super) fn report_imu_noise(&mut self, dt: f64) {
        let a = 1.0 - (-dt / IMU_NOISE_TAU_S).exp();
        let [g0, a0] = self.imu_noise_ratio.map_or([1.0; 2], |r| r.map(|v| v * v));
        let (g1, a1) = (
            self.acc.gyro_var / dt / self.noise.gyro_psd,
            self.acc.accel_var / dt / self.noise.accel_psd,
        );
        self.imu_noise_ratio = Some([(g0 + a * (g1 - g0)).sqrt(), (a0 + a * (a1 - a0)).sqrt()])
            .filter(|r| r.iter().all(|v| v.is_finite()));
    }
}
