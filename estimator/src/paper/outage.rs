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
//! scale-factor error). At the next fix the filter's yaw variance takes that term too
//! ([`PaperFilter::widen_yaw_for_unaided_turn`]), so that the course or the yaw bank can pull
//! back a heading that drifted unobserved.

use super::*;

/// Yaw σ past which the heading counts as lost at the end of an outage, rad: the alignment's
/// settled bound ([`alignment::SETTLED_MAX_SIGMA_RAD`], 5°), beyond which its linearisations
/// (and the GNSS acceleration's heading correction) are no longer trusted.
const LOST_HEADING_SIGMA_RAD: f64 = alignment::SETTLED_MAX_SIGMA_RAD;

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

    /// At the first fix after an outage: the yaw variance takes the scale-factor term the
    /// reported σ carried (module doc), so that the course or the yaw bank can correct a heading
    /// that drifted unobserved. Without it the filter's own σ, ~11° after 120 s of circling on
    /// the shared fixed wing while the heading was 110° off, held the bank's reset back for
    /// 15 s and its heading came back over a minute, with roll and pitch 4–7° off meanwhile.
    pub(super) fn widen_yaw_for_unaided_turn(&mut self) {
        let turn_rad = std::mem::take(&mut self.unaided_turn_rad);
        let Some(att) = self.att.as_mut() else { return };
        att.widen_yaw((self.params.gyro_scale_sigma * turn_rad).powi(2));
        if turn_rad == 0.0
            || att.video_active()
            || att.p_euler()[(2, 2)] <= LOST_HEADING_SIGMA_RAD.powi(2)
        {
            return;
        }
        if self.course_heading {
            // The alignment's course pseudo-measurement takes the heading again (the GNSS
            // acceleration of `gnss_tilt` corrects only a small yaw error).
            self.aligned = false;
        } else {
            // A 3σ contradiction with a filter this wide never comes: the bank (left running;
            // restarting it from scratch never converged in a circle) hands its heading over
            // at the first fix where it can tell it.
            self.heading.restart_search();
        }
    }

    /// Ends the outage's tilt hold, if one runs (module doc).
    pub(super) fn end_outage_tilt_hold(&mut self) {
        if self.outage_tilt_hold {
            self.gnss_tilt.drop_window();
            self.outage_tilt_hold = false;
        }
    }
}
