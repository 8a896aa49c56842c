//! Profile `paper`: the three-EKF architecture of the paper (section V, Fig. 1), kept as documented:
//! Euler-angle attitude and the three-filter split, no bias states, no delay compensation beyond a
//! short attitude history for the late video.
//!
//! | module | filter |
//! |---|---|
//! | [`attitude`] | VIDEO-IMU(1): Euler angles from gyro rates (eq. 31) + video pseudo-attitude (eq. 34) |
//! | [`posvel`] | GPS-IMU (eqs. 29, 30, 32, 33) and VIDEO-IMU(2) (eq. 35): position/velocity EKFs |
//! | this file | the three filters' state, IMU stepping, GNSS fixes, alignment, divergence check |
//! | `alignment` | the alignment from GNSS: tilt and course pseudo-measurements, when it has settled |
//! | [`gnss_tilt`] | our addition: roll/pitch from the GNSS acceleration while no video chain runs |
//! | [`heading`] | our addition: a multirotor's heading from the yaw-hypothesis bank |
//! | `gnssless` | our addition: attitude only until the first usable fix |
//! | `video` | egomotion in: eq. (34), eq. (D1) while GNSS is fused, eq. (35) in outages |
//! | `report` | motion prior, health and the pose output with its stated σ |
//!
//! Where the attitude comes from (our reading of sections V–VI):
//! - Alignment (the "initial known value" of eq. 34): from the first fix, roll/pitch from the
//!   accelerometers compensated by the GNSS acceleration and yaw from the GNSS course (no
//!   sideslip, from the GNSS velocity with the lever-arm velocity removed), fused at every fix
//!   (tilt σ that of the GNSS acceleration, at least 2°; course σ from the velocity σ over the
//!   speed, and, with `paper_gnss_tilt`, from the roll and pitch σ it is solved at: eq. C1) until
//!   every attitude σ is below `paper_video_start_sigma_rad` (about 2 s), then never again.
//! - After that, GNSS reaches the attitude only through the lever arm of eqs. (32)–(33): the
//!   GNSS update is linearized in the Euler angles too (`posvel::PosVelEkf::update_gnss`), so with a
//!   big lever arm the attitude stays observable and with a small one it is nearly gyro
//!   integration, as in section VI.
//! - With video, the eq. (34) pseudo-attitude starts from the aligned attitude and is fused with
//!   its accumulated error as a state (see [`attitude`]).
//! - Beyond the paper (our addition, `EstimatorParams::paper_video_direction`): while GNSS
//!   velocity is fused, the video's direction of travel rotated into NED with the attitude is
//!   compared with the direction of the GNSS-IMU velocity (eq. D1, [`attitude`]), which observes
//!   heading and pitch whatever the lever arm. During outages the direction goes to VIDEO-IMU(2).
//!
//! - Beyond the paper (our addition, `EstimatorParams::paper_gnss_tilt`): while no video
//!   pseudo-attitude chain runs, roll and pitch are fused from the GNSS acceleration against the
//!   accelerometers over windows of about a second ([`gnss_tilt`]); the alignment then takes only
//!   the course from GNSS.
//!
//! - Beyond the paper (our addition, `EstimatorParams::paper_yaw_bank`): a vehicle whose course
//!   is not its heading (a multirotor) takes its heading from the yaw-hypothesis bank once that
//!   has converged ([`heading`]).
//!
//! The un-modelled gyro bias is covered by extra process noise (with `paper_gnss_tilt`, a bias
//! learnt from the windows' corrections is also taken off the gyro).

mod alignment;
pub mod attitude;
pub mod gnss_tilt;
mod gnssless;
pub mod heading;
mod outage;
pub mod posvel;
mod report;
mod video;

use std::collections::VecDeque;

use nalgebra::{Isometry3, Matrix3, Vector3};
use uavnav_core::{Egomotion, GnssFix, ImuSample, Lla, LocalFrame, MotionPrior, VehicleConfig};

use crate::aid_sources::gnss_pos::GnssMeas;
use crate::health::{Health, Mode};
use crate::init::attitude_from_gravity;
use crate::output::{AidingFlags, PoseOutput};
use crate::output_predictor::mean_of;
use crate::params::EstimatorParams;
use crate::prediction::{GravityCache, ImuMean, earth_rate_ned};
pub use alignment::{
    SETTLE_SPAN_NS, SETTLED_MAX_SIGMA_RAD, SETTLED_SHRINK, heading_without_sideslip,
};
use alignment::{alignment_settled, course_sigma_rad, gnss_attitude_aiding};
use attitude::{AttitudeEkf, DirectionMeas};
use outage::track_unaided_turn;
use posvel::PosVelEkf;

/// Window of the mean body rate used in the lever-arm velocity of eq. (33), ns.
const GYRO_MEAN_NS: i64 = 100_000_000;
/// No GNSS for this long activates VIDEO-IMU(2), ns.
const OUTAGE_AFTER_NS: i64 = 1_000_000_000;
/// Least σ of the GNSS-derived tilt pseudo-measurement of the alignment, rad: the GNSS
/// acceleration differenced from two fixes (0.05 m/s over 0.2 s, 0.35 m/s²) over g; a noisier
/// receiver's own figure when larger.
const GNSS_TILT_SIGMA_RAD: f64 = 0.035;
/// σ of the held speed of eq. (35) at the start of an outage, m/s, and its growth, m/s per s.
const SPEED_SIGMA_MPS: f64 = 0.3;
const SPEED_SIGMA_GROWTH_MPS_PER_S: f64 = 0.02;
/// The eq. (D1) direction measurement needs a GNSS velocity fused within this, ns: its reference
/// direction is the GNSS-IMU velocity, which coasts on the inertial sensors without GNSS.
const D1_GNSS_VEL_RECENT_NS: i64 = 500_000_000;
/// History of the GNSS-IMU velocity kept for eq. (D1) (the video arrives ~50 ms after frame 1 and
/// covers the 0.1 s before), ns.
const VEL_HISTORY_NS: i64 = 1_000_000_000;

/// The paper's three filters.
#[derive(Debug, Clone)]
pub struct PaperFilter {
    params: EstimatorParams,
    lever_b: Vector3<f64>,
    body_from_cam: Option<Isometry3<f64>>,
    gyro_psd: f64,
    /// The IMU's turn-on gyro bias σ, rad/s (`paper_unknown_gyro_bias_sigma_radps` when the
    /// configuration states none): see `AttitudeEkf::predict`.
    gyro_bias_sigma_radps: f64,
    accel_psd: f64,
    /// Gyro and accelerometer noise PSDs the data itself shows (see `observe_imu_noise`),
    /// smoothed over [`OBSERVED_NOISE_WINDOW_S`].
    observed_psd: (f64, f64),
    origin: Option<Lla>,
    frame: Option<LocalFrame>,
    w_ie: Vector3<f64>,
    gravity: Option<GravityCache>,
    imu: VecDeque<ImuSample>,
    att: Option<AttitudeEkf>,
    gps_imu: Option<PosVelEkf>,
    vio2: Option<PosVelEkf>,
    last_speed_mps: f64,
    /// The correlated part of the last fix's position variance (N, E, D), m²:
    /// `gnss_pos_correlated_fraction` of its reported variance. GPS-IMU takes the fixes as white
    /// (the paper's filter has no state for their slow error), so averaging them shrinks its
    /// position variance below what the fixes can give; the stated σ and the start of
    /// VIDEO-IMU(2) are kept at least this (without it, 50 % of the simulated flights' positions
    /// were within 3σ).
    gnss_correlated_var: Vector3<f64>,
    /// GNSS-IMU velocity after each IMU sample (NED, m/s), for the mean velocity of eq. (D1).
    vel_hist: VecDeque<(i64, Vector3<f64>)>,
    last_fix: Option<(GnssMeas, Vector3<f64>)>,
    f_sum: (Vector3<f64>, u32),
    init_f: VecDeque<Vector3<f64>>,
    health: Health,
    /// Diagnostics of the GNSS-derived attitude aiding of the alignment.
    gnss_att_diag: crate::aid_sources::InnovDiag,
    /// Fixes left out because they carried no velocity (this profile needs one).
    fixes_without_velocity: u64,
    /// The alignment is over (every attitude σ fell below `paper_video_start_sigma_rad`).
    aligned: bool,
    /// The stated accelerometer turn-on bias as acceleration noise of GPS-IMU, (m/s²)²/s.
    accel_bias_psd: f64,
    /// The alignment has settled above that σ ([`alignment_settled`]): the video may start
    /// while the alignment's GNSS aiding goes on.
    settled: bool,
    /// The largest attitude variance at the start of the current settling span: time, rad².
    settle_check: Option<(i64, f64)>,
    /// The GNSS course may be taken as the heading (a fixed wing, or `EstimatorParams::
    /// course_heading`): a multirotor's course says nothing of its heading.
    course_heading: bool,
    /// Consecutive fixes at which the attitude's roll or pitch disagreed with the accelerometer's
    /// tilt (GNSS-acceleration compensated) by more than [`DIVERGED_TILT_RAD`].
    tilt_disagree: u32,
    /// Restarts after a detected divergence (kept across them).
    divergence_resets: u32,
    /// Roll and pitch from the GNSS acceleration (`gnss_tilt`, our addition).
    gnss_tilt: gnss_tilt::GnssTilt,
    /// The heading from the yaw-hypothesis bank (`heading`, our addition).
    heading: heading::BankHeading,
    /// The configuration has a receiver (without one the start without GNSS is at once).
    has_gnss: bool,
    /// Time of the first IMU sample, ns (the wait before starting without GNSS).
    first_imu_t_ns: Option<i64>,
    /// Running without GNSS (`gnssless`, our addition): attitude only.
    gnssless: bool,
    /// Roll and pitch held against a velocity held at zero through an outage (`outage`, our
    /// addition).
    outage_tilt_hold: bool,
    /// Angle turned about the vertical since the heading was last observed, rad (`outage`).
    unaided_turn_rad: f64,
    /// The frame is `gnssless`'s provisional one (no origin configured, no fix yet).
    frame_provisional: bool,
}

/// Roll or pitch this far from the accelerometer's tilt (with the GNSS acceleration removed) for
/// [`DIVERGED_FIXES`] fixes in a row means the Euler-angle filter has diverged, rad. Far beyond
/// what a banked turn's un-modelled acceleration gives once the GNSS acceleration is removed.
pub const DIVERGED_TILT_RAD: f64 = 0.436; // 25°
/// Fixes in a row (≈ 2 s at 5 Hz) of tilt disagreement that restart the filters.
pub const DIVERGED_FIXES: u32 = 10;
/// Time constant of the smoothing of the observed IMU noise, s.
pub const OBSERVED_NOISE_WINDOW_S: f64 = 0.5;

/// The process noise the IMU data itself shows, as the `eskf` profile takes it
/// ([`crate::prediction::interval_noise_var`] per interval, divided by its length to give a
/// PSD), smoothed over [`OBSERVED_NOISE_WINDOW_S`] (a per-sample maximum would inflate white
/// noise by its own spread) and used where it exceeds the configured densities. The paper leaves
/// the process noise to the designer; with datasheet values its attitude σ on the shared real
/// plane was 3σ-consistent in 46 % of the rows. Returns the gyro and accelerometer PSDs to use.
fn observe_imu_noise(
    observed: &mut (f64, f64),
    a: &ImuSample,
    b: &ImuSample,
    dt_s: f64,
    gyro_psd: f64,
    accel_psd: f64,
) -> (f64, f64) {
    if dt_s.is_finite() && dt_s > 0.0 {
        let (g, f) = crate::prediction::interval_noise_var(a, b, dt_s);
        let k = (dt_s / OBSERVED_NOISE_WINDOW_S).min(1.0);
        observed.0 += k * (g / dt_s - observed.0);
        observed.1 += k * (f / dt_s - observed.1);
    }
    (gyro_psd.max(observed.0), accel_psd.max(observed.1))
}

impl PaperFilter {
    /// The three filters for one vehicle.
    pub fn new(config: &VehicleConfig, params: EstimatorParams, origin: Option<Lla>) -> Self {
        let course_heading =
            params.course_heading || config.airframe == uavnav_core::Airframe::FixedWing;
        let heading = heading::BankHeading::new(
            params.yaw_estimator,
            params.paper_yaw_bank && !course_heading,
        );
        // The accelerometer's turn-on bias, which this profile has no state for: between two
        // fixes a constant error `b` adds `b Δt` to the velocity, as white noise of PSD `b² Δt`
        // (Δt the fix interval). Only a stated bias: a flight log states none.
        let fix_interval_s = config.gnss.map_or(0.2, |g| 1.0 / g.rate_hz.max(0.1));
        let accel_bias_psd = config.imu.accel_bias_sigma_mps2.powi(2) * fix_interval_s;
        let gyro_bias_sigma_radps = match config.imu.gyro_bias_sigma_radps {
            s if s > 0.0 => s,
            _ => params.paper_unknown_gyro_bias_sigma_radps,
        };
        let mut s = Self {
            params,
            lever_b: config
                .gnss
                .map(|g| g.lever_arm_body_m)
                .unwrap_or_else(Vector3::zeros),
            body_from_cam: config.camera.as_ref().map(|c| c.body_from_cam),
            gyro_psd: config.imu.gyro_noise_density.powi(2),
            accel_bias_psd,
            gyro_bias_sigma_radps,
            accel_psd: config.imu.accel_noise_density.powi(2),
            observed_psd: (0.0, 0.0),
            origin,
            frame: None,
            w_ie: Vector3::zeros(),
            gravity: None,
            imu: VecDeque::new(),
            att: None,
            gps_imu: None,
            vio2: None,
            last_speed_mps: 0.0,
            gnss_correlated_var: Vector3::zeros(),
            vel_hist: VecDeque::new(),
            last_fix: None,
            f_sum: (Vector3::zeros(), 0),
            init_f: VecDeque::new(),
            health: Health::default(),
            gnss_att_diag: crate::aid_sources::InnovDiag::new(),
            fixes_without_velocity: 0,
            aligned: false,
            settled: false,
            settle_check: None,
            course_heading,
            tilt_disagree: 0,
            divergence_resets: 0,
            gnss_tilt: gnss_tilt::GnssTilt::new(gyro_bias_sigma_radps, config.imu.gyro_random_walk),
            heading,
            has_gnss: config.gnss.is_some(),
            first_imu_t_ns: None,
            gnssless: false,
            outage_tilt_hold: false,
            unaided_turn_rad: 0.0,
            frame_provisional: false,
        };
        if let Some(o) = origin {
            s.set_frame(o);
        }
        s
    }

    fn set_frame(&mut self, o: Lla) {
        self.frame = Some(LocalFrame::new(o));
        self.w_ie = earth_rate_ned(o.lat_rad);
    }

    /// Back to the state right after `new`.
    pub fn reset(&mut self) {
        let cfg_frame = self.origin;
        let mut fresh = self.clone();
        fresh.frame = None;
        fresh.gravity = None;
        fresh.imu.clear();
        fresh.att = None;
        fresh.gps_imu = None;
        fresh.vio2 = None;
        fresh.last_speed_mps = 0.0;
        fresh.vel_hist.clear();
        fresh.last_fix = None;
        fresh.f_sum = (Vector3::zeros(), 0);
        fresh.init_f.clear();
        fresh.health = Health::default();
        fresh.aligned = false;
        fresh.fixes_without_velocity = 0;
        fresh.tilt_disagree = 0;
        fresh.divergence_resets = 0;
        fresh.observed_psd = (0.0, 0.0);
        fresh.gnss_tilt = self.gnss_tilt.restarted();
        fresh.heading.restart();
        fresh.first_imu_t_ns = None;
        fresh.gnssless = false;
        fresh.outage_tilt_hold = false;
        fresh.unaided_turn_rad = 0.0;
        fresh.frame_provisional = false;
        *self = fresh;
        if let Some(o) = cfg_frame {
            self.set_frame(o);
        }
    }

    /// Bytes held by the attitude history.
    pub fn buffered_bytes(&self) -> usize {
        self.imu.capacity() * size_of::<ImuSample>()
    }

    /// IMU sample: propagates all three filters (eqs. 29–31).
    pub fn push_imu(&mut self, s: &ImuSample) -> Option<PoseOutput> {
        let prev = self.imu.back().copied();
        self.imu.push_back(*s);
        while self.imu.len() >= crate::buffer::MAX_IMU_HISTORY
            || self
                .imu
                .front()
                .is_some_and(|f| s.t_ns - f.t_ns > 2_000_000_000)
        {
            self.imu.pop_front();
        }
        self.f_sum.0 += s.accel_mps2;
        self.f_sum.1 += 1;
        // Also while running without GNSS: the first fix then levels from the latest window,
        // as it would have had the filters waited for it.
        if self.att.is_none() || self.gnssless {
            self.init_f.push_back(s.accel_mps2);
            let keep = (self.params.init_level_window_s * 200.0).max(10.0) as usize;
            while self.init_f.len() > keep {
                self.init_f.pop_front();
            }
        }
        if self.att.is_none() {
            self.try_start_without_gnss(s.t_ns);
        }
        let (Some(prev), Some(frame)) = (prev, self.frame) else {
            return None;
        };
        if self.gnssless {
            return self.step_gnssless(&prev, s, &frame);
        }
        // Both filters run from the first fix (before it, only without GNSS, above).
        self.gps_imu.as_ref()?;
        let (m, gyro, accel_psd, dt_s) = self.predict_attitude(&prev, s)?;
        let (Some(att), Some(gi)) = (self.att.as_mut(), self.gps_imu.as_mut()) else {
            return None;
        };
        self.heading.add_imu(&gyro, &m.accel, dt_s);
        let c = att.rotation();
        let observed = att.video_active()
            || self
                .last_fix
                .is_some_and(|(f, _)| s.t_ns - f.t_ns <= self.params.aid_timeout_ns);
        track_unaided_turn(&mut self.unaided_turn_rad, observed, &(c * gyro), dt_s);
        let att_var = att.p_euler().trace() / 3.0;
        let g = self
            .gravity
            .get_or_insert_with(|| GravityCache::new(&frame, &gi.x))
            .at(&frame, &gi.x);
        let q_acc = accel_psd + m.accel.norm_squared() * att_var + self.accel_bias_psd;
        gi.predict(&c, &m.accel, &g, &self.w_ie, dt_s, q_acc);
        if self.params.is_bridged_gap(prev.t_ns, s.t_ns) {
            // A gap `Estimator` chose to bridge: eq. G1, as `eskf` does. The tilt window that
            // spans it compares velocities the gap's integration cannot vouch for: dropped.
            let [att_g, vel_g, pos_g] =
                crate::prediction::gap_variances(&self.params, &prev, s, dt_s);
            att.widen_tilt(att_g);
            att.widen_yaw(att_g);
            for k in 0..3 {
                gi.p[(k, k)] += pos_g;
                gi.p[(3 + k, 3 + k)] += vel_g;
            }
            self.gnss_tilt.drop_window();
        }
        self.gnss_tilt.add_imu(&c, &m.accel, accel_psd, dt_s);
        self.vel_hist.push_back((s.t_ns, gi.v));
        while self
            .vel_hist
            .front()
            .is_some_and(|h| s.t_ns - h.0 > VEL_HISTORY_NS)
        {
            self.vel_hist.pop_front();
        }
        let outage = self
            .last_fix
            .is_some_and(|(f, _)| s.t_ns - f.t_ns > OUTAGE_AFTER_NS);
        if outage {
            // VIDEO-IMU(2) starts from the GPS-IMU state at the start of the outage.
            let corr = self.gnss_correlated_var;
            let v2 = self.vio2.get_or_insert_with(|| {
                let mut v2 = gi.clone();
                v2.floor_position(&corr);
                v2
            });
            // Through the outage nothing bounds the velocity error that a slowly varying attitude
            // error builds up: it enters with its long-run PSD (see
            // `EstimatorParams::paper_attitude_error_tau_s`). GPS-IMU keeps the white allowance:
            // GNSS corrects its velocity within seconds, and a larger allowance there would
            // explain the lever-arm velocity residuals by the velocity instead of the attitude
            // (big-lever GNSS-only yaw 0.17 → 0.50°, the paper's observability result lost).
            let att_psd_factor = (2.0 * self.params.paper_attitude_error_tau_s).max(1.0);
            let q_outage = accel_psd + m.accel.norm_squared() * att_var * att_psd_factor;
            v2.predict(&c, &m.accel, &g, &self.w_ie, dt_s, q_outage);
        } else {
            self.vio2 = None;
        }
        self.hold_tilt_in_outage(s.t_ns, &frame);
        self.output(s.t_ns)
    }

    /// Whether an IMU gap can be bridged (`Estimator::bridges`): both filters running, with GNSS.
    pub fn can_bridge(&self) -> bool {
        self.att.is_some() && self.gps_imu.is_some() && !self.gnssless
    }

    /// VIDEO-IMU(1)'s prediction over one IMU interval (eq. 31), with the process noise the data
    /// shows and the learnt gyro bias taken off. Returns the interval's mean sample, the gyro
    /// used, the accelerometer PSD and the interval, s; `None` before the filter starts.
    fn predict_attitude(
        &mut self,
        prev: &ImuSample,
        s: &ImuSample,
    ) -> Option<(ImuMean, Vector3<f64>, f64, f64)> {
        let att = self.att.as_mut()?;
        let m = mean_of(prev, s);
        let dt_s = (s.t_ns - prev.t_ns) as f64 * 1e-9;
        let (gyro_psd, accel_psd) = if self.params.is_bridged_gap(prev.t_ns, s.t_ns) {
            // A bridged gap: the samples either side of it say nothing of the IMU's noise, and
            // eq. G1 widens for what the gap hid (`push_imu`).
            (
                self.gyro_psd.max(self.observed_psd.0),
                self.accel_psd.max(self.observed_psd.1),
            )
        } else {
            observe_imu_noise(
                &mut self.observed_psd,
                prev,
                s,
                dt_s,
                self.gyro_psd,
                self.accel_psd,
            )
        };
        let gyro = m.gyro - self.gnss_tilt.gyro_bias_radps();
        att.predict(
            &gyro,
            &self.w_ie,
            dt_s,
            gyro_psd + self.params.paper_gyro_instability_psd,
            self.gyro_bias_sigma_radps,
            s.t_ns,
        );
        Some((m, gyro, accel_psd, dt_s))
    }

    /// GNSS fix: GPS-IMU update (eqs. 32–33), attitude aiding without video, initialisation.
    pub fn push_gnss(&mut self, fix: &GnssFix) {
        let lla = Lla::from_deg(fix.lat_deg, fix.lon_deg, fix.alt_m);
        if fix.velocity.is_some() {
            self.leave_gnssless();
        }
        if self.frame.is_none() {
            self.set_frame(lla);
        }
        let Some(frame) = self.frame else { return };
        let meas = GnssMeas::from_fix(fix, frame.lla_to_ned(&lla));
        // The paper's GPS-IMU filter (eqs. 32–33) fuses position and velocity together and aligns
        // from the velocity: a fix without one is counted and left out of this profile. Without
        // its vertical component (ground speed and course) the vertical is taken as 0 here, for
        // the alignment and the GNSS acceleration, and left unmeasured in eq. (33).
        let Some(meas_vel) = fix_velocity(&meas) else {
            self.fixes_without_velocity += 1;
            return;
        };
        self.end_outage_tilt_hold();
        self.widen_yaw_for_unaided_turn();
        let f_mean = if self.f_sum.1 > 0 {
            self.f_sum.0 / self.f_sum.1 as f64
        } else {
            Vector3::zeros()
        };
        self.f_sum = (Vector3::zeros(), 0);
        // Body rate for the lever-arm velocity of eq. (33) AT the fix time: a straight line fitted
        // to the last 0.1 s of gyro samples, evaluated at the fix (one raw sample's noise times a
        // 10 m lever arm is a third of the GNSS velocity σ). The plain mean over that window
        // refers to 50 ms before the fix: entering or leaving a banked turn (roll accelerations of
        // ~0.2 rad/s²) that lag is ~0.01 rad/s, i.e. 0.1–0.2 m/s through a 17 m lever arm, 2–4× the
        // velocity σ, and the filter reads it as attitude error.
        let recent: Vec<_> = self
            .imu
            .iter()
            .rev()
            .filter(|s| s.t_ns <= fix.t_ns)
            .take_while(|s| fix.t_ns - s.t_ns < GYRO_MEAN_NS)
            .map(|s| ((s.t_ns - fix.t_ns) as f64 * 1e-9, s.gyro_radps))
            .collect();
        let gyro = match (recent.len(), self.imu.back()) {
            (0, Some(s)) => s.gyro_radps,
            (0, None) => Vector3::zeros(),
            (n, _) => rate_at_zero(&recent, n),
        };
        // The GNSS acceleration from two fixes and its 1-σ per axis (two velocities' noise over
        // the interval: 0.35 m/s² for 0.05 m/s at 5 Hz, 2 m/s² for 0.3 m/s).
        let (a_n, a_n_sigma) = match self.last_fix {
            Some((p, _)) if meas.t_ns > p.t_ns && meas.t_ns - p.t_ns < 2_000_000_000 => {
                let dt_s = (meas.t_ns - p.t_ns) as f64 * 1e-9;
                let a = (meas_vel - fix_velocity(&p).unwrap_or(meas_vel)) / dt_s;
                (a, std::f64::consts::SQRT_2 * meas.sigma_vel_mps / dt_s)
            }
            _ => (Vector3::zeros(), 0.0),
        };
        self.last_fix = Some((meas, a_n));
        let g = frame.gravity_ned(&meas.pos_ned_m);
        if self.att.is_none() {
            self.try_init(&meas, &meas_vel, &g, (&a_n, a_n_sigma), &gyro);
            return;
        }
        if self.diverged(&f_mean, &(g - a_n)) {
            // Restart from the next fixes (same frame), counted and visible as Initialising.
            let (resets, frame) = (self.divergence_resets + 1, self.frame);
            let yaw_resets = self.heading.resets;
            self.reset();
            self.frame = frame;
            self.divergence_resets = resets;
            self.heading.resets = yaw_resets;
            return;
        }
        let start_var = self.params.paper_video_start_sigma_rad.powi(2);
        if let Some(att) = self.att.as_mut()
            && !self.aligned
        {
            let var = att.p_euler().diagonal().max();
            // Only where the course gives the heading (a fixed wing): on the simulated
            // multirotor with a consumer IMU, whose heading comes from the yaw bank, a chain
            // started from the settled alignment left the attitude overconfident (75.6 % within
            // 3σ against 100 % without the chain, for roll / pitch / yaw RMSE 0.20 / 0.26 /
            // 0.73° against 1.25 / 1.07 / 6.9°).
            self.settled = self.settled
                || (self.course_heading
                    && alignment_settled(&mut self.settle_check, meas.t_ns, var));
            if var <= start_var {
                self.aligned = true;
            } else if f_mean.norm() > 1.0 {
                // The course is that of the vehicle, not of the antenna: remove the lever-arm
                // velocity C (ω × r) of eq. (33) (0.35 m/s for 2 m at 10 °/s, 0.7° of course).
                let w_nb = gyro - att.rotation().transpose() * self.w_ie;
                let v_body = meas_vel - att.rotation() * w_nb.cross(&self.lever_b);
                let course_sigma = course_sigma_rad(meas.sigma_vel_mps, &v_body);
                // With `paper_gnss_tilt`, roll and pitch come from its windows (honest about the
                // GNSS acceleration's noise, which over one fix interval is several degrees on
                // real receivers); the alignment keeps the course.
                let tilt_sigma = if self.params.paper_gnss_tilt {
                    None
                } else {
                    Some(GNSS_TILT_SIGMA_RAD.max((a_n_sigma / g.norm()).atan()))
                };
                gnss_attitude_aiding(
                    att,
                    &f_mean,
                    &(g - a_n),
                    &v_body,
                    tilt_sigma,
                    course_sigma,
                    if self.course_heading {
                        self.params.init_min_speed_mps
                    } else {
                        f64::INFINITY
                    },
                    self.params.gate_sigma,
                    &mut self.gnss_att_diag,
                );
            }
        }
        let (Some(att), Some(gi)) = (self.att.as_mut(), self.gps_imu.as_mut()) else {
            return;
        };
        self.heading.at_fix(
            meas.t_ns,
            meas.vel_h_mps.unwrap_or_else(|| meas_vel.xy()),
            meas.sigma_vel_mps,
            att,
        );
        let w_nb = gyro - att.rotation().transpose() * self.w_ie;
        let gate = self.params.gate_sigma;
        if self.params.paper_gnss_tilt {
            let fix = gnss_tilt::TiltFix {
                t_ns: meas.t_ns,
                vel_ned_mps: meas_vel - att.rotation() * w_nb.cross(&self.lever_b),
                sigma_vel_mps: meas.sigma_vel_mps,
                g_ned: g,
                w_ie: self.w_ie,
            };
            let video = att.video_active();
            self.gnss_tilt.at_fix(&fix, att, video, gate);
        }
        // After an outage the prediction is what is in doubt: the second refused fix resets
        // (as `eskf` does; our addition), not a 5 s run of them.
        let last_fused = self.health.gnss_pos.last_fused_t_ns;
        let after_outage =
            last_fused != i64::MIN && meas.t_ns - last_fused > self.params.aid_timeout_ns;
        gi.update_gnss(
            &meas,
            att,
            &self.lever_b,
            &w_nb,
            gate,
            if after_outage {
                0
            } else {
                self.params.gnss_reset_timeout_ns
            },
            &mut self.health.gnss_pos,
            &mut self.health.gnss_vel,
        );
        self.last_speed_mps = gi.v.norm();
        let f = self.params.gnss_pos_correlated_fraction;
        self.gnss_correlated_var =
            Vector3::new(meas.sigma_h_m, meas.sigma_h_m, meas.sigma_v_m).map(|s| f * s * s);
    }

    /// The divergence check: roll or pitch far from the accelerometer's tilt for
    /// [`DIVERGED_FIXES`] fixes in a row.
    fn diverged(&mut self, f_mean: &Vector3<f64>, g_app_n: &Vector3<f64>) -> bool {
        let Some(att) = self.att.as_ref() else {
            return false;
        };
        let non_finite = !att.euler.iter().all(|v| v.is_finite());
        // Only where the accelerometer measures the apparent gravity (not in free fall or a
        // violent manoeuvre).
        let ratio = f_mean.norm() / g_app_n.norm().max(1e-6);
        if !non_finite && !(0.8..1.2).contains(&ratio) {
            return false;
        }
        let far = non_finite
            || attitude_from_gravity(f_mean, g_app_n, att.euler.z).is_some_and(|q| {
                let (r, p, _) = q.euler_angles();
                let d = |a: f64, b: f64| {
                    ((a - b + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                        - std::f64::consts::PI)
                        .abs()
                };
                d(r, att.euler.x) > DIVERGED_TILT_RAD || d(p, att.euler.y) > DIVERGED_TILT_RAD
            });
        self.tilt_disagree = if far { self.tilt_disagree + 1 } else { 0 };
        self.tilt_disagree >= DIVERGED_FIXES
    }

    /// The heading from the yaw-hypothesis bank (`heading`, our addition): its state, test ratio
    /// and resets (diagnostics and tests).
    pub fn heading_source(&self) -> &heading::BankHeading {
        &self.heading
    }

    /// Restarts after a detected divergence so far.
    pub fn divergence_resets(&self) -> u32 {
        self.divergence_resets
    }

    /// Enough specific force for the levelling (most of `init_level_window_s` at 200 Hz).
    fn levelling_window_full(&self) -> bool {
        (self.init_f.len() as f64) >= 0.8 * self.params.init_level_window_s * 200.0
    }

    fn try_init(
        &mut self,
        meas: &GnssMeas,
        meas_vel: &Vector3<f64>,
        g: &Vector3<f64>,
        (a_n, a_n_sigma): (&Vector3<f64>, f64),
        gyro: &Vector3<f64>,
    ) {
        if !self.levelling_window_full() {
            return;
        }
        let f_b = self.init_f.iter().sum::<Vector3<f64>>() / self.init_f.len() as f64;
        let moving = meas_vel.xy().norm() >= self.params.init_min_speed_mps;
        let yaw = if moving {
            meas_vel.y.atan2(meas_vel.x)
        } else {
            0.0
        };
        let Some(q) = attitude_from_gravity(&f_b, &(g - a_n), yaw) else {
            return;
        };
        let (r, p, y) = q.euler_angles();
        let yaw_sigma = if moving {
            self.params.init_yaw_sigma_rad
        } else {
            crate::init::UNALIGNED_YAW_SIGMA_RAD
        };
        // The levelling takes the GNSS acceleration off the specific force: its noise is tilt
        // (a receiver 0.3 m/s noisy at 5 Hz: 12°, which the bare 2° of the parameter made a
        // 17° roll error at 2σ... 8σ).
        let tilt = self
            .params
            .init_tilt_sigma_rad
            .hypot((a_n_sigma / g.norm()).atan());
        let att = AttitudeEkf::new(
            Vector3::new(r, p, y),
            Vector3::new(tilt, tilt, yaw_sigma),
            meas.t_ns,
        );
        let c = att.rotation();
        let pos = meas.pos_ned_m - c * self.lever_b;
        let vel = meas_vel - c * gyro.cross(&self.lever_b);
        let mut gi = PosVelEkf::new(
            pos,
            vel,
            Vector3::new(meas.sigma_h_m, meas.sigma_h_m, meas.sigma_v_m),
            meas.sigma_vel_mps * 2.0,
        );
        if meas.vel_ned_mps.is_none() {
            let var = crate::init::UNKNOWN_VERTICAL_VELOCITY_SIGMA_MPS.powi(2);
            gi.p[(5, 5)] = gi.p[(5, 5)].max(var);
        }
        self.gps_imu = Some(gi);
        self.att = Some(att);
    }
}

/// The fix's velocity as this profile takes it: the receiver's 3-D one, or its horizontal one
/// with the vertical taken as 0 (ground speed and course only); `None` without a velocity.
fn fix_velocity(meas: &GnssMeas) -> Option<Vector3<f64>> {
    meas.vel_ned_mps
        .or_else(|| meas.vel_h_mps.map(|h| Vector3::new(h.x, h.y, 0.0)))
}

/// Least-squares line through `(t, ω)` samples (t ≤ 0, s) evaluated at t = 0; the mean when the
/// samples span no time.
fn rate_at_zero(samples: &[(f64, Vector3<f64>)], n: usize) -> Vector3<f64> {
    let nf = n as f64;
    let t_mean = samples.iter().map(|s| s.0).sum::<f64>() / nf;
    let w_mean = samples.iter().map(|s| s.1).sum::<Vector3<f64>>() / nf;
    let stt: f64 = samples.iter().map(|s| (s.0 - t_mean).powi(2)).sum();
    if stt <= 0.0 {
        return w_mean;
    }
    let slope = samples
        .iter()
        .map(|s| (s.1 - w_mean) * (s.0 - t_mean))
        .sum::<Vector3<f64>>()
        / stt;
    w_mean - slope * t_mean
}
