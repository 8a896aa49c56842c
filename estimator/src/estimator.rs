//! [`Estimator`]: one vehicle's filter (either profile) behind input validation.

use uavnav_core::{
    BaroSample, Egomotion, FilterProfile, GnssFix, ImuSample, Lla, MagSample, MotionPrior,
    VehicleConfig,
};

use crate::eskf::Eskf;
use crate::health::Health;
use crate::output::PoseOutput;
use crate::paper::PaperFilter;
use crate::params::EstimatorParams;
use crate::validate::{InputError, check_baro, check_egomotion, check_gnss, check_imu, check_mag};

/// Consecutive continuous samples after a rejected time jump that make the estimator accept the
/// resumed stream by restarting (a genuine gap, not a glitch).
pub const JUMP_RESTART_SAMPLES: u32 = 5;

#[derive(Debug, Clone)]
enum Profile {
    Eskf(Box<Eskf>),
    Paper(Box<PaperFilter>),
}

/// The estimator of one vehicle. Pure and synchronous: time comes with the data.
#[derive(Debug, Clone)]
pub struct Estimator {
    profile: Profile,
    params: EstimatorParams,
    terrain_elevation_m: f64,
    has_camera: bool,
    last_imu_t_ns: Option<i64>,
    last_gnss_t_ns: Option<i64>,
    last_mag_t_ns: Option<i64>,
    last_baro_t_ns: Option<i64>,
    last_ego_t1_ns: Option<i64>,
    /// `GnssConfig::delay_ns`: a fix stamped `t` was valid at `t − delay`.
    gnss_delay_ns: i64,
    /// `GnssConfig::altitude_reference`: MSL altitudes are made ellipsoidal at push.
    altitude_reference: uavnav_core::AltitudeReference,
    /// Time of the last sample rejected for a time jump and how many continuous ones followed.
    jump_run: Option<(i64, u32)>,
    inputs_rejected: u64,
    /// Restarts after a non-finite state or covariance (kept across them).
    divergence_resets: u32,
    /// IMU gaps bridged instead of restarting (kept across restarts).
    imu_gaps_bridged: u64,
    /// Restarted after a divergence and no pose since: the mode is [`Mode::Diverged`].
    diverged: bool,
}

/// Whether every number of a pose is finite: a pose with a NaN or infinite value is never
/// published (the filter has diverged).
fn output_finite(o: &PoseOutput) -> bool {
    let vectors = [
        &o.pos_ned_m,
        &o.vel_ned_mps,
        &o.euler_rad,
        &o.sigma_pos_ned_m,
        &o.sigma_vel_mps,
        &o.sigma_att_rad,
        &o.gyro_bias_radps,
        &o.accel_bias_mps2,
    ];
    vectors.iter().all(|v| v.iter().all(|x| x.is_finite()))
        && o.nav_from_body.coords.iter().all(|x| x.is_finite())
        && [o.lla.lat_rad, o.lla.lon_rad, o.lla.alt_m]
            .iter()
            .all(|x| x.is_finite())
}

impl Estimator {
    /// A filter for one vehicle with the profile named in `config.profile`; `origin` fixes the
    /// local NED frame (else the first GNSS fix does).
    pub fn new(config: &VehicleConfig, params: EstimatorParams, origin: Option<Lla>) -> Self {
        let profile = match config.profile {
            FilterProfile::Eskf => {
                Profile::Eskf(Box::new(Eskf::new(config, params.clone(), origin)))
            }
            FilterProfile::Paper => {
                Profile::Paper(Box::new(PaperFilter::new(config, params.clone(), origin)))
            }
        };
        Self {
            profile,
            params,
            terrain_elevation_m: config.terrain_elevation_m,
            has_camera: config.camera.is_some(),
            last_imu_t_ns: None,
            last_gnss_t_ns: None,
            last_mag_t_ns: None,
            last_baro_t_ns: None,
            last_ego_t1_ns: None,
            gnss_delay_ns: config.gnss.map_or(0, |g| g.delay_ns),
            altitude_reference: config
                .gnss
                .map(|g| g.altitude_reference)
                .unwrap_or_default(),
            jump_run: None,
            inputs_rejected: 0,
            divergence_resets: 0,
            imu_gaps_bridged: 0,
            diverged: false,
        }
    }

    /// The running profile.
    pub fn profile(&self) -> FilterProfile {
        match self.profile {
            Profile::Eskf(_) => FilterProfile::Eskf,
            Profile::Paper(_) => FilterProfile::Paper,
        }
    }

    /// Adds an IMU sample; returns the pose at its time once initialised.
    pub fn push_imu(&mut self, s: &ImuSample) -> Result<Option<PoseOutput>, InputError> {
        if let Err(e) = check_imu(s, self.last_imu_t_ns, &self.params) {
            if let InputError::TimeJump { gap_ns, .. } = e
                && self.bridges(gap_ns)
            {
                // Integrated across, with the covariance widened (`Eskf::widen_for_gap`).
                self.imu_gaps_bridged += 1;
            } else {
                self.inputs_rejected += 1;
                if matches!(e, InputError::TimeJump { .. }) && self.note_jump(s.t_ns) {
                    self.restart_after_gap();
                } else {
                    return Err(e);
                }
            }
        }
        self.jump_run = None;
        self.last_imu_t_ns = Some(s.t_ns);
        let out = match &mut self.profile {
            Profile::Eskf(f) => f.push_imu(s),
            Profile::Paper(f) => f.push_imu(s),
        };
        let Some(mut o) = out else {
            return Ok(None);
        };
        if !(output_finite(&o) && self.covariance_finite()) {
            // Never publish NaN: restart, and report DIVERGED until the next pose.
            self.restart_after_divergence();
            return Ok(None);
        }
        self.diverged = false;
        o.health.inputs_rejected = self.inputs_rejected;
        Ok(Some(o))
    }

    /// Whether an IMU gap of `gap_ns` is bridged rather than refused: a filter with a state to
    /// carry across (`paper`: both filters running, with GNSS), the gap within
    /// [`EstimatorParams::max_bridge_gap_ns`], and the stream not already in a run of refused
    /// jumps.
    fn bridges(&self, gap_ns: i64) -> bool {
        gap_ns <= self.params.max_bridge_gap_ns
            && self.jump_run.is_none()
            && match &self.profile {
                Profile::Eskf(e) => e.nominal().is_some(),
                Profile::Paper(p) => p.can_bridge(),
            }
    }

    fn covariance_finite(&self) -> bool {
        match &self.profile {
            Profile::Eskf(f) => f.covariance_finite(),
            Profile::Paper(f) => f.covariance_finite(),
        }
    }

    fn restart_after_divergence(&mut self) {
        let resets = self.divergence_resets.saturating_add(1);
        self.restart_after_gap();
        self.divergence_resets = resets;
        self.diverged = true;
    }

    /// Tracks samples after a time jump; true once the resumed stream is clearly continuous.
    fn note_jump(&mut self, t_ns: i64) -> bool {
        let run = match self.jump_run {
            Some((last, n)) if t_ns > last && t_ns - last <= self.params.max_imu_gap_ns => n + 1,
            _ => 1,
        };
        self.jump_run = Some((t_ns, run));
        run >= JUMP_RESTART_SAMPLES
    }

    fn restart_after_gap(&mut self) {
        let (rejected, resets, bridged) = (
            self.inputs_rejected,
            self.divergence_resets,
            self.imu_gaps_bridged,
        );
        self.reset();
        self.inputs_rejected = rejected;
        self.divergence_resets = resets;
        self.imu_gaps_bridged = bridged;
    }

    /// Adds a GNSS fix, dated at its time of validity, its stamp less the configured GNSS delay.
    /// `eskf` fuses it there, behind the newest IMU sample, and learns the velocity's own delay
    /// (`crate::gnss_delay`); `paper` fuses it at once, as the paper's filters do (the date only
    /// picks the body rate of its lever-arm velocity).
    pub fn push_gnss(&mut self, fix: &GnssFix) -> Result<(), InputError> {
        // EGM96 N at the fix for MSL (NaN for a non-finite position: refused below like the fix).
        let alt_m = self
            .altitude_reference
            .to_ellipsoid(fix.lat_deg, fix.lon_deg, fix.alt_m);
        let shifted = GnssFix {
            t_ns: fix.t_ns.saturating_sub(self.gnss_delay_ns),
            alt_m,
            ..*fix
        };
        let f = &shifted;
        if let Err(e) = check_gnss(f, self.last_gnss_t_ns, self.last_imu_t_ns, &self.params) {
            self.inputs_rejected += 1;
            return Err(e);
        }
        self.last_gnss_t_ns = Some(f.t_ns);
        match &mut self.profile {
            Profile::Eskf(e) => e.push_gnss(f, fix.t_ns),
            Profile::Paper(p) => p.push_gnss(f),
        }
        Ok(())
    }

    /// Adds a magnetometer sample (validated; the filters that use it fuse it at its time).
    pub fn push_mag(&mut self, m: &MagSample) -> Result<(), InputError> {
        if let Err(e) = check_mag(m, self.last_mag_t_ns) {
            self.inputs_rejected += 1;
            return Err(e);
        }
        self.last_mag_t_ns = Some(m.t_ns);
        if let Profile::Eskf(e) = &mut self.profile {
            e.push_mag(m);
        }
        Ok(())
    }

    /// Adds a barometer sample (validated; the filters that use it fuse it at its time).
    pub fn push_baro(&mut self, b: &BaroSample) -> Result<(), InputError> {
        if let Err(e) = check_baro(b, self.last_baro_t_ns) {
            self.inputs_rejected += 1;
            return Err(e);
        }
        self.last_baro_t_ns = Some(b.t_ns);
        if let Profile::Eskf(e) = &mut self.profile {
            e.push_baro(b);
        }
        Ok(())
    }

    /// Adds a vision egomotion measurement (fused at its frame times).
    pub fn push_egomotion(&mut self, m: &Egomotion) -> Result<(), InputError> {
        if !self.has_camera {
            self.inputs_rejected += 1;
            return Err(InputError::NoCamera);
        }
        if let Err(e) = check_egomotion(m, self.last_ego_t1_ns, self.last_imu_t_ns, &self.params) {
            self.inputs_rejected += 1;
            return Err(e);
        }
        self.last_ego_t1_ns = Some(m.t1_ns);
        match &mut self.profile {
            Profile::Eskf(e) => e.push_egomotion(m),
            Profile::Paper(p) => p.push_egomotion(m),
        }
        Ok(())
    }

    /// The motion prior between two frame times for the vision front end.
    pub fn motion_prior(&self, t0_ns: i64, t1_ns: i64) -> MotionPrior {
        match &self.profile {
            Profile::Eskf(e) => e.motion_prior(t0_ns, t1_ns, self.terrain_elevation_m),
            Profile::Paper(p) => p.motion_prior(t0_ns, t1_ns, self.terrain_elevation_m),
        }
    }

    /// Bytes held by the filter's delayed buffers (IMU history, pending measurements): at most
    /// [`crate::buffer::MAX_BUFFERED_BYTES`], whatever the input.
    pub fn buffered_bytes(&self) -> usize {
        match &self.profile {
            Profile::Eskf(e) => e.buffered_bytes(),
            Profile::Paper(p) => p.buffered_bytes(),
        }
    }

    /// Current health, the full snapshot (every output carries its summary, `PoseHealth`).
    pub fn health(&self) -> Health {
        let mut h = match &self.profile {
            Profile::Eskf(e) => e.health(),
            Profile::Paper(p) => p.health(),
        };
        h.inputs_rejected = self.inputs_rejected;
        h.divergence_resets = h.divergence_resets.saturating_add(self.divergence_resets);
        h.imu_gaps_bridged = self.imu_gaps_bridged;
        if self.diverged {
            h.mode = crate::health::Mode::Diverged;
        }
        h
    }

    /// The ESKF, when that profile runs (diagnostics and tests).
    pub fn eskf(&self) -> Option<&Eskf> {
        match &self.profile {
            Profile::Eskf(e) => Some(e),
            Profile::Paper(_) => None,
        }
    }

    /// The `paper` profile's filters, when that profile runs (diagnostics and tests).
    pub fn paper(&self) -> Option<&PaperFilter> {
        match &self.profile {
            Profile::Paper(p) => Some(p),
            Profile::Eskf(_) => None,
        }
    }

    /// Forgets everything but the configuration and origin.
    pub fn reset(&mut self) {
        match &mut self.profile {
            Profile::Eskf(e) => e.reset(),
            Profile::Paper(p) => p.reset(),
        }
        self.last_imu_t_ns = None;
        self.last_gnss_t_ns = None;
        self.last_mag_t_ns = None;
        self.last_baro_t_ns = None;
        self.last_ego_t1_ns = None;
        self.jump_run = None;
        self.inputs_rejected = 0;
        self.divergence_resets = 0;
        self.imu_gaps_bridged = 0;
        self.diverged = false;
    }
}
