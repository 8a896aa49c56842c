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

/// Attitudes at the frame times and the displacement between them, carried back from the newest
/// state through the retained IMU samples (backward strapdown; Earth rate and Coriolis neglected
/// over a fraction of a second).
#[derive(Debug, Clone, Copy)]
struct Backward {
    c0: UnitQuaternion<f64>,
    c1: UnitQuaternion<f64>,
    /// Body displacement p(t1) − p(t0), m.
    disp: Vector3<f64>,
}

fn carry_back(
    imu: &VecDeque<ImuSample>,
    now: &NowState,
    g: &Vector3<f64>,
    t0_ns: i64,
    t1_ns: i64,
) -> Option<Backward> {
    if imu.front()?.t_ns > t0_ns || t1_ns < t0_ns {
        return None;
    }
    let (mut c, mut v) = (now.q, now.v);
    let (mut c0, mut c1) = (None, if t1_ns >= now.t_ns { Some(now.q) } else { None });
    let mut disp = Vector3::zeros();
    let pairs: Vec<(&ImuSample, &ImuSample)> = imu.iter().zip(imu.iter().skip(1)).collect();
    for (a, b) in pairs.into_iter().rev() {
        if a.t_ns >= now.t_ns {
            continue;
        }
        // Split the interval at the frame times so the attitudes are exact there.
        let mut cuts = vec![b.t_ns.min(now.t_ns)];
        for t in [t1_ns, t0_ns] {
            if t > a.t_ns && t < cuts[cuts.len() - 1] {
                cuts.push(t);
            }
        }
        cuts.push(a.t_ns);
        for w in cuts.windows(2) {
            let (hi, lo) = (w[0], w[1]);
            let m = mean_of(&interp(a, b, lo), &interp(a, b, hi));
            let dt = (hi - lo) as f64 * 1e-9;
            let half = UnitQuaternion::from_scaled_axis((m.gyro - now.bg) * (-0.5 * dt));
            let c_mid = c * half;
            let acc = c_mid * m.accel + g;
            let v_lo = v - acc * dt;
            if lo >= t0_ns && hi <= t1_ns {
                disp += (v + v_lo) * (0.5 * dt);
            }
            c = c_mid * half;
            v = v_lo;
            if lo == t1_ns {
                c1 = Some(c);
            }
            if lo == t0_ns {
                c0 = Some(c);
            }
        }
        if c0.is_some() {
            break;
        }
    }
    Some(Backward {
        c0: c0?,
        c1: c1?,
        disp,
    })
}

/// Distance from a camera centre (local NED, m) down to the terrain of the Earth-surface model
/// (the ellipsoid at `terrain_elevation_m`), m: the `d` of the plane solver, used both for the
/// prior and for the estimator's model of the plane-scaled translation (eq. V2).
pub fn terrain_distance_m(
    frame: &LocalFrame,
    centre_ned_m: &Vector3<f64>,
    terrain_elevation_m: f64,
) -> f64 {
    frame.ned_to_lla(centre_ned_m).alt_m - terrain_elevation_m
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
    let g = frame.gravity_ned(&now.p);
    let Some(back) = carry_back(imu, now, &g, t0_ns, t1_ns) else {
        return prior;
    };
    let (c0, c1) = (back.c0, back.c1);
    let r_c0n = (c0 * r_bc).inverse();
    // The terrain is the ellipsoid at the terrain elevation: its normal is the local vertical
    // under the vehicle, which leans away from the fixed frame's down by distance / Earth radius
    // (≈ 0.5 mrad after 3 km). The plane solver refines the normal from the image (2° prior), so
    // on the paper flights this moved the attitude by < 0.001°; the prior should still be right.
    let n_cam0 = r_c0n * g.normalize();
    prior.ground_normal_cam0 = Some(Unit::new_normalize(n_cam0));
    let t_bc = body_from_cam.translation.vector;
    let p0 = now.p - now.v * ((now.t_ns - t0_ns) as f64 * 1e-9);
    let h = terrain_distance_m(frame, &(p0 + c0 * t_bc), terrain_elevation_m);
    if h > 0.0 {
        prior.ground_distance_m = Some(h);
    }
    // t = R_c1n (centre0 − centre1), centre_k = p_k + C_k t_bc.
    let d = -back.disp + c0 * t_bc - c1 * t_bc;
    prior.t_cam1_m = Some((c1 * r_bc).inverse() * d);
    prior
}
