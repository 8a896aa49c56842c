//! Helpers to build the [`uavnav_core::MotionPrior`] from raw IMU data (for the CLI and tests;
//! the estimator builds its own prior from its state).

use nalgebra::{UnitQuaternion, Vector3};
use uavnav_core::ImuSample;

/// Integrates the gyro between `t0_ns` and `t1_ns` (piecewise constant rates, samples sorted by
/// time) and returns `body1_from_body0`, the rotation taking body-0 coordinates into body-1
/// coordinates. `None` when the samples do not cover the interval.
pub fn gyro_rotation(
    imu: &[ImuSample],
    t0_ns: i64,
    t1_ns: i64,
    gyro_bias_radps: &Vector3<f64>,
) -> Option<UnitQuaternion<f64>> {
    if t1_ns < t0_ns || imu.is_empty() || imu[0].t_ns > t0_ns || imu[imu.len() - 1].t_ns < t1_ns {
        return None;
    }
    // body0_from_body(t) accumulates Exp(ω dt) on the right
    let mut q = UnitQuaternion::identity();
    for w in imu.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        let lo = a.t_ns.max(t0_ns);
        let hi = b.t_ns.min(t1_ns);
        if hi <= lo {
            continue;
        }
        let dt_s = (hi - lo) as f64 * 1e-9;
        let omega = 0.5 * (a.gyro_radps + b.gyro_radps) - gyro_bias_radps;
        q *= UnitQuaternion::from_scaled_axis(omega * dt_s);
    }
    Some(q.inverse())
}
