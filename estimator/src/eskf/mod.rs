//! The error-state EKF (profile `eskf`): the nominal state runs at the fusion horizon, a fixed delay
//! behind the newest IMU sample; buffered measurements are fused at their own time of validity;
//! the [`OutputPredictor`] carries the state forward to every IMU sample.
//!
//! | module | what it holds |
//! |---|---|
//! | this file | the filter's state, horizon stepping, buffered events, GNSS, baro and vision fusion |
//! | [`heading`] | the heading lifecycle ([`HeadingSource`]), magnetometer and yaw-bank alignment |
//! | [`gnssless`] | the start without GNSS, attitude only until the first fix |
//! | [`imu_noise`] | the IMU's noise measured from its samples, clipping, and their report in health |
//! | [`outage`] | the limit of dead reckoning in a GNSS outage: a position hold until the next fix; bridged IMU gaps (eq. G1) |
//! | `report` | mode, health, the pose output, the motion prior for vision |

mod delay;
mod gnssless;
mod heading;
pub mod imu_noise;
mod outage;
mod report;

pub use heading::HeadingSource;

use std::collections::VecDeque;

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use uavnav_core::magnetic::MagneticField;
use uavnav_core::{Egomotion, ImuSample, Lla, LocalFrame, VehicleConfig};

use crate::aid_sources::baro_height::{BaroHeightSource, BaroParams};
use crate::aid_sources::gnss_pos::{
    GnssMeas, GnssPosSource, correlated_sigma, gm_psd, white_noise,
};
use crate::aid_sources::gnss_vel::{GnssVelSource, LEVER_GYRO_HALF_WINDOW_NS, lever_gyro};
use crate::aid_sources::mag_calibration::MagCalibration;
use crate::aid_sources::mag_heading::MagHeadingSource;
use crate::aid_sources::position_hold::PositionHold;
use crate::aid_sources::vision::{PlaneScale, VisionSource, VisionUse};
use crate::buffer::{DelayBuffer, Event, MAX_IMU_HISTORY};
use crate::gnss_delay::GnssDelayLearner;
use crate::init::{Initialiser, hold_yaw_unknown};
use crate::output::PoseOutput;
use crate::output_predictor::{OutputPredictor, mean_of};
use crate::params::EstimatorParams;
use crate::prediction::{
    ErrorDynamics, GravityCache, ImuMean, ProcessNoise, earth_rate_ned, integrate_nominal,
};
use crate::state::{Cov, ErrVec, ITH, Nominal, PoseClone, augment_clone, clear_clone};
use crate::yaw_estimator::YawEstimator;

/// Covariance-prediction accumulator (PX4 downsampling of the covariance prediction).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct CovAccum {
    dt_s: f64,
    gyro_dt: Vector3<f64>,
    accel_dt: Vector3<f64>,
    /// Σ of the per-axis variance the IMU data itself shows over the interval (see
    /// [`Eskf::observed_imu_noise`]), rad² and (m/s)².
    gyro_var: f64,
    accel_var: f64,
}

/// The error-state EKF.
#[derive(Debug, Clone)]
pub struct Eskf {
    config: VehicleConfig,
    params: EstimatorParams,
    lever_b: Vector3<f64>,
    body_from_cam: Option<Isometry3<f64>>,
    gyro_psd: f64,
    /// The gyro PSD of the last covariance prediction (configured or observed, the larger),
    /// (rad/s)²/Hz: the noise of the gyro sample in the GNSS lever-arm velocity.
    gyro_psd_used: f64,
    noise: ProcessNoise,
    origin: Option<Lla>,
    frame: Option<LocalFrame>,
    w_ie: Vector3<f64>,
    gravity: Option<GravityCache>,
    /// IMU samples from the horizon sample (front, already integrated) to the newest.
    imu: VecDeque<ImuSample>,
    /// The samples already behind the horizon: [`LEVER_GYRO_HALF_WINDOW_NS`] of them (50 at
    /// 1 kHz), [`MAX_IMU_BEHIND`] at most whatever the rate.
    imu_behind: VecDeque<ImuSample>,
    x: Option<Nominal>,
    p: Cov,
    acc: CovAccum,
    buffer: DelayBuffer,
    init: Initialiser,
    yaw_aligned: bool,
    heading: HeadingSource,
    /// The least yaw σ the output may claim, rad: what a heading seen only through the GNSS
    /// velocity can honestly claim (`manage_heading`), 0 when something else sees the heading.
    yaw_sigma_floor_rad: f64,
    gnss_pos: GnssPosSource,
    gnss_vel: GnssVelSource,
    body_from_mag: Option<UnitQuaternion<f64>>,
    mag: MagHeadingSource,
    /// The compass's offset and own field, learnt in flight (eq. M2).
    mag_cal: MagCalibration,
    /// The model field at the origin and the data's date, and the extra declination σ (rad) for
    /// a date outside the model's validity or unknown.
    mag_field: Option<(MagneticField, f64)>,
    yaw_est: YawEstimator,
    /// Barometer per-sample pressure σ, Pa, when fitted.
    baro_sigma_pa: Option<f64>,
    baro: BaroHeightSource,
    /// The heading may be taken from the course (`EstimatorParams::course_heading`, or a fixed
    /// wing).
    course_heading: bool,
    /// Heading resets from the yaw estimator after alignment.
    pub yaw_resets: u32,
    /// IMU intervals with a clipped axis.
    imu_clipped: u64,
    /// An IMU gap was bridged and no fix has come since: the next one widens the position and
    /// velocity to its innovation first (`widen_for_gap`).
    gap_fix_pending: bool,
    /// The IMU noise measured over about the last second over the configured, σ ratio (gyro,
    /// accelerometer): vibration, or a logged IMU too slow for the motion.
    imu_noise_ratio: Option<[f64; 2]>,
    /// Since when the magnetometer-held heading has contradicted the converged yaw bank.
    mag_contradicted_since_ns: Option<i64>,
    /// How far the compass-held heading and the converged yaw bank have recently disagreed
    /// beyond the bank's σ (`Eskf::compass_conflict_rad`).
    mag_bank_conflict: heading::CompassConflict,
    vision: VisionSource,
    out: OutputPredictor,
    late_dropped: u64,
    /// How far the fusion horizon trails the newest IMU sample, ns: `fusion_delay_ns` plus the
    /// GNSS delay (see [`horizon_lag_ns`]).
    horizon_lag_ns: i64,
    corrected: bool,
    lla: Option<crate::output::LlaLinearizer>,
    /// Running without GNSS (started from the IMU alone, no fix processed yet; `gnssless`).
    gnssless: bool,
    /// The frame is the provisional one of a filter that does not know where it is.
    frame_provisional: bool,
    /// A GNSS fix has been pushed: the filter starts from it, not without it.
    gnss_seen: bool,
    /// Time of the first IMU sample at the horizon, ns.
    first_imu_t_ns: Option<i64>,
    /// The position hold of a filter without position aiding.
    hold: PositionHold,
    /// Angle turned about the vertical since the heading was last observed, rad (`outage`).
    unaided_turn_rad: f64,
    /// The GNSS velocity's own delay, learnt (eq. L1; `delay.rs`).
    gnss_delay: GnssDelayLearner,
}

/// Most samples kept behind the horizon for the lever-arm gyro window (≈ 13 kB).
const MAX_IMU_BEHIND: usize = 128;

/// How far the fusion horizon trails the newest IMU sample, ns: `fusion_delay_ns` (the arrival
/// lateness the service allows any measurement) plus the GNSS delay. A fix stamped `t` was valid
/// at `t − delay` and is fused there, yet it arrives only once the IMU has reached about `t`: with
/// a horizon of `fusion_delay_ns` alone, any delay above it made every such fix late. ArduPilot's
/// default `EK3_GPS_DELAY` is 220 ms against our 200 ms, and a real copter log lost its fixes in
/// runs of 3–7 s that way, dropped as late (counted, not refused) while the yaw bank saw gaps.
pub fn horizon_lag_ns(config: &VehicleConfig, params: &EstimatorParams) -> i64 {
    let gnss_delay_ns = config.gnss.map_or(0, |g| g.delay_ns.max(0));
    params.fusion_delay_ns.saturating_add(gnss_delay_ns)
}

/// Linear interpolation of two IMU samples at `t_ns`.
pub fn interp(a: &ImuSample, b: &ImuSample, t_ns: i64) -> ImuSample {
    if b.t_ns == a.t_ns {
        return *b;
    }
    let w = (t_ns - a.t_ns) as f64 / (b.t_ns - a.t_ns) as f64;
    ImuSample {
        t_ns,
        gyro_radps: a.gyro_radps + (b.gyro_radps - a.gyro_radps) * w,
        accel_mps2: a.accel_mps2 + (b.accel_mps2 - a.accel_mps2) * w,
    }
}

impl Eskf {
    /// A filter for one vehicle; `origin` fixes the local frame (else the first GNSS fix does).
    pub fn new(config: &VehicleConfig, mut params: EstimatorParams, origin: Option<Lla>) -> Self {
        let imu = &config.imu;
        // The IMU's own turn-on bias σ, where it says its biases are larger than the default
        // prior (a consumer-grade IMU); the default stays a floor for calibration residuals.
        params.init_gyro_bias_sigma_radps = params
            .init_gyro_bias_sigma_radps
            .max(imu.gyro_bias_sigma_radps);
        params.init_accel_bias_sigma_mps2 = params
            .init_accel_bias_sigma_mps2
            .max(imu.accel_bias_sigma_mps2);
        let noise = ProcessNoise {
            gyro_psd: imu.gyro_noise_density.powi(2),
            accel_psd: imu.accel_noise_density.powi(2),
            gyro_bias_psd: imu.gyro_random_walk.powi(2),
            accel_bias_psd: imu.accel_random_walk.powi(2),
            gm_psd: [0.0; 3],
            gm_tau_s: params.gnss_pos_tau_s,
        };
        let mut s = Self {
            config: config.clone(),
            lever_b: config
                .gnss
                .map(|g| g.lever_arm_body_m)
                .unwrap_or_else(Vector3::zeros),
            body_from_cam: config.camera.as_ref().map(|c| c.body_from_cam),
            gyro_psd: noise.gyro_psd,
            gyro_psd_used: noise.gyro_psd,
            noise,
            origin,
            frame: None,
            w_ie: Vector3::zeros(),
            gravity: None,
            imu: VecDeque::new(),
            imu_behind: VecDeque::new(),
            x: None,
            p: Cov::zeros(),
            acc: CovAccum::default(),
            buffer: DelayBuffer::default(),
            init: Initialiser::default(),
            yaw_aligned: false,
            yaw_sigma_floor_rad: 0.0,
            heading: HeadingSource::Unknown,
            gnss_pos: GnssPosSource::default(),
            gnss_vel: GnssVelSource::default(),
            body_from_mag: config.mag.map(|m| m.body_from_mag),
            mag: MagHeadingSource::default(),
            mag_cal: MagCalibration::new(params.mag_calibration),
            mag_field: None,
            yaw_est: YawEstimator::new(params.yaw_estimator),
            baro_sigma_pa: config.baro.map(|b| b.sigma_pressure_pa),
            baro: BaroHeightSource::default(),
            course_heading: params.course_heading
                || config.airframe == uavnav_core::Airframe::FixedWing,
            yaw_resets: 0,
            mag_contradicted_since_ns: None,
            mag_bank_conflict: heading::CompassConflict::default(),
            imu_clipped: 0,
            gap_fix_pending: false,
            imu_noise_ratio: None,
            vision: VisionSource::default(),
            out: OutputPredictor::new(),
            late_dropped: 0,
            horizon_lag_ns: horizon_lag_ns(config, &params),
            corrected: false,
            lla: None,
            gnssless: false,
            frame_provisional: false,
            gnss_seen: false,
            first_imu_t_ns: None,
            hold: PositionHold::default(),
            unaided_turn_rad: 0.0,
            gnss_delay: GnssDelayLearner::new(config.gnss.map_or(0, |g| g.delay_ns)),
            params,
        };
        if let Some(o) = origin {
            s.set_frame(o);
        }
        s
    }

    /// Back to the state right after `new` (same configuration and origin): the filter is
    /// rebuilt, so no field can be forgotten.
    pub fn reset(&mut self) {
        *self = Self::new(&self.config, self.params.clone(), self.origin);
    }

    fn set_frame(&mut self, origin: Lla) {
        self.frame = Some(LocalFrame::new(origin));
        self.w_ie = earth_rate_ned(origin.lat_rad);
    }

    /// Where the heading came from.
    pub fn heading_source(&self) -> HeadingSource {
        self.heading
    }

    /// The magnetometer heading source (state, diagnostics).
    pub fn mag_source(&self) -> &MagHeadingSource {
        &self.mag
    }

    /// The in-flight compass calibration (offset, field, diagnostics).
    pub fn mag_calibration(&self) -> &MagCalibration {
        &self.mag_cal
    }

    /// The yaw estimator (diagnostics).
    pub fn yaw_estimator(&self) -> &YawEstimator {
        &self.yaw_est
    }

    /// The local frame, once known.
    pub fn frame(&self) -> Option<&LocalFrame> {
        self.frame.as_ref()
    }

    /// Time of the fusion horizon (the oldest retained IMU sample).
    pub fn horizon_t_ns(&self) -> Option<i64> {
        self.imu.front().map(|s| s.t_ns)
    }

    /// The horizon nominal state (for tests and diagnostics).
    pub fn nominal(&self) -> Option<&Nominal> {
        self.x.as_ref()
    }

    /// The error covariance at the horizon.
    pub fn covariance(&self) -> &Cov {
        &self.p
    }

    /// Adds a GNSS fix (already validated, stamped with its time of validity: its stamp
    /// `stamp_ns` as it arrived less the configured delay) to the delay buffer.
    pub fn push_gnss(&mut self, fix: &uavnav_core::GnssFix, stamp_ns: i64) {
        let lla = Lla::from_deg(fix.lat_deg, fix.lon_deg, fix.alt_m);
        self.gnss_seen = true;
        self.replace_provisional_frame(lla);
        if self.frame.is_none() {
            self.set_frame(lla);
        }
        let Some(frame) = self.frame.as_ref() else {
            return;
        };
        if self.horizon_t_ns().is_some_and(|h| fix.t_ns <= h) {
            self.late_dropped += 1;
            return;
        }
        let meas = GnssMeas::from_fix(fix, frame.lla_to_ned(&lla));
        self.learn_delay_from_fix(fix, stamp_ns);
        if !self.buffer.push(Event::Gnss(meas)) {
            self.late_dropped += 1;
        }
    }

    /// Adds a magnetometer sample (already validated; sensor frame) to the delay buffer.
    pub fn push_mag(&mut self, m: &uavnav_core::MagSample) {
        let Some(r) = self.body_from_mag else {
            return;
        };
        if self.horizon_t_ns().is_some_and(|h| m.t_ns <= h) {
            self.late_dropped += 1;
            return;
        }
        if !self.buffer.push(Event::Mag(m.t_ns, r * m.field_t)) {
            self.late_dropped += 1;
        }
    }

    /// Adds a barometer sample (already validated) to the delay buffer.
    pub fn push_baro(&mut self, b: &uavnav_core::BaroSample) {
        if self.baro_sigma_pa.is_none() {
            return;
        }
        if self.horizon_t_ns().is_some_and(|h| b.t_ns <= h) {
            self.late_dropped += 1;
            return;
        }
        if !self.buffer.push(Event::Baro(b.t_ns, b.pressure_pa)) {
            self.late_dropped += 1;
        }
    }

    /// Bytes held by the IMU history and the delay buffer.
    pub fn buffered_bytes(&self) -> usize {
        self.imu.capacity() * size_of::<ImuSample>() + self.buffer.bytes()
    }

    /// The barometer source (state, offset, diagnostics).
    pub fn baro_source(&self) -> &BaroHeightSource {
        &self.baro
    }

    /// Adds a vision egomotion (already validated) to the delay buffer.
    pub fn push_egomotion(&mut self, m: &Egomotion) {
        let h = self.horizon_t_ns();
        if self.body_from_cam.is_none() || h.is_some_and(|h| m.t1_ns <= h) {
            self.late_dropped += 1;
            return;
        }
        let clone_ok = self
            .x
            .as_ref()
            .and_then(|x| x.clone)
            .is_some_and(|c| c.t_ns == m.t0_ns);
        if h.is_none_or(|h| m.t0_ns > h) && !self.buffer.has_clone_at(m.t0_ns) && !clone_ok {
            self.buffer.push(Event::CloneAt(m.t0_ns));
        }
        if !self.buffer.push(Event::Ego(Box::new(m.clone()))) {
            self.late_dropped += 1;
        }
    }

    /// Adds an IMU sample (already validated, strictly newer than the last) and returns the pose
    /// at its time once initialised.
    pub fn push_imu(&mut self, s: &ImuSample) -> Option<PoseOutput> {
        let prev_newest = self.imu.back().copied();
        self.imu.push_back(*s);
        if self.imu.len() == 1 {
            self.init.add_imu(
                s.t_ns,
                &s.gyro_radps,
                &s.accel_mps2,
                self.params.init_level_window_s,
            );
        }
        self.corrected = false;
        let target = s.t_ns - self.horizon_lag_ns;
        // Kept below the bound before the next push, so the deque never reserves beyond it.
        while self.imu.len() >= 2
            && (self.imu[1].t_ns <= target || self.imu.len() >= MAX_IMU_HISTORY)
        {
            self.step();
        }
        // Borrowed, not copied: this runs for every IMU sample of every vehicle of the service.
        let (Some(frame), Some(x)) = (self.frame.as_ref(), self.x.as_ref()) else {
            return None;
        };
        let tau = self.params.gnss_pos_tau_s;
        if self.corrected || self.out.x.is_none() {
            self.out.resync(frame, x, self.imu.iter(), &self.w_ie, tau);
        } else if let Some(prev) = prev_newest {
            if let Some(o) = self.out.x.as_mut() {
                o.bg = x.bg;
                o.ba = x.ba;
            }
            self.out.advance(frame, &prev, s, &self.w_ie, tau);
        }
        self.output()
    }

    /// Advances the horizon by one IMU interval, processing the events inside it.
    fn step(&mut self) {
        let (a, b) = (self.imu[0], self.imu[1]);
        while let Some(e) = self.buffer.pop_until(b.t_ns) {
            let t = e.t_ns().max(a.t_ns);
            self.integrate_to(&a, &b, t);
            self.process(e, &a, &b);
        }
        self.integrate_to(&a, &b, b.t_ns);
        let dt_s = (b.t_ns - a.t_ns) as f64 * 1e-9;
        let bridged = self.params.is_bridged_gap(a.t_ns, b.t_ns);
        if bridged {
            // A gap the estimator chose to bridge (`EstimatorParams::max_bridge_gap_ns`).
            self.widen_for_gap(&a, &b, dt_s);
        } else {
            // Consecutive samples across a gap say nothing of the IMU's noise.
            self.observed_imu_noise(&a, &b, dt_s);
        }
        // Without GNSS the bank sees a zero bias, as it would had the filter waited for a fix
        // (`gnssless`: the start from the first fix is then the same).
        let bg = match self.x.as_ref() {
            Some(x) if !self.gnssless => x.bg,
            _ => Vector3::zeros(),
        };
        let m = mean_of(&a, &b);
        self.yaw_est.predict(&(m.gyro - bg), &m.accel, dt_s);
        self.track_unaided_turn(&m.gyro, dt_s);
        if !bridged {
            self.learn_delay_from_imu(&a, &b, &m.accel);
        }
        if let Some(done) = self.imu.pop_front() {
            // Kept for the lever-arm gyro window around a fix at the horizon.
            self.imu_behind.push_back(done);
            while self.imu_behind.len() > MAX_IMU_BEHIND
                || self
                    .imu_behind
                    .front()
                    .is_some_and(|s| done.t_ns - s.t_ns > LEVER_GYRO_HALF_WINDOW_NS)
            {
                self.imu_behind.pop_front();
            }
        }
        if self.x.is_none() || self.gnssless {
            self.init.add_imu(
                b.t_ns,
                &b.gyro_radps,
                &b.accel_mps2,
                self.params.init_level_window_s,
            );
        }
        self.try_start_without_gnss(b.t_ns);
        self.limit_dead_reckoning(b.t_ns);
        self.hold_position(b.t_ns);
    }

    /// Integrates the nominal state to `t_ns` within the IMU interval `[a, b]`.
    fn integrate_to(&mut self, a: &ImuSample, b: &ImuSample, t_ns: i64) {
        let (Some(x), Some(frame)) = (self.x.as_mut(), self.frame.as_ref()) else {
            return;
        };
        if t_ns <= x.t_ns {
            return;
        }
        let s0 = interp(a, b, x.t_ns);
        let s1 = interp(a, b, t_ns);
        let m = mean_of(&s0, &s1);
        let dt_s = (t_ns - x.t_ns) as f64 * 1e-9;
        let g = self
            .gravity
            .get_or_insert_with(|| GravityCache::new(frame, &x.p))
            .at(frame, &x.p);
        integrate_nominal(x, &m, dt_s, &g, &self.w_ie, self.params.gnss_pos_tau_s);
        x.t_ns = t_ns;
        self.acc.dt_s += dt_s;
        self.acc.gyro_dt += m.gyro * dt_s;
        self.acc.accel_dt += m.accel * dt_s;
        if self.acc.dt_s >= self.params.cov_period_s {
            self.flush_cov();
        }
    }

    /// Propagates the covariance over the accumulated interval.
    fn flush_cov(&mut self) {
        let Some(x) = self.x.as_ref() else { return };
        if self.acc.dt_s <= 0.0 {
            return;
        }
        let dt = self.acc.dt_s;
        let mean = ImuMean {
            gyro: self.acc.gyro_dt / dt,
            accel: self.acc.accel_dt / dt,
        };
        let noise = ProcessNoise {
            gyro_psd: self.noise.gyro_psd.max(self.acc.gyro_var / dt),
            accel_psd: self.noise.accel_psd.max(self.acc.accel_var / dt),
            ..self.noise
        };
        self.gyro_psd_used = noise.gyro_psd;
        ErrorDynamics::new(x, &mean, &self.w_ie, self.params.gnss_pos_tau_s).propagate(
            &mut self.p,
            dt,
            &noise,
        );
        self.report_imu_noise(dt);
        self.acc = CovAccum::default();
    }

    fn inject(&mut self, dx: Option<ErrVec>) {
        if let (Some(mut dx), Some(x)) = (dx, self.x.as_mut()) {
            if !self.yaw_aligned {
                // An unknown heading is not estimated (see `HeadingSource::Unknown`).
                dx[ITH + 2] = 0.0;
                hold_yaw_unknown(&mut self.p);
            }
            x.inject(&dx);
            self.corrected = true;
        }
    }

    /// Handles one buffered event at the horizon (state already integrated to its time).
    fn process(&mut self, e: Event, a: &ImuSample, b: &ImuSample) {
        if self.gnssless && matches!(e, Event::Gnss(_)) {
            self.restart_for_gnss();
        }
        if let Event::Gnss(m) = &e
            && self.outage_hold()
        {
            self.end_outage_hold(m);
        }
        if let Event::Gnss(m) = &e
            && std::mem::take(&mut self.gap_fix_pending)
        {
            // What the inertial prediction across the gap got wrong is the gap's, not evidence
            // about the attitude: widened and decorrelated, as at the end of an outage.
            self.widen_to_fix(m);
        }
        if self.x.is_none() {
            if let Event::Gnss(m) = e {
                self.feed_yaw_estimator(&m);
                self.try_init(&m);
            }
            return;
        }
        self.flush_cov();
        match e {
            Event::Gnss(m) => {
                // The lever-arm rate: the gyro around the fix, with its white-noise variance per
                // axis (PSD / interval / samples averaged).
                let (gyro, n) = lever_gyro(self.imu_behind.iter().chain(self.imu.iter()), m.t_ns)
                    .unwrap_or((interp(a, b, m.t_ns).gyro_radps, 1));
                let dt_s = (b.t_ns - a.t_ns) as f64 * 1e-9;
                let gyro_var = if dt_s > 0.0 {
                    self.gyro_psd_used / dt_s / n as f64
                } else {
                    0.0
                };
                self.fuse_gnss(&m, &gyro, gyro_var);
            }
            Event::Mag(t, m_b) => self.fuse_mag(t, &m_b),
            Event::Baro(t, pressure) => self.fuse_baro(t, pressure),
            Event::CloneAt(t) => self.take_clone(t),
            Event::Ego(m) => self.fuse_vision(&m),
        }
    }

    fn try_init(&mut self, m: &GnssMeas) {
        let Some(frame) = self.frame.as_ref() else {
            return;
        };
        let g = frame.gravity_ned(&m.pos_ned_m);
        let s = correlated_sigma(m, self.params.gnss_pos_correlated_fraction);
        let gm_sigma = [s.x, s.y, s.z];
        let params = EstimatorParams {
            course_heading: self.course_heading,
            ..self.params.clone()
        };
        if let Some(r) = self.init.try_init(m, &self.lever_b, &g, &params, gm_sigma) {
            self.x = Some(r.x);
            self.p = r.p;
            self.yaw_aligned = r.yaw_aligned;
            self.heading = if r.yaw_aligned {
                HeadingSource::Course
            } else {
                hold_yaw_unknown(&mut self.p);
                HeadingSource::Unknown
            };
            self.acc = CovAccum::default();
            self.corrected = true;
            self.gnss_pos.gm_sigma_m = Some(s);
            self.noise.gm_psd = gm_psd(&s, self.params.gnss_pos_tau_s);
        }
    }

    fn fuse_baro(&mut self, t_ns: i64, pressure_pa: f64) {
        let (Some(x), Some(sigma_pa)) = (self.x, self.baro_sigma_pa) else {
            return;
        };
        // Without GNSS the first sample anchors the offset at the held height (as a GNSS height
        // would), and the barometer holds the height from then on.
        let gnss_active = self.gnss_pos.diag.active(t_ns, self.params.aid_timeout_ns)
            || (self.gnssless && self.baro.offset.is_none());
        let params = BaroParams {
            height_sigma_m: self.params.baro_height_sigma_m,
            offset_walk_m_per_sqrt_s: self.params.baro_offset_walk_m_per_sqrt_s,
            gate_sigma: self.params.gate_sigma,
        };
        let dx = self.baro.process(
            &x,
            &mut self.p,
            t_ns,
            pressure_pa,
            sigma_pa,
            gnss_active,
            &params,
        );
        self.inject(dx);
    }

    fn fuse_gnss(&mut self, m: &GnssMeas, gyro_b: &Vector3<f64>, gyro_var_radps2: f64) {
        self.feed_yaw_estimator(m);
        self.manage_heading(m);
        // The velocity at the fusion time, from its own time of validity (eq. L2).
        let mv = self.velocity_at_fusion_time(m);
        self.gnss_vel
            .observe(&mv, &self.params.gnss_vel_consistency);
        let Some(mut x) = self.x else { return };
        // The Gauss–Markov error state follows the receiver's reported accuracy, fix by fix.
        self.noise.gm_psd = self.gnss_pos.follow_accuracy(
            &mut x,
            &mut self.p,
            m,
            self.params.gnss_pos_correlated_fraction,
            self.params.gnss_pos_tau_s,
        );
        self.x = Some(x);
        let r = white_noise(
            m,
            self.params.gnss_pos_correlated_fraction,
            self.params.gnss_pos_white_min_m,
        );
        // Without a heading the horizontal inertial prediction cannot tell where the vehicle
        // went (its accelerations are rotated by a yaw that is not known), and the yaw held
        // uncorrelated at every update keeps the velocity σ from growing with that error: a GNSS
        // fix the prediction disagrees with is then no evidence against the fix. So until the
        // heading is aligned, the second fix in a row that the gate refuses is taken with an
        // inflate-and-fuse reset, as a long rejection is once aligned (counted in the sources'
        // `resets`). So is the second refused fix after an outage (`outage`): then the
        // prediction is what is in doubt, not the fix.
        let reset = if self.yaw_aligned && !self.after_outage(m.t_ns) {
            self.params.gnss_reset_timeout_ns
        } else {
            0
        };
        let gate = self.params.gate_sigma;
        let consider = self.heading_unobservable_states();
        let dx = self
            .gnss_pos
            .fuse(&x, &mut self.p, &self.lever_b, m, &r, gate, reset, consider);
        self.inject(dx);
        let Some(x) = self.x else { return };
        let dx = self.gnss_vel.fuse(
            &x,
            &mut self.p,
            &self.lever_b,
            gyro_b,
            gyro_var_radps2,
            &self.w_ie,
            &mv,
            gate,
            reset,
            consider,
        );
        self.inject(dx);
    }

    fn take_clone(&mut self, t_ns: i64) {
        if let Some(x) = self.x.as_mut() {
            x.clone = Some(PoseClone {
                t_ns,
                q: x.q,
                p: x.p,
            });
            augment_clone(&mut self.p);
        }
    }

    fn fuse_vision(&mut self, m: &Egomotion) {
        let (Some(x), Some(bfc)) = (self.x, self.body_from_cam) else {
            return;
        };
        let use_ = VisionUse {
            rotation: self.params.use_vision_rotation,
            // Without GNSS the place, and so the height above the terrain, is unknown.
            translation: self.params.use_vision_translation && !self.gnssless,
            joint: self.params.vision_joint_update,
            cov_scale: self.params.vision_cov_scale,
            gate_sigma: self.params.gate_sigma,
            scale: self.plane_scale(&x, &bfc, m),
        };
        match x.clone {
            Some(c0) if c0.t_ns == m.t0_ns && use_.joint && use_.rotation && use_.translation => {
                let dx = self.vision.fuse_joint(&x, &c0, &mut self.p, &bfc, m, &use_);
                self.inject(dx);
            }
            Some(c0) if c0.t_ns == m.t0_ns => {
                if use_.rotation {
                    let dx = self
                        .vision
                        .fuse_rotation(&x, &c0, &mut self.p, &bfc, m, &use_);
                    self.inject(dx);
                }
                if use_.translation
                    && let Some(x) = self.x
                    && let Some(c0) = x.clone
                {
                    let dx = self
                        .vision
                        .fuse_translation(&x, &c0, &mut self.p, &bfc, m, &use_);
                    self.inject(dx);
                }
            }
            _ => self.vision.no_clone += 1,
        }
        // Chain: the next egomotion normally starts at this frame.
        let needed = x.clone.map(|c| c.t_ns);
        if !needed.is_some_and(|t| self.buffer_needs_clone(t)) {
            clear_clone(&mut self.p);
            self.take_clone(m.t1_ns);
        }
    }

    /// The scale reference of a plane-scaled metric translation: the solver's distance against
    /// the clone camera's height above the configured terrain (the same Earth-surface model the
    /// motion prior used).
    fn plane_scale(
        &self,
        x: &Nominal,
        body_from_cam: &Isometry3<f64>,
        m: &Egomotion,
    ) -> Option<PlaneScale> {
        let (Some(prior_distance_m), Some(c0), Some(frame)) =
            (m.scale_distance_m, x.clone, self.frame.as_ref())
        else {
            return None;
        };
        let centre = c0.p + c0.q * body_from_cam.translation.vector;
        let distance_m = crate::motion_prior::terrain_distance_m(
            frame,
            &centre,
            self.config.terrain_elevation_m,
        );
        PlaneScale::new(prior_distance_m, distance_m)
    }

    fn buffer_needs_clone(&self, t0_ns: i64) -> bool {
        // A pending egomotion from the current clone's time still needs that clone.
        self.buffer_pending_ego_t0().contains(&t0_ns)
    }

    fn buffer_pending_ego_t0(&self) -> Vec<i64> {
        self.buffer.pending_ego_t0()
    }
}
