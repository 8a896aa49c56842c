//! Ground truth, as in the EuRoC `state_groundtruth_estimate0/data.csv` rows.

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
