//! A GNSS outage in flight (`eskf`): dead reckoning has a limit.
//!
//! Without a position or velocity source the inertial solution drifts without bound, and with it
//! the tilt, which only the velocity holds: on the shared fixed wing (10 Hz IMU) a 120 s outage
//! dead-reckoned took the position 2.7 km off in 60 s and the roll and pitch 20° off, and the
//! filter then diverged. So, as PX4 EKF2 does after `EKF2_NOAID_TOUT` (there after a fixed 5 s):
//!
//! * **start**: once no horizontal GNSS position or velocity (nor vision translation) has been
//!   fused for `aid_timeout_ns`, the horizontal position σ has passed the hold's own
//!   (`noaid_pos_sigma_m`: the filter no longer knows where it is any better than "about here")
//!   and the tilt σ has passed `dead_reckoning_max_tilt_sigma_rad` (the tilt is slipping: an IMU
//!   good enough to coast through the outage is left to), the filter holds its position
//!   ([`crate::aid_sources::position_hold`], "within `noaid_pos_sigma_m` of where it stopped",
//!   down-weighted as the vehicle moves on) and reports [`crate::Mode::AttitudeOnly`], the mode
//!   of a filter started without GNSS. The velocity is decorrelated from the rest and given at
//!   least its own size as σ: the hold treats where the vehicle goes next as unknown motion, and
//!   a velocity still claimed to the dead-reckoning σ would make the hold's pull read as a tilt;
//! * **continue**: the hold at every [`crate::aid_sources::position_hold::HOLD_PERIOD_NS`]; the
//!   barometer holds the height, the compass the heading, as before;
//! * **stop** at the next fix: the position and velocity are decorrelated from the rest and
//!   widened to cover their innovations, so that fix sets them (counted in the GNSS sources'
//!   `resets`), and the attitude, biases and heading carry on. Unlike the start without GNSS,
//!   nothing is rebuilt: the filter was right about everything the hold kept.
//!
//! **An IMU gap** of 0.5–5 s (a dropped link, a stalled logger) is the same kind of blind spell,
//! shorter: [`Eskf::widen_for_gap`] (eq. G1) widens what integrating across it cannot know, and
//! the next fix widens the position and velocity to its innovation ([`Eskf::widen_to_fix`]), as
//! at the end of an outage.
//!
//! **The heading while nothing observes it.** A gyro's scale-factor error (`gyro_scale_sigma`)
//! is absorbed by the bias state and the heading corrections at the turn rate flown while GNSS
//! velocity, a compass or vision observes the heading; without them it turns into yaw error in
//! proportion to the angle turned. On plane_E, circling at 14°/s through a 120 s outage, the
//! filter's yaw left the autopilot's by 20° (0.9°/s when the hold does not correct it) while its
//! covariance said 5.6°. So the angle turned about the vertical since the heading was last
//! observed is counted, and `gyro_scale_sigma` times it is added to the reported yaw σ (in
//! quadrature; only the reported σ: the filter's own covariance, inflated the same way, let
//! the hold pull the yaw and tilt harder, roll / pitch RMSE 4.7–6.2° → 6.6–7.4°).

use nalgebra::Vector3;
use uavnav_core::ImuSample;

use super::Eskf;
use crate::aid_sources::gnss_pos::GnssMeas;
use crate::aid_sources::position_hold::HoldState;
use crate::prediction::gap_variances;
use crate::state::{Cov, IP, ITH, IV, N};

impl Eskf {
    /// Counts the angle turned about the vertical at the horizon, back to zero whenever
    /// something observes the heading (see the module doc).
    pub(super) fn track_unaided_turn(&mut self, gyro_b: &Vector3<f64>, dt_s: f64) {
        let Some(x) = self.x.as_ref() else { return };
        let to = self.params.aid_timeout_ns;
        let observed = self.gnss_vel.diag.active(x.t_ns, to)
            || self.mag.diag.active(x.t_ns, to)
            || self.vision.rot.active(x.t_ns, to);
        if observed || !self.yaw_aligned {
            self.unaided_turn_rad = 0.0;
        } else if dt_s.is_finite() && dt_s > 0.0 {
            self.unaided_turn_rad += (x.q * gyro_b).z.abs() * dt_s;
        }
    }

    /// Whether a fix at `t_ns` comes after an outage: no GNSS position fused for
    /// `aid_timeout_ns` (a refused fix then resets the position at once, see `fuse_gnss`).
    pub(super) fn after_outage(&self, t_ns: i64) -> bool {
        let last = self.gnss_pos.diag.last_fused_t_ns;
        last != i64::MIN && t_ns - last > self.params.aid_timeout_ns
    }

    /// The yaw σ the unobserved turns add, rad.
    pub(super) fn unaided_turn_sigma_rad(&self) -> f64 {
        self.params.gyro_scale_sigma * self.unaided_turn_rad
    }
    /// Whether the hold of an outage runs (not that of a filter started without GNSS).
    pub(super) fn outage_hold(&self) -> bool {
        !self.gnssless && self.hold.state == HoldState::Active
    }

    /// At the horizon `t_ns`: starts the hold once dead reckoning has gone as far as it can
    /// (see the module doc).
    pub(super) fn limit_dead_reckoning(&mut self, t_ns: i64) {
        let Some(x) = self.x else { return };
        let max_tilt_sigma = self.params.dead_reckoning_max_tilt_sigma_rad;
        if self.gnssless || self.hold.state == HoldState::Active {
            return;
        }
        let to = self.params.aid_timeout_ns;
        let aided = self.gnss_pos.diag.active(t_ns, to)
            || self.gnss_vel.diag.active(t_ns, to)
            || self.vision.trans.active(t_ns, to);
        // A filter that never fused a position has not started dead reckoning from one.
        if aided || self.gnss_pos.diag.last_fused_t_ns == i64::MIN {
            return;
        }
        let var = |i: usize| self.p[(i, i)].max(0.0);
        let lost = (var(IP) + var(IP + 1)).sqrt() > self.params.noaid_pos_sigma_m;
        let slipping = var(ITH).max(var(ITH + 1)).sqrt() > max_tilt_sigma;
        if !(lost && slipping) {
            return;
        }
        self.flush_cov();
        let sigma_v: Vector3<f64> = x.v.map(f64::abs);
        widen(&mut self.p, IV, &sigma_v);
        self.hold.start_in_outage(&x);
    }

    /// The first fix after an outage's hold: ends the hold and frees the position and velocity
    /// for the fix to set (see the module doc).
    pub(super) fn end_outage_hold(&mut self, m: &GnssMeas) {
        self.hold.stop();
        self.widen_to_fix(m);
    }

    /// After integrating across a bridged IMU gap of `gap_s` between the samples `a` and `b`:
    /// the covariance takes what that cannot know (eq. G1, [`gap_variances`]), and the output
    /// predictor starts again from the filter; the next fix widens the position and velocity to
    /// its innovation ([`Eskf::widen_to_fix`]).
    pub(super) fn widen_for_gap(&mut self, a: &ImuSample, b: &ImuSample, gap_s: f64) {
        if self.x.is_none() {
            return;
        }
        self.flush_cov();
        let [att_var, vel_var, pos_var] = gap_variances(&self.params, a, b, gap_s);
        for i in 0..3 {
            self.p[(ITH + i, ITH + i)] += att_var;
            self.p[(IV + i, IV + i)] += vel_var;
            self.p[(IP + i, IP + i)] += pos_var;
        }
        self.corrected = true;
        self.gap_fix_pending = true;
    }

    /// Widens the position and velocity to at least their innovation against the fix `m`,
    /// decorrelated from the rest, and counts it as a reset of each source: the fix then
    /// corrects them rather than the attitude or the biases.
    pub(super) fn widen_to_fix(&mut self, m: &GnssMeas) {
        let Some(x) = self.x else { return };
        self.flush_cov();
        widen(&mut self.p, IP, &(m.pos_ned_m - x.p).map(f64::abs));
        self.gnss_pos.resets += 1;
        if let Some(v) = m.vel_ned_mps {
            widen(&mut self.p, IV, &(v - x.v).map(f64::abs));
            self.gnss_vel.resets += 1;
        }
    }
}

/// Decorrelates the three states from `i0` from all others and raises each one's variance to at
/// least `sigma²` (never lowers it).
fn widen(p: &mut Cov, i0: usize, sigma: &Vector3<f64>) {
    for k in i0..i0 + 3 {
        for j in 0..N {
            if !(i0..i0 + 3).contains(&j) {
                p[(k, j)] = 0.0;
                p[(j, k)] = 0.0;
            }
        }
    }
    for a in 0..3 {
        let v = p[(i0 + a, i0 + a)].max(sigma[a] * sigma[a]);
        p[(i0 + a, i0 + a)] = v;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widen_decorrelates_and_only_raises() {
        let mut p = Cov::from_fn(|i, j| if i == j { 4.0 } else { 0.5 });
        widen(&mut p, IV, &Vector3::new(1.0, 3.0, 0.0));
        for k in IV..IV + 3 {
            for j in (0..N).filter(|j| !(IV..IV + 3).contains(j)) {
                assert_eq!((p[(k, j)], p[(j, k)]), (0.0, 0.0));
            }
        }
        assert_eq!(
            (p[(IV, IV)], p[(IV + 1, IV + 1)], p[(IV + 2, IV + 2)]),
            (4.0, 9.0, 4.0)
        );
        // Within the block and elsewhere, untouched.
        assert_eq!((p[(IV, IV + 1)], p[(IP, IP + 1)]), (0.5, 0.5));
    }
}
