//! Profile `paper`, OUR ADDITION (not in the paper, whose filters start from a GNSS fix): running
//! without GNSS, attitude only ([`Mode::AttitudeOnly`]), as the `eskf` profile does
//! (`eskf::gnssless`).
//!
//! * **Start**: when no fix this profile can use (one with a velocity) has come for
//!   `start_without_gnss_after_s` since the first IMU sample (at once for a vehicle configured
//!   without a receiver), from the levelling window: roll and pitch from the mean specific
//!   force, the heading unknown (this profile reads no magnetometer). Without a configured
//!   origin the frame is provisional: 45° N, the Earth rate left out.
//! * **While running**: VIDEO-IMU(1) propagates on the gyro as usual (its video chain does not
//!   start: eq. 34 starts from an aligned attitude, and the heading is unknown); roll and pitch
//!   are held by the tilt windows
//!   of [`super::gnss_tilt`] against a velocity held at zero within
//!   `paper_noaid_speed_sigma_mps` ([`super::gnss_tilt::GnssTilt::at_hold`]); GPS-IMU and
//!   VIDEO-IMU(2) do not run (nothing observes a position).
//! * **Divergence**: [`HOLD_DIVERGED_WINDOWS`] windows rejected in a row restart it from the
//!   latest levelling window (counted in `divergence_resets`).
//! * **First usable fix**: everything learnt without GNSS is dropped and the filters start from
//!   that fix as if they had waited for it (the IMU history and the levelling window are kept).

use super::*;
use crate::init::{
    UNALIGNED_YAW_SIGMA_RAD, gyro_bias_at_rest, mean_and_spread, start_without_gnss_due,
};

/// Held-velocity windows rejected in a row that restart the filter without GNSS (15 s with
/// 5 s windows): the tilt is then far from what the accelerometers have shown for that long,
/// the way a vehicle at rest after landing shows it.
pub const HOLD_DIVERGED_WINDOWS: u32 = 3;

impl PaperFilter {
    /// Before the filters have started: starts without GNSS when it is time (module doc).
    pub(super) fn try_start_without_gnss(&mut self, t_ns: i64) {
        if self.att.is_some() || self.last_fix.is_some() {
            return;
        }
        let first = *self.first_imu_t_ns.get_or_insert(t_ns);
        if !start_without_gnss_due(first, t_ns, self.has_gnss, &self.params) {
            return;
        }
        if !self.levelling_window_full() {
            return;
        }
        let frame =
            crate::init::ensure_frame(&mut self.frame, &mut self.frame_provisional, &mut self.w_ie);
        // The levelling window: the latest samples, as many as `init_f` holds.
        let n = self.init_f.len().min(self.imu.len());
        let window: Vec<(i64, Vector3<f64>, Vector3<f64>)> = self
            .imu
            .iter()
            .skip(self.imu.len() - n)
            .map(|s| (s.t_ns, s.gyro_radps, s.accel_mps2))
            .collect();
        let (f_b, spread) = mean_and_spread(window.iter().map(|s| s.2));
        let g_n = frame.gravity_ned(&Vector3::zeros());
        let Some(q) = attitude_from_gravity(&f_b, &g_n, 0.0) else {
            return;
        };
        let g = g_n.norm();
        // As `eskf`'s start at rest: a window away from 1 g, or spread, is a vehicle already
        // moving, and the tilt σ allows for it; the mean gyro of a still vehicle is its bias
        // (plane_E's pitch gyro reads 1 °/s on the ground: left in, it pitched the attitude over
        // in a minute, faster than the held velocity's windows correct).
        let unlevel = (((f_b.norm() - g).abs() + spread) / g).min(1.0).asin();
        if let Some((bias, _)) = gyro_bias_at_rest(window.iter(), &f_b, g, spread) {
            self.gnss_tilt.set_start_gyro_bias(bias);
        }
        let (r, p, y) = q.euler_angles();
        let tilt = self.params.init_tilt_sigma_rad + unlevel;
        self.att = Some(AttitudeEkf::new(
            Vector3::new(r, p, y),
            Vector3::new(tilt, tilt, UNALIGNED_YAW_SIGMA_RAD),
            t_ns,
        ));
        self.gnssless = true;
    }

    /// One IMU interval without GNSS: the attitude filter and the held-velocity tilt window.
    pub(super) fn step_gnssless(
        &mut self,
        prev: &ImuSample,
        s: &ImuSample,
        frame: &LocalFrame,
    ) -> Option<PoseOutput> {
        let (m, _, accel_psd, dt_s) = self.predict_attitude(prev, s)?;
        let att = self.att.as_mut()?;
        // Without GNSS nothing else bounds the Euler angles' covariance when the vehicle
        // tumbles (see `cap_euler_variance`). Not applied with GNSS, whose runs it would not
        // change but by rounding.
        att.cap_euler_variance(UNALIGNED_YAW_SIGMA_RAD * UNALIGNED_YAW_SIGMA_RAD);
        self.gnss_tilt
            .add_imu(&att.rotation(), &m.accel, accel_psd, dt_s);
        let hold = gnss_tilt::TiltFix {
            t_ns: s.t_ns,
            vel_ned_mps: Vector3::zeros(),
            sigma_vel_mps: self.params.paper_noaid_speed_sigma_mps,
            g_ned: frame.gravity_ned(&Vector3::zeros()),
            w_ie: self.w_ie,
        };
        let video = att.video_active();
        self.gnss_tilt
            .at_hold(&hold, att, video, self.params.gate_sigma);
        if self.gnss_tilt.diag.consecutive_rejects >= HOLD_DIVERGED_WINDOWS {
            // The divergence check without GNSS: restart from the latest levelling window,
            // counted and reported as a restart (the pose says Initialising until then).
            self.restart_gnssless();
            return None;
        }
        self.output(s.t_ns)
    }

    /// Back to before the start without GNSS, keeping the IMU history, the levelling window
    /// and the restarts count: the next IMU sample starts again.
    fn restart_gnssless(&mut self) {
        self.divergence_resets += 1;
        self.gnssless = false;
        self.att = None;
        self.gnss_tilt = self.gnss_tilt.restarted();
        self.observed_psd = (0.0, 0.0);
    }

    /// At the first usable fix while running without GNSS: back to the state before the start,
    /// keeping the IMU history and the levelling window (module doc).
    pub(super) fn leave_gnssless(&mut self) {
        if !self.gnssless && !self.frame_provisional {
            return;
        }
        self.gnssless = false;
        self.att = None;
        self.gnss_tilt = self.gnss_tilt.restarted();
        self.health = Health::default();
        self.observed_psd = (0.0, 0.0);
        if self.frame_provisional {
            self.frame_provisional = false;
            self.frame = None;
            self.gravity = None;
            self.w_ie = Vector3::zeros();
        }
    }
}
