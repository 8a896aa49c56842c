//! Profile `paper`: the alignment from GNSS (the "initial known value" of eq. 34, see the
//! `paper` module doc): the tilt and course pseudo-measurements fused at every fix until the
//! attitude is known, their σ (eq. C1: the course solved at the filter's roll and pitch carries
//! their σ), and the rule that says when the alignment has settled enough for the video chain.

use nalgebra::Vector3;

use super::attitude::AttitudeEkf;
use crate::init::attitude_from_gravity;

/// Floor of the course pseudo-measurement's σ, rad: the no-sideslip heading's sensitivity to the
/// roll/pitch error in banked flight and the velocity's timing (0.1°). The course σ itself is the
/// cross-track velocity σ over the speed (0.05 m/s at 30 m/s: 0.1°); the earlier fixed 0.05 rad
/// was 30× that, so the alignment barely reached the 0.5° start σ of the video and left roll and
/// pitch σ at the threshold.
const GNSS_COURSE_FLOOR_RAD: f64 = 0.002;

/// GNSS-derived attitude pseudo-measurement for the no-video case (see the module doc).
#[allow(clippy::too_many_arguments)]
pub(super) fn gnss_attitude_aiding(
    att: &mut AttitudeEkf,
    f_b: &Vector3<f64>,
    g_app_n: &Vector3<f64>,
    vel_n: &Vector3<f64>,
    tilt_sigma: Option<f64>,
    course_sigma: f64,
    min_speed: f64,
    gate: f64,
    diag: &mut crate::aid_sources::InnovDiag,
) {
    let moving = vel_n.xy().norm() >= min_speed;
    let yaw = if moving {
        vel_n.y.atan2(vel_n.x)
    } else {
        att.euler.z
    };
    let Some(q) = attitude_from_gravity(f_b, g_app_n, yaw) else {
        return;
    };
    let (r, p, y) = q.euler_angles();
    let (y, course_sigma) = match (moving, tilt_sigma) {
        (false, _) => (y, course_sigma),
        (true, Some(_)) => (heading_without_sideslip(r, p, vel_n), course_sigma),
        // Solved at the filter's roll and pitch when this fix's own are not fused: they carry
        // the GNSS acceleration's noise (12° for a receiver 0.3 m/s noisy at 5 Hz, which put the
        // heading 5° off at a σ of 0.6°). That heading moves with the roll and pitch it is
        // solved at (by tan(roll) per unit of pitch in a bank): their uncertainty is the
        // course's too (eq. C1), by central differences.
        (true, None) => {
            let (r0, p0) = (att.euler.x, att.euler.y);
            let y0 = heading_without_sideslip(r0, p0, vel_n);
            let dy = |a: f64, b: f64| {
                uavnav_core::rotation::wrap_pi(heading_without_sideslip(a, b, vel_n) - y0)
            };
            let d = 1e-4;
            let dr = (dy(r0 + d, p0) - dy(r0 - d, p0)) / (2.0 * d);
            let dp = (dy(r0, p0 + d) - dy(r0, p0 - d)) / (2.0 * d);
            let p_e = att.p_euler();
            let var = dr * dr * p_e[(0, 0)] + dp * dp * p_e[(1, 1)] + 2.0 * dr * dp * p_e[(0, 1)];
            (y0, (course_sigma * course_sigma + var.max(0.0)).sqrt())
        }
    };
    let course_sigma = moving.then_some(course_sigma);
    att.update_euler(
        &Vector3::new(r, p, y),
        [tilt_sigma, tilt_sigma, course_sigma],
        gate,
        att.t_ns,
        diag,
    );
}

/// 1-σ of the course pseudo-measurement, rad: the velocity noise across the track over the
/// horizontal speed, combined with `GNSS_COURSE_FLOOR_RAD`.
pub(super) fn course_sigma_rad(sigma_vel_mps: f64, v: &Vector3<f64>) -> f64 {
    let vh = v.xy().norm().max(1e-3);
    (sigma_vel_mps / vh).hypot(GNSS_COURSE_FLOOR_RAD)
}

/// The heading that puts the velocity in the body x–z plane (coordinated flight, no sideslip) at
/// the given roll and pitch: solves `(Cᵀ v)_y = 0` by Newton's method from the course. With an
/// angle of attack in a banked turn the heading differs from the course; this accounts for it.
pub fn heading_without_sideslip(roll: f64, pitch: f64, vel_n: &Vector3<f64>) -> f64 {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let mut yaw = vel_n.y.atan2(vel_n.x);
    for _ in 0..4 {
        let (sy, cy) = yaw.sin_cos();
        let u1 = cy * vel_n.x + sy * vel_n.y;
        let u2 = -sy * vel_n.x + cy * vel_n.y;
        let f = cr * u2 + sr * (sp * u1 + cp * vel_n.z);
        let df = -cr * u1 + sr * sp * u2;
        if df.abs() < 1e-9 {
            break;
        }
        yaw -= f / df;
    }
    uavnav_core::rotation::wrap_pi(yaw)
}

/// Largest attitude σ at which a settled alignment ends, rad: the linearisation of the
/// pseudo-attitude chain (eq. 34) and of eq. (D1) holds there.
pub const SETTLED_MAX_SIGMA_RAD: f64 = 0.0873;
/// Span over which the attitude variance must stop shrinking, ns.
pub const SETTLE_SPAN_NS: i64 = 10_000_000_000;
/// Share of the variance a settled alignment may still lose over [`SETTLE_SPAN_NS`].
pub const SETTLED_SHRINK: f64 = 0.2;

/// Whether the alignment has settled: the largest attitude variance `var_rad2` is below
/// [`SETTLED_MAX_SIGMA_RAD`]² and shrank by less than [`SETTLED_SHRINK`] over the last
/// [`SETTLE_SPAN_NS`]. An absolute threshold alone (`paper_video_start_sigma_rad`, 0.5°) is
/// never reached with a consumer-grade IMU, whose process noise holds roll and pitch at a
/// degree or two: its video chain never started (a simulated fixed wing, consumer IMU, camera:
/// no rotation fused, yaw 40° off after the 120 s outage). Only the video waits for it: the
/// alignment's GNSS aiding (the course, while no video chain runs the heading) goes on, since
/// without it such an IMU's heading drifts freely (17° → 61° RMSE without video when the
/// settled alignment also ended it). `check` keeps the span's start.
pub(super) fn alignment_settled(check: &mut Option<(i64, f64)>, t_ns: i64, var_rad2: f64) -> bool {
    if var_rad2 > SETTLED_MAX_SIGMA_RAD.powi(2) {
        *check = None;
        return false;
    }
    match *check {
        Some((t0, v0)) if t_ns - t0 >= SETTLE_SPAN_NS => {
            if var_rad2 >= (1.0 - SETTLED_SHRINK) * v0 {
                return true;
            }
            *check = Some((t_ns, var_rad2));
            false
        }
        Some(_) => false,
        None => {
            *check = Some((t_ns, var_rad2));
            false
        }
    }
}
