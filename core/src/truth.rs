//! Ground truth, as in the EuRoC `state_groundtruth_estimate0/data.csv` rows, and its interpolation
//! at an estimate's time.

use nalgebra::{UnitQuaternion, Vector3};

/// One ground-truth sample of the body (IMU) frame relative to the local NED frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthSample {
    /// Time, ns.
    pub t_ns: i64,
    /// Body origin in local NED (origin = the dataset's `origin`), m.
    pub pos_ned_m: Vector3<f64>,
    /// Rotation of body vectors into NED (`nav_from_body`), Hamilton.
    pub nav_from_body: UnitQuaternion<f64>,
    /// Body velocity in NED, m/s.
    pub vel_ned_mps: Vector3<f64>,
    /// Gyro bias, body frame, rad/s.
    pub gyro_bias_radps: Vector3<f64>,
    /// Accelerometer bias, body frame, m/s².
    pub accel_bias_mps2: Vector3<f64>,
}

/// Truth interpolated at `t_ns` (linear position/velocity, slerp attitude); `truth` sorted by time.
pub fn truth_at(truth: &[TruthSample], t_ns: i64) -> Option<TruthSample> {
    let i = truth.partition_point(|s| s.t_ns < t_ns);
    if i < truth.len() && truth[i].t_ns == t_ns {
        return Some(truth[i]);
    }
    if i == 0 || i >= truth.len() {
        return None;
    }
    let (a, b) = (&truth[i - 1], &truth[i]);
    let w = (t_ns - a.t_ns) as f64 / (b.t_ns - a.t_ns) as f64;
    Some(TruthSample {
        t_ns,
        pos_ned_m: a.pos_ned_m.lerp(&b.pos_ned_m, w),
        vel_ned_mps: a.vel_ned_mps.lerp(&b.vel_ned_mps, w),
        nav_from_body: a.nav_from_body.slerp(&b.nav_from_body, w),
        gyro_bias_radps: a.gyro_bias_radps.lerp(&b.gyro_bias_radps, w),
        accel_bias_mps2: a.accel_bias_mps2.lerp(&b.accel_bias_mps2, w),
    })
}
