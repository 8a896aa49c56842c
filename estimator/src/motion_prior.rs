//! The [`MotionPrior`] handed to the vision front end (paper section IV-A: the IMU predicts the
//! optical flow; the terrain model gives the scene plane).

use std::collections::VecDeque;

use nalgebra::{Isometry3, Unit, UnitQuaternion, Vector3};
use uavnav_core::{ImuSample, LocalFrame, MotionPrior};

use crate::eskf::interp;
use crate::output_predictor::mean_of;

/// The filter's newest state used by the prior.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NowState {
    /// Time, ns.
    pub t_ns: i64,
    /// nav_from_body.
    pub q: UnitQuaternion<f64>,
    /// Position NED, m.
    pub p: Vector3<f64>,
    /// Velocity NED, m/s.
    pub v: Vector3<f64>,
    /// Gyro bias, rad/s.
    pub bg: Vector3<f64>,
}

/// `body(t0)_from_body(t1)` integrated from retained gyro samples with the bias removed (Earth rate
/// neglected over a frame interval); `None` when `[t0, t1]` is not covered by the samples.
pub fn gyro_rotation(
    imu: &VecDeque<ImuSample>,
    t0_ns: i64,
    t1_ns: i64,
    bg: &Vector3<f64>,
) -> Option<UnitQuaternion<f64>> {
    let first = imu.front()?;
    let last = imu.back()?;
    if t0_ns < first.t_ns || t1_ns > last.t_ns || t1_ns < t0_ns {
        return None;
    }
    let mut q = UnitQuaternion::identity();
    for (a, b) in imu.iter().zip(imu.iter().skip(1)) {
        let lo = a.t_ns.max(t0_ns);
        let hi = b.t_ns.min(t1_ns);
        if hi <= lo {
            continue;
        }
        let m = mean_of(&interp(a, b, lo), &interp(a, b, hi));
        q *= UnitQuaternion::from_scaled_axis((m.gyro - bg) * ((hi - lo) as f64 * 1e-9));
    }
    Some(q)
}

/// Builds the prior: gyro rotation `cam1_from_cam0`, the ground normal and distance in camera 0
/// (flat terrain at `terrain_elevation_m` above the ellipsoid), and `t` from the velocity.
#[allow(clippy::too_many_arguments)]
pub fn prior(
    imu: &VecDeque<ImuSample>,
    body_from_cam: &Isometry3<f64>,
    frame: &LocalFrame,
    now: &NowState,
    t0_ns: i64,
    t1_ns: i64,
    terrain_elevation_m: f64,
    gyro_noise_density: f64,
    gyro_bias_sigma: f64,
) -> MotionPrior {
    let mut prior = MotionPrior::default();
    let Some(b0_from_b1) = gyro_rotation(imu, t0_ns, t1_ns, &now.bg) else {
        return prior;
    };
    let r_bc = body_from_cam.rotation;
    prior.cam1_from_cam0 = Some(r_bc.inverse() * b0_from_b1.inverse() * r_bc);
    let dt_s = (t1_ns - t0_ns) as f64 * 1e-9;
    prior.rot_sigma_rad = gyro_noise_density * dt_s.sqrt() + gyro_bias_sigma * dt_s;
    // Attitudes at the frame times: the newest attitude carried back by the gyros.
    let back =
        |t: i64| gyro_rotation(imu, t, now.t_ns.max(t), &now.bg).map(|r| now.q * r.inverse());
    let (Some(c0), Some(c1)) = (back(t0_ns), back(t1_ns)) else {
        return prior;
    };
    let r_c0n = (c0 * r_bc).inverse();
    prior.ground_normal_cam0 = Some(Unit::new_normalize(r_c0n * Vector3::z()));
    let p0 = now.p - now.v * ((now.t_ns - t0_ns) as f64 * 1e-9);
    let cam0 = p0 + c0 * body_from_cam.translation.vector;
    let n_cam0 = r_c0n * Vector3::z();
    let h = frame.ned_to_lla(&cam0).alt_m - terrain_elevation_m;
    if h > 0.0 && n_cam0.norm() > 0.0 {
        prior.ground_distance_m = Some(h);
    }
    prior.t_cam1_m = Some(-((c1 * r_bc).inverse() * (now.v * dt_s)));
    prior
}
