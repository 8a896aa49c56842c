//! Profile `paper`, OUR ADDITION: a GNSS outage without video. The paper bridges outages with
//! VIDEO-IMU(2) and the camera; without a camera its attitude filter only integrates the gyro,
//! and nothing holds roll and pitch: on the shared fixed wing (10 Hz IMU log) a 120 s outage took
//! them 34–36° off. So, as `eskf::outage` does for that profile:
//!
//! * **start**: no fix for [`crate::EstimatorParams::aid_timeout_ns`], no video running, and the
//!   roll or pitch σ past `dead_reckoning_max_tilt_sigma_rad` (an IMU good enough to coast is
//!   left to); the current tilt window, which began at the last fix's velocity, is dropped;
//! * **continue**: the tilt windows of [`super::gnss_tilt`] against a velocity held at zero
//!   within `paper_noaid_speed_sigma_mps`, as without GNSS ([`super::gnss_tilt::GnssTilt::at_hold`]);
//! * **stop** at the next fix: the held window is dropped so that the fixes' windows start
//!   afresh from a measured velocity. GPS-IMU and VIDEO-IMU(2) run through it as before.
//!
//! The reported yaw σ grows with the angle turned about the vertical while neither a fix nor
//! video observes the heading (`gyro_scale_sigma` per radian, as in `eskf::outage`: the gyro's
//! scale-factor error; only the σ reported).

use super::*;

/// Adds the angle turned about the vertical over `dt_s` (`gyro_n`, the rate in the navigation
/// frame) to `turn_rad`, or zeroes it when the heading is `observed`.
pub(super) fn track_unaided_turn(
    turn_rad: &mut f64,
    observed: bool,
    gyro_n: &Vector3<f64>,
    dt_s: f64,
) {
    if observed {
        *turn_rad = 0.0;
    } else if dt_s.is_finite() && dt_s > 0.0 {
        *turn_rad += gyro_n.z.abs() * dt_s;
    }
}

impl PaperFilter {
    /// One IMU interval in an outage (`t_ns`, the interval's mean specific force already in the
    /// tilt window): starts or continues the held-velocity tilt windows (module doc).
    pub(super) fn hold_tilt_in_outage(&mut self, t_ns: i64, frame: &LocalFrame) {
        let Some(att) = self.att.as_mut() else { return };
        let unaided = self
            .last_fix
            .is_some_and(|(f, _)| t_ns - f.t_ns > self.params.aid_timeout_ns);
        let video = att.video_active();
        if !unaided || video || !self.params.paper_gnss_tilt {
            self.end_outage_tilt_hold();
            return;
        }
        if !self.outage_tilt_hold {
            let p = att.p_euler();
            let tilt_sigma = p[(0, 0)].max(p[(1, 1)]).max(0.0).sqrt();
            if tilt_sigma <= self.params.dead_reckoning_max_tilt_sigma_rad {
                return;
            }
            self.gnss_tilt.drop_window();
            self.outage_tilt_hold = true;
        }
        let hold = gnss_tilt::TiltFix {
            t_ns,
            vel_ned_mps: Vector3::zeros(),
            sigma_vel_mps: self.params.paper_noaid_speed_sigma_mps,
            g_ned: frame.gravity_ned(&Vector3::zeros()),
            w_ie: self.w_ie,
        };
        self.gnss_tilt
            .at_hold(&hold, att, false, self.params.gate_sigma);
    }

    /// Ends the outage's tilt hold, if one runs (module doc).
    pub(super) fn end_outage_tilt_hold(&mut self) {
        if self.outage_tilt_hold {
            self.gnss_tilt.drop_window();
            self.outage_tilt_hold = false;
        }
    }
}
