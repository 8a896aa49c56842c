//! Initialisation without operator input: level from averaged accelerometers (compensated by the
//! GNSS-derived acceleration, so it also works in a turn), heading from the GNSS course when
//! moving, position and velocity from the fix through the lever arm.
//!
//! On the ground (too slow for a course) the filter starts with yaw 0 and a wide yaw σ, and the
//! heading is re-aligned from the course as soon as the vehicle moves ([`yaw_from_course`]).

use std::collections::VecDeque;

use nalgebra::{UnitQuaternion, Vector3};

use crate::aid_sources::gnss_pos::GnssMeas;
use crate::params::EstimatorParams;
use crate::state::{Cov, IBA, IBG, IGM, IP, ITH, IV, Nominal};

/// Yaw σ while the heading is unknown, rad: that of a heading uniform round the circle (π/√3),
/// so the stated σ covers the truth whatever it is. The filter does not correct its yaw while
/// unaligned (the linearisation is meaningless that far out); the magnetometer or the yaw
/// estimator aligns it.
pub const UNALIGNED_YAW_SIGMA_RAD: f64 = std::f64::consts::PI / 1.732_050_807_568_877_2;

/// Collects what the initial alignment needs.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Initialiser {
    /// (t_ns, gyro, accel) of recent IMU samples at the fusion horizon.
    samples: VecDeque<(i64, Vector3<f64>, Vector3<f64>)>,
    /// The previous GNSS fix (for the acceleration).
    prev_fix: Option<GnssMeas>,
}

/// The initial state and covariance, and whether the heading came from a course.
#[derive(Debug, Clone, PartialEq)]
pub struct InitResult {
    /// Nominal state.
    pub x: Nominal,
    /// Covariance.
    pub p: Cov,
    /// Heading aligned from the GNSS course.
    pub yaw_aligned: bool,
}

impl Initialiser {
    /// Adds an IMU sample seen at the horizon, keeping the levelling window.
    pub fn add_imu(&mut self, t_ns: i64, gyro: &Vector3<f64>, accel: &Vector3<f64>, window_s: f64) {
        self.samples.push_back((t_ns, *gyro, *accel));
        let keep_ns = (window_s * 1e9) as i64;
        while self.samples.front().is_some_and(|s| t_ns - s.0 > keep_ns) {
            self.samples.pop_front();
        }
    }

    /// Tries to initialise at a GNSS fix. `g_n` is gravity at the fix.
    pub fn try_init(
        &mut self,
        fix: &GnssMeas,
        lever_b: &Vector3<f64>,
        g_n: &Vector3<f64>,
        params: &EstimatorParams,
        gm_sigma_m: [f64; 3],
    ) -> Option<InitResult> {
        let prev = self.prev_fix.replace(*fix);
        let (v_fix, v_sigma) = init_velocity(fix, prev.as_ref())?;
        let (t_first, t_last) = (self.samples.front()?.0, self.samples.back()?.0);
        if ((t_last - t_first) as f64) < 0.8 * params.init_level_window_s * 1e9 {
            return None;
        }
        let n = self.samples.len() as f64;
        let f_b = self.samples.iter().map(|s| s.2).sum::<Vector3<f64>>() / n;
        let w_b = self.samples.iter().map(|s| s.1).sum::<Vector3<f64>>() / n;
        // Kinematic acceleration from consecutive GNSS velocities (zero without a previous fix).
        let a_n = match prev {
            Some(GnssMeas {
                t_ns,
                vel_ned_mps: Some(v_prev),
                ..
            }) if fix.t_ns > t_ns && fix.t_ns - t_ns < 2_000_000_000 => {
                (v_fix - v_prev) / ((fix.t_ns - t_ns) as f64 * 1e-9)
            }
            _ => Vector3::zeros(),
        };
        let speed_h = v_fix.xy().norm();
        // A course is a heading only when the speed stands well clear of its own noise.
        let yaw_aligned =
            params.course_heading && speed_h >= params.init_min_speed_mps.max(3.0 * v_sigma.x);
        let yaw = if yaw_aligned {
            v_fix.y.atan2(v_fix.x)
        } else {
            0.0
        };
        let q = attitude_from_gravity(&f_b, &(g_n - a_n), yaw)?;
        let c = q.to_rotation_matrix();
        let p = fix.pos_ned_m - c * lever_b;
        let v = v_fix - c * w_b.cross(lever_b);
        let x = Nominal {
            t_ns: fix.t_ns,
            p,
            v,
            q,
            bg: Vector3::zeros(),
            ba: Vector3::zeros(),
            gm: Vector3::zeros(),
            clone: None,
        };
        let yaw_sigma = if yaw_aligned {
            params.init_yaw_sigma_rad
        } else {
            UNALIGNED_YAW_SIGMA_RAD
        };
        let mut cov = Cov::zeros();
        let pos_var = [
            fix.sigma_h_m.powi(2),
            fix.sigma_h_m.powi(2),
            fix.sigma_v_m.powi(2),
        ];
        for k in 0..3 {
            cov[(IP + k, IP + k)] = pos_var[k].max(gm_sigma_m[k].powi(2));
            cov[(IGM + k, IGM + k)] = gm_sigma_m[k].powi(2);
            // p̂ = z − C r ⇒ δp = −(e_gnss + n): position and GNSS error start anti-correlated.
            cov[(IP + k, IGM + k)] = -gm_sigma_m[k].powi(2);
            cov[(IGM + k, IP + k)] = -gm_sigma_m[k].powi(2);
            cov[(IV + k, IV + k)] = v_sigma[k].powi(2);
            cov[(IBG + k, IBG + k)] = params.init_gyro_bias_sigma_radps.powi(2);
            cov[(IBA + k, IBA + k)] = params.init_accel_bias_sigma_mps2.powi(2);
        }
        set_attitude_cov(&mut cov, params.init_tilt_sigma_rad, yaw_sigma);
        Some(InitResult {
            x,
            p: cov,
            yaw_aligned,
        })
    }
}

/// σ of the velocity at a start without GNSS, m/s: the vehicle is taken to be about still
/// (a hover or the ground); the position hold then keeps it near zero whatever it does.
pub const GNSSLESS_START_VEL_SIGMA_MPS: f64 = 1.0;

/// Largest mean gyro over the levelling window taken as the gyro's bias at a start without
/// GNSS, rad/s (5.7 °/s): a vehicle starts its stream at rest, on the ground or held, and its
/// motors' vibration averages out of the mean while a MEMS turn-on bias does not (EuRoC's
/// ADIS16448 on an idling MAV: 0.08 rad/s about one axis, spread 0.06 rad/s per sample);
/// anything faster is a turn.
pub const START_BIAS_MAX_RADPS: f64 = 0.1;

/// Largest mean gyro taken as its bias when the accelerometer disproves the rotation
/// ([`rotation_disproved`]), rad/s (57 °/s): beyond any MEMS gyro's turn-on bias.
pub const START_BIAS_PROVEN_MAX_RADPS: f64 = 1.0;

/// Largest spread of the gyro samples over the window, as a share of the rate across the
/// specific force, for [`rotation_disproved`] (the bench logs: 0.1).
pub const MAX_BIAS_RATE_SPREAD: f64 = 0.15;

/// Whether the accelerometer shows that the mean gyro over the levelling window is not a
/// rotation, so that it is the gyro's bias however large (eq. I2, ours). A rotation at `ω`
/// turns the specific force's direction in the body at `|ω_⊥|`, the rate's component across it;
/// between the means of the window's first and last thirds, `Δt` apart, it would turn by
/// `|ω_⊥| Δt`. Disproved when it turned by less than half of that, and that is at least three
/// times what the accelerometer's noise can hide (`spread / g · √(2/k)`, `k` samples a third).
/// The component along the specific force cannot be checked that way (a yaw turn does not move
/// gravity in the body), so it must stay under [`START_BIAS_MAX_RADPS`]; and the specific force
/// must be within 10 % of gravity: a coordinated turn also holds the specific force still in
/// the body, but its rate lies mostly along it unless banked beyond 45° (1.41 g). A multirotor's
/// specific force stays along its thrust axis through any manoeuvre, so the rate must also be
/// steady (spread at most [`MAX_BIAS_RATE_SPREAD`] of it): only used at a start without GNSS,
/// where the vehicle is taken to be at rest; the GNSS start learns the bias from the velocity
/// (applied there too, it took copter_218's pitching at its first fix for a bias).
/// Public ArduPilot logs `7-9-2014/6` and `/7` start level and still on a bench (the specific
/// force steady to 0.2 m/s²) with the gyro reading −0.15, −0.15, −0.03 rad/s, left uncalibrated:
/// taken as a turn, it rolled the estimate through 180° in 18 s at a stated tilt σ of 3–7°.
pub fn rotation_disproved<'a>(
    samples: impl ExactSizeIterator<Item = &'a (i64, Vector3<f64>, Vector3<f64>)> + Clone,
    f_b: &Vector3<f64>,
    w_b: &Vector3<f64>,
    g: f64,
    spread: f64,
    gyro_spread: f64,
) -> bool {
    let n = samples.len();
    let k = n / 3;
    let f_norm = f_b.norm();
    if k < 2 || w_b.norm() > START_BIAS_PROVEN_MAX_RADPS || (f_norm - g).abs() > 0.1 * g {
        return false;
    }
    let f_hat = f_b / f_norm;
    let w_along = w_b.dot(&f_hat);
    if w_along.abs() > START_BIAS_MAX_RADPS {
        return false;
    }
    let w_across = (w_b - f_hat * w_along).norm();
    // A flying multirotor's specific force stays along its thrust axis whatever it turns, so a
    // steady specific force proves nothing unless the rate is steady too: a bias is constant,
    // a manoeuvre is not (copter_218 at its first fix: 0.47 rad/s of pitch, spread 0.12).
    if gyro_spread > MAX_BIAS_RATE_SPREAD * w_across {
        return false;
    }
    let Some(&(t0, _, _)) = samples.clone().next() else {
        return false;
    };
    let third = |it: &mut dyn Iterator<Item = &'a (i64, Vector3<f64>, Vector3<f64>)>| {
        let (mut t, mut f) = (0.0, Vector3::zeros());
        for s in it.take(k) {
            t += (s.0 - t0) as f64 * 1e-9;
            f += s.2;
        }
        (t / k as f64, f / k as f64)
    };
    let (t_a, f_a) = third(&mut samples.clone());
    let (t_b, f_b_last) = third(&mut samples.skip(n - k));
    let would_rad = w_across * (t_b - t_a);
    let noise_rad = spread / g * (2.0 / k as f64).sqrt();
    would_rad >= 3.0 * noise_rad && f_a.angle(&f_b_last) < 0.5 * would_rad
}

/// Makes `frame` the provisional frame of a filter that does not know where it is, when it has
/// none: origin at 45° N, 0° E, 0 m (only its normal gravity is used), the Earth rate `w_ie` left
/// out, `provisional` set. Returns the frame in use.
pub fn ensure_frame<'a>(
    frame: &'a mut Option<uavnav_core::LocalFrame>,
    provisional: &mut bool,
    w_ie: &mut Vector3<f64>,
) -> &'a uavnav_core::LocalFrame {
    frame.get_or_insert_with(|| {
        *provisional = true;
        *w_ie = Vector3::zeros();
        uavnav_core::LocalFrame::new(uavnav_core::Lla::from_deg(45.0, 0.0, 0.0))
    })
}

/// Whether a filter whose first IMU sample came at `first_t_ns` starts without GNSS at `t_ns`:
/// after `start_without_gnss_after_s`, at once for a vehicle configured without a receiver.
/// Written so that a NaN wait never starts (and an infinite one never does either).
pub fn start_without_gnss_due(
    first_t_ns: i64,
    t_ns: i64,
    has_gnss: bool,
    params: &EstimatorParams,
) -> bool {
    let wait_s = if has_gnss {
        params.start_without_gnss_after_s
    } else {
        0.0
    };
    let waited_s = (t_ns - first_t_ns) as f64 * 1e-9;
    waited_s.partial_cmp(&wait_s).is_some_and(|o| o.is_ge())
}

/// The gyro's bias from a levelling window of `(t_ns, gyro, accel)` samples taken at rest (a
/// start without GNSS): the mean gyro, when it is small ([`START_BIAS_MAX_RADPS`]) or the
/// accelerometer disproves the rotation ([`rotation_disproved`]), with the mean's own noise per
/// axis (the samples' spread over `√(3n)`); `None` for a turn. `f_b` is the window's mean
/// specific force, `g` gravity's magnitude and `spread` the specific force's RMS spread.
pub fn gyro_bias_at_rest<'a>(
    samples: impl ExactSizeIterator<Item = &'a (i64, Vector3<f64>, Vector3<f64>)> + Clone,
    f_b: &Vector3<f64>,
    g: f64,
    spread: f64,
) -> Option<(Vector3<f64>, f64)> {
    let n = samples.len() as f64;
    let (w_b, gyro_spread) = mean_and_spread(samples.clone().map(|s| s.1));
    let still = w_b.norm() <= START_BIAS_MAX_RADPS
        || rotation_disproved(samples, f_b, &w_b, g, spread, gyro_spread);
    still.then(|| (w_b, gyro_spread / (3.0 * n).sqrt()))
}

impl Initialiser {
    /// Starts without a GNSS fix, at `p_ned` (the hold point) with zero velocity, levelled on the
    /// mean specific force taken as gravity alone (no GNSS to measure an acceleration): a tilt σ
    /// of `init_tilt_sigma_rad` plus what the window's departure from 1 g and its spread allow
    /// (a vehicle already manoeuvring at the start). Heading unknown. `None` until the levelling
    /// window is full, or in free fall.
    pub fn try_init_at_rest(
        &self,
        t_ns: i64,
        p_ned: &Vector3<f64>,
        g_n: &Vector3<f64>,
        params: &EstimatorParams,
        pos_sigma_m: f64,
    ) -> Option<InitResult> {
        let (t_first, t_last) = (self.samples.front()?.0, self.samples.back()?.0);
        if ((t_last - t_first) as f64) < 0.8 * params.init_level_window_s * 1e9 {
            return None;
        }
        let (f_b, spread) = mean_and_spread(self.samples.iter().map(|s| s.2));
        let q = attitude_from_gravity(&f_b, g_n, 0.0)?;
        let g = g_n.norm();
        let unlevel = (((f_b.norm() - g).abs() + spread) / g).min(1.0).asin();
        // Standing still, the mean gyro is its bias (the Earth rate, 7e-5 rad/s, left in): with
        // GNSS the bias is learnt from the velocity in seconds, without it only slowly through
        // the tilt, and a MEMS turn-on bias of a few °/s would tilt the attitude by tens of
        // degrees first (EuRoC's IMU: 0.08 rad/s about one axis).
        let still = gyro_bias_at_rest(self.samples.iter(), &f_b, g, spread);
        let bias_sigma = params.init_gyro_bias_sigma_radps + still.map_or(0.0, |b| b.1);
        let mut cov = Cov::zeros();
        for k in 0..3 {
            cov[(IP + k, IP + k)] = pos_sigma_m.powi(2);
            cov[(IV + k, IV + k)] = GNSSLESS_START_VEL_SIGMA_MPS.powi(2);
            cov[(IBG + k, IBG + k)] = bias_sigma.powi(2);
            cov[(IBA + k, IBA + k)] = params.init_accel_bias_sigma_mps2.powi(2);
        }
        set_attitude_cov(
            &mut cov,
            params.init_tilt_sigma_rad + unlevel,
            UNALIGNED_YAW_SIGMA_RAD,
        );
        let x = Nominal {
            t_ns,
            p: *p_ned,
            v: Vector3::zeros(),
            q,
            bg: still.map_or_else(Vector3::zeros, |b| b.0),
            ba: Vector3::zeros(),
            gm: Vector3::zeros(),
            clone: None,
        };
        Some(InitResult {
            x,
            p: cov,
            yaw_aligned: false,
        })
    }
}

/// The mean of some vectors and their RMS distance from it (zeros for none).
pub fn mean_and_spread(v: impl Iterator<Item = Vector3<f64>> + Clone) -> (Vector3<f64>, f64) {
    let n = v.clone().count().max(1) as f64;
    let mean = v.clone().sum::<Vector3<f64>>() / n;
    let spread = (v.map(|x| (x - mean).norm_squared()).sum::<f64>() / n).sqrt();
    (mean, spread)
}

/// σ of an unknown vertical velocity at the alignment, m/s (a receiver that gives ground speed and
/// course only): a climb or descent of a small UAV.
pub const UNKNOWN_VERTICAL_VELOCITY_SIGMA_MPS: f64 = 3.0;

/// The velocity the alignment starts from and its 1-σ per axis (NED), m/s:
/// * the receiver's 3-D velocity, σ twice its stated one (it is one sample);
/// * its horizontal velocity only (ground speed and course, MAVLink `GPS_RAW_INT`): vertical 0
///   with [`UNKNOWN_VERTICAL_VELOCITY_SIGMA_MPS`];
/// * no velocity at all (a position-only source, ROS `NavSatFix`): the difference of this fix's
///   position and the previous one's over the interval (0.1–2 s), σ from their position σ.
///
/// `None` when none applies (the first position-only fix): the alignment waits for the next.
fn init_velocity(fix: &GnssMeas, prev: Option<&GnssMeas>) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let s = fix.sigma_vel_mps.max(0.01) * 2.0;
    if let Some(v) = fix.vel_ned_mps {
        return Some((v, Vector3::repeat(s)));
    }
    if let Some(h) = fix.vel_h_mps {
        return Some((
            Vector3::new(h.x, h.y, 0.0),
            Vector3::new(s, s, UNKNOWN_VERTICAL_VELOCITY_SIGMA_MPS),
        ));
    }
    let p = prev?;
    let dt_s = (fix.t_ns - p.t_ns) as f64 * 1e-9;
    if !(0.1..=2.0).contains(&dt_s) {
        return None;
    }
    let sh = fix.sigma_h_m.hypot(p.sigma_h_m) / dt_s;
    let sv = fix.sigma_v_m.hypot(p.sigma_v_m) / dt_s;
    Some((
        (fix.pos_ned_m - p.pos_ned_m) / dt_s,
        Vector3::new(sh, sh, sv),
    ))
}

/// Sets the attitude block to diag(tilt², tilt², yaw²) and removes its correlations.
pub fn set_attitude_cov(cov: &mut Cov, tilt_sigma: f64, yaw_sigma: f64) {
    for k in 0..3 {
        cov.row_mut(ITH + k).fill(0.0);
        cov.column_mut(ITH + k).fill(0.0);
    }
    cov[(ITH, ITH)] = tilt_sigma.powi(2);
    cov[(ITH + 1, ITH + 1)] = tilt_sigma.powi(2);
    cov[(ITH + 2, ITH + 2)] = yaw_sigma.powi(2);
}

/// `nav_from_body` such that the body specific force `f_b` maps onto `−g_app_n` (apparent gravity
/// = gravity − kinematic acceleration) and the heading is `yaw`. `None` in free fall.
pub fn attitude_from_gravity(
    f_b: &Vector3<f64>,
    g_app_n: &Vector3<f64>,
    yaw: f64,
) -> Option<UnitQuaternion<f64>> {
    if f_b.norm() < 1.0 || g_app_n.norm() < 1.0 {
        return None;
    }
    let roll = (-f_b.y).atan2(-f_b.z);
    let pitch = f_b.x.atan2((f_b.y * f_b.y + f_b.z * f_b.z).sqrt());
    let level = UnitQuaternion::from_euler_angles(roll, pitch, 0.0);
    let heading = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
    let tilt = UnitQuaternion::rotation_between(&Vector3::z(), &g_app_n.normalize())
        .unwrap_or_else(UnitQuaternion::identity);
    Some(tilt * heading * level)
}

/// Re-aligns the heading to the GNSS course keeping roll and pitch (only with
/// `EstimatorParams::course_heading`); resets the attitude covariance.
pub fn yaw_from_course(
    x: &mut Nominal,
    cov: &mut Cov,
    vel_ned: &Vector3<f64>,
    params: &EstimatorParams,
) {
    set_yaw(
        x,
        cov,
        vel_ned.y.atan2(vel_ned.x),
        params.init_yaw_sigma_rad,
    );
}

/// Sets the heading keeping roll and pitch, with a fresh, decorrelated attitude covariance.
pub fn set_yaw(x: &mut Nominal, cov: &mut Cov, yaw: f64, yaw_sigma_rad: f64) {
    let (roll, pitch, _) = x.q.euler_angles();
    x.q = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
    let tilt = cov[(ITH, ITH)].max(cov[(ITH + 1, ITH + 1)]).sqrt();
    set_attitude_cov(cov, tilt, yaw_sigma_rad);
}

/// Keeps the heading unknown: no correlation with any other state and the variance of a heading
/// uniform round the circle (the yaw is not estimated until aligned).
pub fn hold_yaw_unknown(cov: &mut Cov) {
    crate::state::set_uncorrelated(cov, ITH + 2, UNALIGNED_YAW_SIGMA_RAD.powi(2));
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    fn level_initialiser(t_ns: i64) -> Initialiser {
        let mut init = Initialiser::default();
        for k in 0..=100 {
            init.add_imu(
                t_ns - 1_000_000_000 + k * 10_000_000,
                &Vector3::zeros(),
                &Vector3::new(0.0, 0.0, -9.806_65),
                1.0,
            );
        }
        init
    }

    fn meas(t_ns: i64, north_m: f64) -> GnssMeas {
        GnssMeas {
            t_ns,
            pos_ned_m: Vector3::new(north_m, 0.0, 0.0),
            vel_ned_mps: None,
            vel_h_mps: None,
            sigma_h_m: 1.0,
            sigma_v_m: 1.5,
            sigma_vel_mps: f64::INFINITY,
        }
    }

    fn try_at(init: &mut Initialiser, m: &GnssMeas) -> Option<InitResult> {
        let g = Vector3::new(0.0, 0.0, 9.806_65);
        init.try_init(
            m,
            &Vector3::zeros(),
            &g,
            &EstimatorParams::default(),
            [1.0; 3],
        )
    }

    #[test]
    fn ground_speed_and_course_are_enough_to_start() {
        let t = 10_000_000_000;
        let mut init = level_initialiser(t);
        let m = GnssMeas {
            vel_h_mps: Some(Vector2::new(3.0, 4.0)),
            sigma_vel_mps: 0.3,
            ..meas(t, 0.0)
        };
        let r = try_at(&mut init, &m).expect("started");
        assert!((r.x.v - Vector3::new(3.0, 4.0, 0.0)).norm() < 1e-9);
        assert!((r.p[(IV + 2, IV + 2)].sqrt() - UNKNOWN_VERTICAL_VELOCITY_SIGMA_MPS).abs() < 1e-12);
        assert!((r.p[(IV, IV)].sqrt() - 0.6).abs() < 1e-12);
    }

    #[test]
    fn a_position_only_source_starts_from_two_fixes() {
        let t = 10_000_000_000;
        let mut init = level_initialiser(t);
        assert!(
            try_at(&mut init, &meas(t, 0.0)).is_none(),
            "one fix has no velocity"
        );
        let mut init = level_initialiser(t + 500_000_000);
        init.prev_fix = Some(meas(t, 0.0));
        let r = try_at(&mut init, &meas(t + 500_000_000, 5.0)).expect("started");
        assert!((r.x.v.x - 10.0).abs() < 1e-9, "{}", r.x.v);
        // σ from the two positions over 0.5 s: √2 · 1 m / 0.5 s.
        assert!((r.p[(IV, IV)].sqrt() - 2f64.sqrt() * 2.0).abs() < 1e-9);
    }

    /// 0.5 s at 50 Hz: `rate` from the gyro, and the specific force turning at `turn` (the
    /// rotation that really happens) from level.
    fn window(rate: Vector3<f64>, turn: Vector3<f64>) -> Vec<(i64, Vector3<f64>, Vector3<f64>)> {
        (0..25)
            .map(|i| {
                let t = i as f64 * 0.02;
                // Deterministic "noise" of ±0.05 m/s².
                let wobble = Vector3::new(0.05, -0.05, 0.05) * if i % 2 == 0 { 1.0 } else { -1.0 };
                let f = UnitQuaternion::from_scaled_axis(-turn * t) * Vector3::new(0.0, 0.0, -9.81);
                (i * 20_000_000, rate, f + wobble)
            })
            .collect()
    }

    fn disproved(w: &[(i64, Vector3<f64>, Vector3<f64>)]) -> bool {
        let (f, spread) = mean_and_spread(w.iter().map(|s| s.2));
        let (g, g_spread) = mean_and_spread(w.iter().map(|s| s.1));
        rotation_disproved(w.iter(), &f, &g, 9.81, spread, g_spread)
    }

    #[test]
    fn a_large_gyro_bias_is_told_from_a_turn_by_the_accelerometer() {
        let bias = Vector3::new(-0.154, -0.154, -0.029);
        // Still on a bench: the gyro's reading is its bias.
        assert!(disproved(&window(bias, Vector3::zeros())));
        // The same rate, really turning: gravity moves in the body.
        assert!(!disproved(&window(bias, bias)));
        // Too much about gravity's axis, which the accelerometer cannot check.
        assert!(!disproved(&window(
            Vector3::new(0.0, 0.0, 0.2),
            Vector3::zeros()
        )));
        // Too small a rate to show against the accelerometer's noise.
        assert!(!disproved(&window(
            Vector3::new(0.01, 0.0, 0.0),
            Vector3::zeros()
        )));
        // A multirotor pitching about (0.47 rad/s on average, swinging by ±0.15) with its
        // specific force steady on the thrust axis: the rate is not steady enough to be a bias.
        let mut pitching = window(Vector3::zeros(), Vector3::zeros());
        for (i, s) in pitching.iter_mut().enumerate() {
            s.1 = Vector3::new(0.0, 0.47 + if i % 2 == 0 { 0.15 } else { -0.15 }, 0.0);
        }
        assert!(!disproved(&pitching));
    }
}
