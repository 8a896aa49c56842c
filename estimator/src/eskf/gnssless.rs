//! Running without GNSS: the `eskf` starts from the IMU alone when no fix has come for
//! `start_without_gnss_after_s` (at once, once level, for a vehicle configured without a
//! receiver), and reports attitude only ([`Mode::AttitudeOnly`]) until GNSS starts it properly.
//!
//! * **Start**: levelled on gravity, heading unknown (the magnetometer aligns it as usual), zero
//!   velocity, at the configured origin or, without one, at the origin of a provisional frame
//!   ([`crate::init::ensure_frame`]: the place is unknown, so the Earth rate is left out and gravity is
//!   the normal gravity at 45°; its ±0.03 m/s² from the true place goes into the accelerometer
//!   bias).
//! * **While running**: the position hold ([`crate::aid_sources::position_hold`]) keeps the
//!   velocity and, through it, the tilt bounded; the barometer holds the height from its first
//!   sample; the magnetometer is fused against its own field when the place is unknown (no
//!   model: its declination is unknown, `unknown_declination_sigma_rad`); vision gives rotation
//!   only (its metric scale needs the height above the terrain, which needs the place).
//! * **First fix**: the filter is rebuilt and started from that fix exactly as if it had waited
//!   for it (the same IMU history, levelling window, buffered measurements and yaw bank it would
//!   have had; nothing learnt without GNSS is carried over), so a flight whose GNSS comes late
//!   runs from its first fix as it always did.

use nalgebra::Vector3;
use uavnav_core::Lla;
use uavnav_core::magnetic::MagneticField;

use super::Eskf;
use crate::aid_sources::baro_height::BaroState;
use crate::aid_sources::mag_heading::DEAD_FIELD_T;
use crate::health::Mode;

impl Eskf {
    /// At the horizon `t_ns` with no filter yet: starts without GNSS when it is time (see the
    /// module doc).
    pub(super) fn try_start_without_gnss(&mut self, t_ns: i64) {
        if self.x.is_some() || self.gnss_seen {
            return;
        }
        let first = *self.first_imu_t_ns.get_or_insert(t_ns);
        let has_gnss = self.config.gnss.is_some();
        if !crate::init::start_without_gnss_due(first, t_ns, has_gnss, &self.params) {
            return;
        }
        let frame =
            crate::init::ensure_frame(&mut self.frame, &mut self.frame_provisional, &mut self.w_ie);
        let at = Vector3::zeros();
        let g = frame.gravity_ned(&at);
        let Some(r) =
            self.init
                .try_init_at_rest(t_ns, &at, &g, &self.params, self.params.noaid_pos_sigma_m)
        else {
            return;
        };
        self.x = Some(r.x);
        // The start's covariance already has the heading unknown and uncorrelated.
        self.p = r.p;
        self.yaw_aligned = false;
        self.gnssless = true;
        self.hold.start(&r.x);
        self.acc = Default::default();
        self.corrected = true;
    }

    /// Fuses the position hold at the horizon while running without GNSS or through an outage.
    pub(super) fn hold_position(&mut self, t_ns: i64) {
        let Some(x) = self.x else { return };
        if !self.gnssless && !self.outage_hold() {
            return;
        }
        // The barometer holds the height once it has its first sample.
        let vertical = self.baro.state != BaroState::Holding;
        self.flush_cov();
        let dx = self.hold.fuse(
            &x,
            &mut self.p,
            t_ns,
            self.params.noaid_pos_sigma_m,
            vertical,
            self.params.gate_sigma,
        );
        self.inject(dx);
    }

    /// The first fix of a filter running without GNSS: rebuilt as it would be had it waited (see
    /// the module doc). The frame is the real one by now (`push_gnss` set it at the fix).
    pub(super) fn restart_for_gnss(&mut self) {
        let mut fresh = Eskf::new(&self.config, self.params.clone(), self.origin);
        fresh.imu = std::mem::take(&mut self.imu);
        fresh.imu_behind = std::mem::take(&mut self.imu_behind);
        fresh.buffer = std::mem::take(&mut self.buffer);
        fresh.init = std::mem::take(&mut self.init);
        fresh.yaw_est = self.yaw_est.clone();
        fresh.late_dropped = self.late_dropped;
        fresh.imu_clipped = self.imu_clipped;
        fresh.frame = self.frame;
        fresh.w_ie = self.w_ie;
        fresh.first_imu_t_ns = self.first_imu_t_ns;
        fresh.gnss_seen = true;
        fresh.hold.stop();
        *self = fresh;
    }

    /// The first fix pushed while the frame is provisional: the real frame is set at it (the
    /// filter's positions are relative and its hold point stays where it is).
    pub(super) fn replace_provisional_frame(&mut self, lla: Lla) {
        if self.frame_provisional {
            self.set_frame(lla);
            self.frame_provisional = false;
            self.gravity = None;
            self.lla = None;
            self.mag_field = None;
        }
    }

    /// The field the compass is fused against when the place is unknown: its own, as the first
    /// usable sample shows it through the filter's tilt (strength and inclination), with
    /// declination 0. No extra σ per sample: the filter's heading is then the magnetic heading,
    /// which each sample measures to its own σ, and the unknown declination, one offset for the
    /// whole flight, enters once, as the floor of the reported yaw σ
    /// ([`Self::reported_yaw_floor_rad`]). It used to be added to every sample as well; on the
    /// 14 compass logs of the survey without GNSS the summed yaw RMSE went 435.5 → 431.2° without
    /// it (copter_218 2.0 → 1.6°), roll and pitch within 0.03°. (Before the compass held the tilt,
    /// `mag_heading::HELD_STATES`, that 10° per sample was what kept its errors out of the tilt.)
    pub(super) fn own_field(&mut self, m_b: &Vector3<f64>) -> Option<(MagneticField, f64)> {
        if self.mag_field.is_none() {
            let x = self.x.as_ref()?;
            let m_n = x.q.transform_vector(m_b);
            if m_n.norm() < DEAD_FIELD_T {
                return None;
            }
            let field = MagneticField {
                ned_t: Vector3::new(m_n.xy().norm(), 0.0, m_n.z),
            };
            self.mag_field = Some((field, 0.0));
        }
        self.mag_field
    }

    /// The least yaw σ the output may claim, rad: the heading floor of `manage_heading`, and,
    /// for a compass fused against its own field (the place unknown), the unknown declination's
    /// σ. The declination is the same for every sample, so fusing many samples does not make
    /// true north better known than it is: the filter's own yaw σ shrank to 1–2° on public
    /// ArduPilot copters without GNSS while 10–30° off their autopilots' heading.
    pub(super) fn reported_yaw_floor_rad(&self) -> f64 {
        let mut floor = self.yaw_sigma_floor_rad;
        if self.frame_provisional && self.heading == super::HeadingSource::Magnetometer {
            floor = floor.max(self.params.unknown_declination_sigma_rad);
        }
        floor
    }

    /// [`Mode::AttitudeOnly`] while running without GNSS or holding through an outage
    /// (`outage`), else `other`.
    pub(super) fn gnssless_mode(&self, other: Mode) -> Mode {
        if (self.gnssless || self.outage_hold()) && other != Mode::Diverged {
            Mode::AttitudeOnly
        } else {
            other
        }
    }
}
