//! Magnetometer heading: the azimuth of the measured field rotated into NED with the filter's
//! attitude, against the local declination of the world magnetic model (WMM2025, `uavnav_core::
//! magnetic`).
//!
//! Why heading only, not the 3-axis field: real compasses are imperfectly calibrated — on the
//! shared ArduPilot flights the field's direction matches the model (inclination 58.2° against
//! 58.1°) while its strength is 0.6–0.8 of it — and the motors disturb it by several degrees. The
//! azimuth of the horizontal component does not depend on the strength, and tilt errors enter
//! through the Jacobian below, so nothing the model cannot know is trusted.
//!
//! Measurement (eq. M1): `α = atan2(m_E, m_N)` with `m = C m_b`, `C = nav_from_body`; with the
//! global attitude error `δθ` (`C ← exp(δθ) C`), `δm = δθ × m = −[m]× δθ`, and
//! `∂α/∂m = [−m_E, m_N, 0] / (m_N² + m_E²)`, so `H_θ = ∂α/∂m · (−[m]×)` (the yaw column is 1,
//! the tilt columns carry the inclination coupling). The residual is `y = D − α` wrapped to ±π.
//!
//! Lifecycle:
//! * **off** until a sample arrives; **stopped** for good when the sensor is dead (a field below
//!   [`DEAD_FIELD_T`] for [`DEAD_SAMPLES`] samples in a row, e.g. a compass reading all zeros);
//! * a sample is **disturbed** (diagnosed, not fused) when its inclination through the filter's
//!   tilt is more than `mag_max_inclination_error_rad` from the model's, when its strength is
//!   implausible against the model's ([`STRENGTH_RATIO_RANGE`], wide: compass scales are often
//!   far off — 0.15 to 1.8 of the model on public ArduPilot flights), or when it strays more than
//!   [`STRENGTH_DEVIATION`] from the compass's **own** typical strength (learnt in flight: a
//!   motor current or a steel structure changes it; a scale error does not), or its inclination
//!   more than `mag_max_inclination_error_rad` from the compass's own typical inclination; the
//!   typical inclination may sit off the model's (a hard-iron offset the calibration left) by up
//!   to [`MAX_STATIC_INCLINATION_ERROR_RAD`] more, and widens the heading σ by as much;
//! * **aligning**: the heading is taken from the compass only once [`ALIGN_SAMPLES`] consistent
//!   samples in a row imply the same heading within [`ALIGN_SPREAD_RAD`];
//! * **stopped** for good, too, when the heading it gives keeps contradicting a converged yaw
//!   bank (`Eskf::check_mag_against_bank`): a compass that is consistently wrong (a bad
//!   calibration, a mounting error) must not hold the filter confidently wrong;
//! * **active**: fused as a heading only (a Schmidt update that holds [`HELD_STATES`]: it
//!   corrects the yaw and the z gyro bias, not the tilt, the velocity or the other biases),
//!   gated like every source, at most every [`MIN_FUSION_INTERVAL_NS`]: the
//!   compass's error is time-correlated (calibration, motor current), so fusing every sample
//!   would average away an error that does not average.

use nalgebra::{SMatrix, Vector3};
use uavnav_core::magnetic::MagneticField;
use uavnav_core::rotation::skew;

use super::{InnovDiag, UpdateOutcome, gated_update, gated_update_considering};
use crate::state::{Cov, ErrVec, IBA, IBG, IGM, IP, ITH, IV, N, Nominal};

/// Below this |field| a sample is dead, T (the Earth's field is 22–67 µT).
pub const DEAD_FIELD_T: f64 = 1.0e-6;
/// Dead samples in a row that stop the source.
pub const DEAD_SAMPLES: u32 = 20;
/// Shortest interval between two fused headings, ns.
pub const MIN_FUSION_INTERVAL_NS: i64 = 500_000_000;
/// Plausible measured/model strength ratio (calibrations are often far off in scale; see module
/// doc): outside it the compass reads something else (a magnet, a stuck axis).
pub const STRENGTH_RATIO_RANGE: std::ops::RangeInclusive<f64> = 0.1..=5.0;
/// Largest relative deviation from the compass's own typical strength for a usable sample.
pub const STRENGTH_DEVIATION: f64 = 0.25;
/// Samples that teach the typical strength before the deviation test applies; then it follows
/// the strength slowly (an exponential average over this many samples).
pub const STRENGTH_LEARN_SAMPLES: u32 = 50;

/// The error states a compass heading does not correct (eq. M1 fused as a Schmidt update: their
/// uncertainty counts in the innovation, their values and covariance are held): position,
/// velocity, roll and pitch, the x/y gyro bias, the accelerometer bias and the GNSS error state.
/// The heading corrects the yaw, the z gyro bias (what the yaw's drift is learnt from) and the
/// pose clone through its correlation with them. Why: a compass error is a heading error
/// (motor current, calibration, a structure nearby), correlated over seconds; through the
/// inclination coupling of `H_θ` and the yaw's correlation with the tilt and the velocity, a
/// full update carried it into the tilt, and from there into the biases the tilt is learnt from.
/// Measured on 14 public ArduPilot copter logs with a compass (`erlerobot/logs`, scored against
/// each autopilot's EKF1; `real_flights survey`), GNSS withheld: roll / pitch RMSE summed over
/// the logs 46.5 / 36.8° → 40.2 / 31.3°, no log more than 0.15° worse on either angle but the
/// one that crashes (roll +0.9°, pitch −2.1°); with GNSS (7 logs) 8.9 / 6.2° → 8.7 / 6.0° with
/// the crash left out. Holding the tilt alone moved the error into the velocity and back (pitch
/// 4.1 → 6.8° on one log).
pub const HELD_STATES: [usize; 16] = [
    IP,
    IP + 1,
    IP + 2,
    IV,
    IV + 1,
    IV + 2,
    ITH,
    ITH + 1,
    IBG,
    IBG + 1,
    IBA,
    IBA + 1,
    IBA + 2,
    IGM,
    IGM + 1,
    IGM + 2,
];

/// Largest static difference between the compass's typical inclination and the model's beyond
/// `mag_max_inclination_error_rad`, rad: within it the compass is used with a wider heading σ.
pub const MAX_STATIC_INCLINATION_ERROR_RAD: f64 = 0.35;
/// Consecutive consistent samples whose headings must agree before the compass sets the heading.
pub const ALIGN_SAMPLES: usize = 10;
/// Largest spread of those headings, rad.
pub const ALIGN_SPREAD_RAD: f64 = 0.087;

/// State of the source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MagState {
    /// No sample yet.
    #[default]
    Off,
    /// Fusing (or ready to) heading.
    Active,
    /// Stopped: the sensor is dead, or its heading contradicts the GNSS-velocity yaw bank.
    Stopped,
}

/// Why the last sample was not fused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MagSkip {
    /// Fused.
    None,
    /// The field's inclination or strength is off the model.
    Disturbed,
    /// Within the minimum interval after the last fused heading.
    Saturated,
    /// Rejected by the innovation gate.
    Gated,
    /// No horizontal field to speak of (near the magnetic poles) or a dead sample.
    Unusable,
}

/// The magnetometer heading source.
#[derive(Debug, Clone, PartialEq)]
pub struct MagHeadingSource {
    /// Diagnostics (innovation and test ratio are computed even when not fused).
    pub diag: InnovDiag,
    /// Lifecycle state.
    pub state: MagState,
    /// Samples judged disturbed.
    pub disturbed: u64,
    /// Why the last sample was not fused.
    pub last_skip: MagSkip,
    /// Whether the source was stopped because its heading contradicted the yaw bank.
    pub contradicted: bool,
    dead_run: u32,
    /// The compass's own typical strength, T, and inclination, rad (0 until learnt), and the
    /// samples behind them.
    typical_t: f64,
    typical_incl_rad: f64,
    learnt: u32,
    /// Headings implied by the latest consistent samples while aligning.
    align: Vec<f64>,
}

impl Default for MagHeadingSource {
    fn default() -> Self {
        Self {
            diag: InnovDiag::new(),
            state: MagState::Off,
            disturbed: 0,
            last_skip: MagSkip::None,
            contradicted: false,
            dead_run: 0,
            typical_t: 0.0,
            typical_incl_rad: 0.0,
            learnt: 0,
            align: Vec::new(),
        }
    }
}

/// Residual (wrapped) and Jacobian of eq. (M1) for a field `m_b` in the body frame.
pub fn model(x: &Nominal, m_b: &Vector3<f64>, declination_rad: f64) -> (f64, SMatrix<f64, 1, N>) {
    let m = x.q.transform_vector(m_b);
    let h2 = (m.x * m.x + m.y * m.y).max(1e-30);
    let alpha = m.y.atan2(m.x);
    let g = Vector3::new(-m.y, m.x, 0.0) / h2;
    let h_th = g.transpose() * (-skew(&m));
    let mut h = SMatrix::<f64, 1, N>::zeros();
    h.fixed_view_mut::<1, 3>(0, ITH).copy_from(&h_th);
    (wrap_pi(declination_rad - alpha), h)
}

fn wrap_pi(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    (a + PI).rem_euclid(TAU) - PI
}

/// Heading of the body x axis implied by a body-frame field and the roll/pitch of `x` (used to
/// align the heading at start).
pub fn heading_from_field(x: &Nominal, m_b: &Vector3<f64>, declination_rad: f64) -> Option<f64> {
    let m = x.q.transform_vector(m_b);
    if m.xy().norm() < DEAD_FIELD_T * 0.5 {
        return None;
    }
    let (_, _, yaw) = x.q.euler_angles();
    // The filter's yaw is off by (measured azimuth − declination).
    Some(wrap_pi(yaw + declination_rad - m.y.atan2(m.x)))
}

impl MagHeadingSource {
    /// Checks a sample for a dead sensor; returns whether it is usable at all.
    pub fn check_alive(&mut self, m_b: &Vector3<f64>) -> bool {
        if self.state == MagState::Stopped {
            return false;
        }
        if m_b.norm() < DEAD_FIELD_T {
            self.dead_run += 1;
            if self.dead_run >= DEAD_SAMPLES {
                self.state = MagState::Stopped;
            }
            self.last_skip = MagSkip::Unusable;
            return false;
        }
        self.dead_run = 0;
        if self.state == MagState::Off {
            self.state = MagState::Active;
        }
        true
    }

    /// Whether the sample agrees with the compass's own typical field (strength, and inclination
    /// through the current tilt), which is learnt here and follows slow changes; a sample that
    /// strays from it is disturbed (motor current, steel nearby). The model bounds plausibility
    /// only: a typical inclination up to [`MAX_STATIC_INCLINATION_ERROR_RAD`] off the model's (a
    /// hard-iron offset left by the calibration) is a static error the heading σ absorbs
    /// ([`Self::static_sigma_rad`]), not a reason to ignore the compass.
    pub fn consistent(
        &mut self,
        x: &Nominal,
        m_b: &Vector3<f64>,
        model_field: &MagneticField,
        max_incl_err_rad: f64,
    ) -> bool {
        let m = x.q.transform_vector(m_b);
        let incl = m.z.atan2(m.xy().norm());
        let strength = m.norm();
        let ratio = strength / model_field.strength_t().max(1e-9);
        if !STRENGTH_RATIO_RANGE.contains(&ratio)
            || (incl - model_field.inclination_rad()).abs()
                > MAX_STATIC_INCLINATION_ERROR_RAD + max_incl_err_rad
        {
            return false;
        }
        let ok = self.learnt < STRENGTH_LEARN_SAMPLES
            || ((strength / self.typical_t - 1.0).abs() <= STRENGTH_DEVIATION
                && (incl - self.typical_incl_rad).abs() <= max_incl_err_rad);
        self.learnt = self.learnt.saturating_add(1);
        let k = 1.0 / f64::from(self.learnt.min(STRENGTH_LEARN_SAMPLES));
        self.typical_t += k * (strength - self.typical_t);
        self.typical_incl_rad += k * (incl - self.typical_incl_rad);
        let static_ok = (self.typical_incl_rad - model_field.inclination_rad()).abs()
            <= MAX_STATIC_INCLINATION_ERROR_RAD;
        ok && static_ok
    }

    /// The heading σ a static inclination error adds, rad: a hard-iron offset that tilts the
    /// field by δ turns the heading by up to about δ once the vehicle banks.
    pub fn static_sigma_rad(&self, model_field: &MagneticField, max_incl_err_rad: f64) -> f64 {
        if self.learnt == 0 {
            return 0.0;
        }
        let d = (self.typical_incl_rad - model_field.inclination_rad()).abs();
        (d - max_incl_err_rad).max(0.0)
    }

    /// Forgets the typical strength and inclination: the samples behind them were read through
    /// a compass offset that is now subtracted (`mag_calibration`).
    pub fn relearn_typical(&mut self) {
        self.learnt = 0;
    }

    /// The compass's typical strength learnt so far, T (0 before the first usable sample).
    pub fn typical_strength_t(&self) -> f64 {
        self.typical_t
    }

    /// Feeds the heading a consistent sample implies while aligning; returns the heading to take
    /// once [`ALIGN_SAMPLES`] in a row agree within [`ALIGN_SPREAD_RAD`] (their circular mean).
    pub fn align_with(&mut self, heading_rad: f64) -> Option<f64> {
        self.align.push(heading_rad);
        if self.align.len() > ALIGN_SAMPLES {
            self.align.remove(0);
        }
        if self.align.len() < ALIGN_SAMPLES {
            return None;
        }
        let (s, c) = self
            .align
            .iter()
            .fold((0.0, 0.0), |(s, c), a| (s + a.sin(), c + a.cos()));
        let mean = s.atan2(c);
        let spread = self
            .align
            .iter()
            .map(|a| wrap_pi(a - mean).abs())
            .fold(0.0, f64::max);
        (spread <= ALIGN_SPREAD_RAD).then_some(mean)
    }

    /// Forgets the alignment samples (an inconsistent sample breaks the run).
    pub fn align_break(&mut self) {
        self.align.clear();
    }

    /// Stops the source for good: its heading contradicts the GNSS-velocity yaw bank.
    pub fn stop_contradicted(&mut self) {
        self.state = MagState::Stopped;
        self.contradicted = true;
    }

    /// Fuses one sample (body frame) at the horizon; returns the correction, if any.
    #[allow(clippy::too_many_arguments)]
    pub fn fuse(
        &mut self,
        x: &Nominal,
        p: &mut Cov,
        m_b: &Vector3<f64>,
        model_field: &MagneticField,
        sigma_rad: f64,
        max_incl_err_rad: f64,
        gate_sigma: f64,
        t_ns: i64,
    ) -> Option<ErrVec> {
        if !self.check_alive(m_b) {
            return None;
        }
        let m = x.q.transform_vector(m_b);
        if m.xy().norm() < 0.1 * m.norm() {
            self.last_skip = MagSkip::Unusable;
            return None;
        }
        let (y, h) = model(x, m_b, model_field.declination_rad());
        let consistent = self.consistent(x, m_b, model_field, max_incl_err_rad);
        // Consecutive compass errors are nearly the same (calibration, motor current): fusing
        // every sample would count one error many times, so at most one per interval.
        let saturated = self.diag.last_fused_t_ns != i64::MIN
            && t_ns - self.diag.last_fused_t_ns < MIN_FUSION_INTERVAL_NS;
        let r = SMatrix::<f64, 1, 1>::new(sigma_rad * sigma_rad);
        let yv = SMatrix::<f64, 1, 1>::new(y);
        if !consistent || saturated {
            // Diagnostics only: innovation and test ratio without touching P.
            let mut scratch = *p;
            let mut d = self.diag;
            let _ = gated_update(&mut scratch, &h, &r, &yv, gate_sigma, t_ns, false, &mut d);
            self.diag.innov = d.innov;
            self.diag.innov_var = d.innov_var;
            self.diag.test_ratio = d.test_ratio;
            if consistent {
                self.last_skip = MagSkip::Saturated;
            } else {
                self.disturbed += 1;
                self.last_skip = MagSkip::Disturbed;
            }
            return None;
        }
        match gated_update_considering(
            p,
            &h,
            &r,
            &yv,
            gate_sigma,
            t_ns,
            false,
            &mut self.diag,
            &HELD_STATES,
        ) {
            UpdateOutcome::Fused(dx) => {
                self.last_skip = MagSkip::None;
                Some(dx)
            }
            _ => {
                self.last_skip = MagSkip::Gated;
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    /// A level vehicle heading north and a field of 22 µT north, 36 µT down (inclination 58.6°).
    fn setup() -> (Nominal, MagneticField) {
        let x = Nominal {
            t_ns: 0,
            p: Vector3::zeros(),
            v: Vector3::zeros(),
            q: UnitQuaternion::identity(),
            bg: Vector3::zeros(),
            ba: Vector3::zeros(),
            gm: Vector3::zeros(),
            clone: None,
        };
        (
            x,
            MagneticField {
                ned_t: Vector3::new(22e-6, 0.0, 36e-6),
            },
        )
    }

    const INCL: f64 = 0.1745;

    #[test]
    fn a_compass_off_the_models_strength_is_used_and_its_own_strength_learnt() {
        let (x, field) = setup();
        let mut src = MagHeadingSource::default();
        // 1.8 × the model (a scale the calibration left): consistent throughout
        for _ in 0..100 {
            assert!(src.consistent(&x, &(field.ned_t * 1.8), &field, INCL));
        }
        assert!((src.typical_strength_t() / (field.strength_t() * 1.8) - 1.0).abs() < 1e-9);
        // a sample 40 % stronger than the compass's own typical field is disturbed
        assert!(!src.consistent(&x, &(field.ned_t * 1.8 * 1.4), &field, INCL));
        // implausible against the model (a magnet): disturbed from the first sample
        let mut fresh = MagHeadingSource::default();
        assert!(!fresh.consistent(&x, &(field.ned_t * 8.0), &field, INCL));
    }

    #[test]
    fn a_static_inclination_error_widens_the_heading_sigma_instead_of_stopping_the_compass() {
        let (x, field) = setup();
        // 17° steeper than the model, as a hard-iron offset along the body z axis leaves it
        let tilted = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 17f64.to_radians())
            .transform_vector(&field.ned_t);
        let mut src = MagHeadingSource::default();
        for _ in 0..60 {
            assert!(src.consistent(&x, &tilted, &field, INCL));
        }
        let extra = src.static_sigma_rad(&field, INCL);
        assert!(
            (extra - (17f64.to_radians() - INCL)).abs() < 0.01,
            "{}",
            extra.to_degrees()
        );
        // beyond the static bound: never consistent
        let far = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 35f64.to_radians())
            .transform_vector(&field.ned_t);
        let mut src = MagHeadingSource::default();
        assert!(!src.consistent(&x, &far, &field, INCL));
    }

    #[test]
    fn alignment_needs_agreeing_samples() {
        let mut src = MagHeadingSource::default();
        for k in 0..ALIGN_SAMPLES - 1 {
            assert_eq!(src.align_with(1.0 + 0.001 * k as f64), None);
        }
        let yaw = src.align_with(1.0).expect("aligned");
        assert!((yaw - 1.004).abs() < 0.01, "{yaw}");
        // a spread wider than ALIGN_SPREAD_RAD never aligns, and a break starts over
        let mut src = MagHeadingSource::default();
        for k in 0..3 * ALIGN_SAMPLES {
            let a = if k % 2 == 0 { 0.0 } else { 0.3 };
            assert_eq!(src.align_with(a), None);
        }
        src.align_break();
        assert_eq!(src.align_with(0.0), None);
    }

    #[test]
    fn a_contradicted_compass_stays_stopped() {
        let (x, field) = setup();
        let mut src = MagHeadingSource::default();
        assert!(src.check_alive(&field.ned_t));
        src.stop_contradicted();
        assert!(src.contradicted);
        assert!(!src.check_alive(&field.ned_t));
        let mut p = Cov::identity() * 0.01;
        let fused = src.fuse(&x, &mut p, &field.ned_t, &field, 0.2, INCL, 3.29, 1_000);
        assert!(fused.is_none());
        assert_eq!(src.state, MagState::Stopped);
    }
}
