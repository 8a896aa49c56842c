//! The GNSS velocity's own delay ([`crate::gnss_delay`], eq. L1) in the filter: the learner fed
//! from the horizon, and each fix's velocity carried to the time it is fused at (eq. L2).
//!
//! A fix is fused at its stamp less the configured delay, position and velocity together. The
//! learner measures only the velocity's delay (the position's is not seen by eq. L1, and receivers
//! differ there: on one surveyed copter the velocity lagged the position by 0.2 s), so the
//! position keeps the configured delay and the velocity is moved to the fusion time.

use nalgebra::Vector3;
use uavnav_core::{GnssFix, ImuSample};

use super::Eskf;
use crate::aid_sources::gnss_pos::GnssMeas;
use crate::gnss_delay::DelayDiag;

impl Eskf {
    /// The delay learner's diagnostics (the delay in use is also in `Health`).
    pub fn gnss_delay_diag(&self) -> DelayDiag {
        self.gnss_delay.diag()
    }

    /// The horizontal kinematic acceleration over the horizon's IMU interval `[a, b]`, rotated by
    /// the heading the filter holds: only while that heading is known (aligned) and GNSS runs.
    pub(super) fn learn_delay_from_imu(
        &mut self,
        a: &ImuSample,
        b: &ImuSample,
        mean_accel: &Vector3<f64>,
    ) {
        if !self.params.learn_gnss_delay {
            return;
        }
        match self.x.as_ref() {
            Some(x) if self.yaw_aligned && !self.gnssless => {
                let f = x.q * (mean_accel - x.ba);
                self.gnss_delay.push_accel(a.t_ns, b.t_ns, [f.x, f.y]);
            }
            _ => self.gnss_delay.interrupt(),
        }
    }

    /// A fix's horizontal velocity at its stamp as it arrived.
    pub(super) fn learn_delay_from_fix(&mut self, fix: &GnssFix, stamp_ns: i64) {
        if !self.params.learn_gnss_delay {
            return;
        }
        if let Some(v) = &fix.velocity {
            self.gnss_delay
                .push_velocity(stamp_ns, [v.north_mps, v.east_mps]);
        }
    }

    /// Eq. L2: the fix's velocity at its fusion time `t_f` (the stamp less the configured delay),
    /// from its own time of validity `t_v` (the stamp less the learnt velocity delay):
    /// `v(t_f) = v(t_v) − ∫_{t_f}^{t_v} (R(q) (f − b_a) + g) dt`, the specific force of the IMU
    /// samples around the horizon rotated by the horizon's attitude (a turn of 0.3 rad/s moves it
    /// 4° in 0.22 s), the part beyond the newest sample taken at that sample's value. Unchanged
    /// while the delays agree or the heading is not known.
    pub(super) fn velocity_at_fusion_time(&self, m: &GnssMeas) -> GnssMeas {
        let offset_ns = self
            .gnss_delay
            .configured_ns()
            .saturating_sub(self.gnss_delay.delay_ns());
        let (Some(v), Some(x), Some(frame)) = (m.vel_ned_mps, self.x.as_ref(), self.frame.as_ref())
        else {
            return *m;
        };
        if offset_ns == 0 || !self.yaw_aligned {
            return *m;
        }
        let g = frame.gravity_ned(&x.p);
        let accel = |s: &ImuSample| x.q * (s.accel_mps2 - x.ba) + g;
        let (t0, t1) = if offset_ns > 0 {
            (m.t_ns, m.t_ns.saturating_add(offset_ns))
        } else {
            (m.t_ns.saturating_add(offset_ns), m.t_ns)
        };
        let mut dv = Vector3::zeros();
        let mut covered_ns = 0i64;
        let samples = || self.imu_behind.iter().chain(self.imu.iter());
        for (s0, s1) in samples().zip(samples().skip(1)) {
            let (lo, hi) = (s0.t_ns.max(t0), s1.t_ns.min(t1));
            if hi > lo {
                dv += (accel(s0) + accel(s1)) * (0.5 * (hi - lo) as f64 * 1e-9);
                covered_ns = covered_ns.saturating_add(hi - lo);
            }
        }
        // What the samples do not cover, at the nearest one's value.
        let uncovered_ns = t1.saturating_sub(t0).saturating_sub(covered_ns);
        if uncovered_ns > 0 {
            let nearest = if offset_ns > 0 {
                samples().last()
            } else {
                samples().next()
            };
            if let Some(s) = nearest {
                dv += accel(s) * (uncovered_ns as f64 * 1e-9);
            }
        }
        let v_f = if offset_ns > 0 { v - dv } else { v + dv };
        GnssMeas {
            vel_ned_mps: Some(v_f),
            ..*m
        }
    }
}
