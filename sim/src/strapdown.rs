//! A reference strapdown integrator for the simulator's physics contract (see the crate doc).
//!
//! It exists to prove the truth and the IMU agree: RK4 on attitude quaternion, velocity and
//! position, with the IMU signal interpolated by a cubic Lagrange polynomial through four
//! neighbouring samples (the samples are instantaneous values, so higher-order interpolation
//! recovers the continuous signal to O(dt⁴)). Earth rate, Coriolis and position-dependent gravity
//! are included.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use uavnav_core::geodesy::OMEGA_EARTH_RADPS;
use uavnav_core::{ImuSample, LocalFrame};

/// Earth rotation rate `ω_ie^n` expressed in the fixed NED frame at latitude `lat0_rad`, rad/s.
pub fn earth_rate_ned(lat0_rad: f64) -> Vector3<f64> {
    Vector3::new(
        OMEGA_EARTH_RADPS * lat0_rad.cos(),
        0.0,
        -OMEGA_EARTH_RADPS * lat0_rad.sin(),
    )
}

/// Navigation state in the fixed local NED frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavState {
    /// Position, m.
    pub pos_ned_m: Vector3<f64>,
    /// Velocity, m/s.
    pub vel_ned_mps: Vector3<f64>,
    /// Attitude, body → NED.
    pub nav_from_body: UnitQuaternion<f64>,
}

/// Time derivative of (q, v, p) for gyro `w` and specific force `f` (the contract's equations).
fn derivative(
    frame: &LocalFrame,
    omega_ie: &Vector3<f64>,
    q: &Quaternion<f64>,
    v: &Vector3<f64>,
    p: &Vector3<f64>,
    w: &Vector3<f64>,
    f: &Vector3<f64>,
) -> (Quaternion<f64>, Vector3<f64>, Vector3<f64>) {
    let uq = UnitQuaternion::new_normalize(*q);
    // The NED frame is Earth-fixed: ω_nb^b = ω_ib^b − C_n^b ω_ie^n.
    let w_nb = w - uq.inverse_transform_vector(omega_ie);
    let q_dot = q * Quaternion::from_parts(0.0, w_nb) * 0.5;
    let v_dot = uq.transform_vector(f) + frame.gravity_ned(p) - 2.0 * omega_ie.cross(v);
    (q_dot, v_dot, *v)
}

/// Cubic Lagrange weights for nodes −1, 0, 1, 2 at `tau` in [0, 1].
fn lagrange4(tau: f64) -> [f64; 4] {
    [
        -tau * (tau - 1.0) * (tau - 2.0) / 6.0,
        (tau + 1.0) * (tau - 1.0) * (tau - 2.0) / 2.0,
        -(tau + 1.0) * tau * (tau - 2.0) / 2.0,
        (tau + 1.0) * tau * (tau - 1.0) / 6.0,
    ]
}

/// The IMU signal at fraction `tau` of interval `k → k+1` (cubic inside, linear at the ends).
fn interpolate(imu: &[ImuSample], k: usize, tau: f64) -> (Vector3<f64>, Vector3<f64>) {
    if k >= 1 && k + 2 < imu.len() {
        let w = lagrange4(tau);
        let mut g = Vector3::zeros();
        let mut a = Vector3::zeros();
        for (i, wi) in w.iter().enumerate() {
            g += imu[k + i - 1].gyro_radps * *wi;
            a += imu[k + i - 1].accel_mps2 * *wi;
        }
        (g, a)
    } else {
        let (s0, s1) = (&imu[k], &imu[k + 1]);
        (
            s0.gyro_radps.lerp(&s1.gyro_radps, tau),
            s0.accel_mps2.lerp(&s1.accel_mps2, tau),
        )
    }
}

/// Integrates `imu` (uniformly spaced) from `initial` at `imu[0].t_ns`; returns the state at every
/// sample time (the first is `initial`).
pub fn integrate(frame: &LocalFrame, initial: NavState, imu: &[ImuSample]) -> Vec<NavState> {
    let omega_ie = earth_rate_ned(frame.origin().lat_rad);
    let mut out = Vec::with_capacity(imu.len());
    out.push(initial);
    let mut q = *initial.nav_from_body.quaternion();
    let (mut v, mut p) = (initial.vel_ned_mps, initial.pos_ned_m);
    for k in 0..imu.len().saturating_sub(1) {
        let h = (imu[k + 1].t_ns - imu[k].t_ns) as f64 * 1e-9;
        let (w0, f0) = interpolate(imu, k, 0.0);
        let (wm, fm) = interpolate(imu, k, 0.5);
        let (w1, f1) = interpolate(imu, k, 1.0);
        let d = |q: &Quaternion<f64>, v: &Vector3<f64>, p: &Vector3<f64>, w, f| {
            derivative(frame, &omega_ie, q, v, p, w, f)
        };
        let (q1, v1, p1) = d(&q, &v, &p, &w0, &f0);
        let (q2, v2, p2) = d(
            &(q + q1 * (h / 2.0)),
            &(v + v1 * (h / 2.0)),
            &(p + p1 * (h / 2.0)),
            &wm,
            &fm,
        );
        let (q3, v3, p3) = d(
            &(q + q2 * (h / 2.0)),
            &(v + v2 * (h / 2.0)),
            &(p + p2 * (h / 2.0)),
            &wm,
            &fm,
        );
        let (q4, v4, p4) = d(&(q + q3 * h), &(v + v3 * h), &(p + p3 * h), &w1, &f1);
        q = (q + (q1 + q2 * 2.0 + q3 * 2.0 + q4) * (h / 6.0)).normalize();
        v += (v1 + v2 * 2.0 + v3 * 2.0 + v4) * (h / 6.0);
        p += (p1 + p2 * 2.0 + p3 * 2.0 + p4) * (h / 6.0);
        out.push(NavState {
            pos_ned_m: p,
            vel_ned_mps: v,
            nav_from_body: UnitQuaternion::new_unchecked(q),
        });
    }
    out
}
