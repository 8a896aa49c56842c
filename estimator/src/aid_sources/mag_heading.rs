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
//!   tilt is more than `mag_max_inclination_error_rad` from the model's or its strength outside
//!   [`STRENGTH_RATIO_RANGE`] of the model's;
//! * **active**: fused, gated like every source, at most every [`MIN_FUSION_INTERVAL_NS`]: the
//!   compass's error is time-correlated (calibration, motor current), so fusing every sample
//!   would average away an error that does not average.

use nalgebra::{SMatrix, Vector3};
use uavnav_core::magnetic::MagneticField;
use uavnav_core::rotation::skew;

use super::{InnovDiag, UpdateOutcome, gated_update};
use crate::state::{Cov, ErrVec, ITH, N, Nominal};

/// Below this |field| a sample is dead, T (the Earth's field is 22–67 µT).
pub const DEAD_FIELD_T: f64 = 1.0e-6;
/// Dead samples in a row that stop the source.
pub const DEAD_SAMPLES: u32 = 20;
/// Shortest interval between two fused headings, ns.
pub const MIN_FUSION_INTERVAL_NS: i64 = 500_000_000;
/// Accepted measured/model strength ratio (calibrations are often off in scale; see module doc).
pub const STRENGTH_RATIO_RANGE: std::ops::RangeInclusive<f64> = 0.4..=1.8;

/// State of the source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MagState {
    /// No sample yet.
    #[default]
    Off,
    /// Fusing (or ready to) heading.
    Active,
    /// Stopped: the sensor is dead.
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
    dead_run: u32,
}

impl Default for MagHeadingSource {
    fn default() -> Self {
        Self {
            diag: InnovDiag::new(),
            state: MagState::Off,
            disturbed: 0,
            last_skip: MagSkip::None,
            dead_run: 0,
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

    /// Whether the sample's direction and strength agree with the model through the current tilt.
    pub fn consistent(
        &self,
        x: &Nominal,
        m_b: &Vector3<f64>,
        model_field: &MagneticField,
        max_incl_err_rad: f64,
    ) -> bool {
        let m = x.q.transform_vector(m_b);
        let incl = m.z.atan2(m.xy().norm());
        let ratio = m.norm() / model_field.strength_t().max(1e-9);
        (incl - model_field.inclination_rad()).abs() <= max_incl_err_rad
            && STRENGTH_RATIO_RANGE.contains(&ratio)
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
        match gated_update(p, &h, &r, &yv, gate_sigma, t_ns, false, &mut self.diag) {
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
