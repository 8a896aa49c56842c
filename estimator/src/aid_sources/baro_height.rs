//! Barometric height with an offset that drifts (weather, the sensor's own warming, propeller
//! wash): it holds the height through GNSS outages.
//!
//! Height from static pressure by the ISA troposphere (eq. B1):
//! `h = (1 − (p / p₀)^(1/5.255 88)) / 2.255 77·10⁻⁵ m`, `p₀` = 101 325 Pa. Its absolute value is off
//! by the day's sea-level pressure and temperature (tens of metres), so only its changes are
//! trusted: the offset `b = h_baro − h` (with `h = −p_D` in the local frame) is a random walk,
//! estimated by a scalar Kalman filter apart from the error state while GNSS position is fused
//! (GNSS gives the height then; fusing both would count the GNSS height twice through `b`).
//!
//! Lifecycle:
//! * **off** until a sample arrives;
//! * **starting** until GNSS position is being fused: the first such sample sets `b` with the
//!   filter's height variance;
//! * **tracking**: GNSS active, `b` follows `h_baro + p_D` with the GNSS-aided height's variance
//!   plus the baro's noise;
//! * **holding**: GNSS lost: the height is fused as `p_D = b − h_baro` with `R = σ_h² + σ_b²`, at
//!   most every [`MIN_FUSION_INTERVAL_NS`] (the offset's error is the same for every sample, so it
//!   cannot be averaged away: the filter's height variance is also kept at or above `σ_b²`).
//!
//! Diagnostics (innovation, test ratio) are computed in every state once `b` is known.

use nalgebra::SMatrix;

use super::{InnovDiag, UpdateOutcome, gated_update};
use crate::state::{Cov, ErrVec, IP, N, Nominal};

/// Window over which the offset's drift is measured while tracking, ns (eq. B2).
pub const DRIFT_WINDOW_NS: i64 = 30_000_000_000;
/// Time constant with which a measured drift rate relaxes after a worse window, s.
const DRIFT_RELEASE_S: f64 = 300.0;

/// Shortest interval between two fused heights while holding, ns.
pub const MIN_FUSION_INTERVAL_NS: i64 = 200_000_000;
/// ISA sea-level pressure, Pa.
const P0_PA: f64 = 101_325.0;

/// ISA height of a static pressure, m (eq. B1).
pub fn isa_height_m(pressure_pa: f64) -> f64 {
    (1.0 - (pressure_pa / P0_PA).powf(1.0 / 5.255_88)) / 2.255_77e-5
}

/// Metres of height per pascal at a pressure (the slope of eq. B1), m/Pa.
pub fn metres_per_pascal(pressure_pa: f64) -> f64 {
    let e = 1.0 / 5.255_88;
    (e / 2.255_77e-5) * (pressure_pa / P0_PA).powf(e - 1.0) / P0_PA
}

/// State of the source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BaroState {
    /// No sample yet.
    #[default]
    Off,
    /// Samples arrive; the offset waits for GNSS height.
    Starting,
    /// GNSS height fused: the offset is tracked, the height not fused.
    Tracking,
    /// No GNSS height: the barometer holds the height.
    Holding,
}

/// The barometric height source.
#[derive(Debug, Clone, PartialEq)]
pub struct BaroHeightSource {
    /// Diagnostics of the height residual `b − h_baro − p_D`.
    pub diag: InnovDiag,
    /// Lifecycle state.
    pub state: BaroState,
    /// Offset `h_baro − h`, m, and its variance, m².
    pub offset: Option<(f64, f64)>,
    /// Random-walk rate of the offset measured while tracking (eq. B2), m²/s.
    pub measured_walk_var_per_s: f64,
    /// Start of the current drift window: time, `h_baro − h` and the variance of both ends.
    drift_window: Option<(i64, f64, f64)>,
    last_t_ns: Option<i64>,
}

impl Default for BaroHeightSource {
    fn default() -> Self {
        Self {
            diag: InnovDiag::new(),
            state: BaroState::Off,
            offset: None,
            measured_walk_var_per_s: 0.0,
            drift_window: None,
            last_t_ns: None,
        }
    }
}

/// Tuning of the barometer source.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaroParams {
    /// 1-σ height noise per sample, m, before the sensor's own pressure noise is added.
    pub height_sigma_m: f64,
    /// Random walk of the offset, m/√s (weather, warming sensor).
    pub offset_walk_m_per_sqrt_s: f64,
    /// Innovation gate, σ.
    pub gate_sigma: f64,
}

impl BaroHeightSource {
    /// Eq. B2: how fast the offset really wanders, from the data. Over a window of `W` seconds
    /// with GNSS height, the change of `z = h_baro − h` has the variance `q W + v₀ + v₁` (`v` the
    /// variance of each end); the excess of its square over `v₀ + v₁`, divided by `W`, estimates
    /// the walk rate `q`. On the shared real copters `z` changes by 3.7–4.0 m RMS in a minute
    /// (propeller wash, the sensor warming, and the GNSS height's own wander), ~5× the nominal
    /// walk: holding the height through an outage with the nominal rate claimed σ = 1.1 m with
    /// 4.6 m of error. The largest recent rate is used, relaxing over [`DRIFT_RELEASE_S`].
    fn measure_drift(&mut self, t_ns: i64, z: f64, var_z: f64) {
        let Some((t0, z0, var0)) = self.drift_window else {
            self.drift_window = Some((t_ns, z, var_z));
            return;
        };
        if t_ns - t0 < DRIFT_WINDOW_NS {
            return;
        }
        let w_s = (t_ns - t0) as f64 * 1e-9;
        let q = (((z - z0).powi(2) - var0 - var_z) / w_s).max(0.0);
        let decay = (-w_s / DRIFT_RELEASE_S).exp();
        self.measured_walk_var_per_s = q.max(self.measured_walk_var_per_s * decay);
        self.drift_window = Some((t_ns, z, var_z));
    }

    /// Handles one sample at the horizon. `gnss_active`: GNSS position fused recently. Returns a
    /// correction to inject when the height was fused.
    #[allow(clippy::too_many_arguments)]
    pub fn process(
        &mut self,
        x: &Nominal,
        p: &mut Cov,
        t_ns: i64,
        pressure_pa: f64,
        sigma_pressure_pa: f64,
        gnss_active: bool,
        params: &BaroParams,
    ) -> Option<ErrVec> {
        let h_baro = isa_height_m(pressure_pa);
        let sigma_h = params
            .height_sigma_m
            .hypot(sigma_pressure_pa * metres_per_pascal(pressure_pa));
        let dt_s = self
            .last_t_ns
            .map_or(0.0, |l| ((t_ns - l) as f64 * 1e-9).max(0.0));
        self.last_t_ns = Some(t_ns);
        let walk = params
            .offset_walk_m_per_sqrt_s
            .powi(2)
            .max(self.measured_walk_var_per_s);
        if let Some((_, var)) = self.offset.as_mut() {
            *var += walk * dt_s;
        }
        let h = -x.p.z;
        let var_h = p[(IP + 2, IP + 2)].max(0.0);
        if gnss_active {
            self.measure_drift(t_ns, h_baro - h, var_h + sigma_h * sigma_h);
        } else {
            self.drift_window = None;
        }
        match (self.offset, gnss_active) {
            (None, false) => {
                self.state = BaroState::Starting;
                None
            }
            (None, true) => {
                self.offset = Some((h_baro - h, var_h + sigma_h * sigma_h));
                self.state = BaroState::Tracking;
                None
            }
            (Some((b, var_b)), true) => {
                // Scalar Kalman update of the offset against the GNSS-aided height.
                let z = h_baro - h;
                let s = var_b + var_h + sigma_h * sigma_h;
                let k = var_b / s;
                self.diag.innov = [z - b, 0.0, 0.0];
                self.diag.innov_var = [s, 0.0, 0.0];
                self.diag.test_ratio = (z - b).powi(2) / s / super::chi2_gate(1, params.gate_sigma);
                // The GNSS height's error is time-correlated (the same for many samples): the
                // offset is never known better than the height it is compared with.
                self.offset = Some((b + k * (z - b), ((1.0 - k) * var_b).max(var_h)));
                self.state = BaroState::Tracking;
                None
            }
            (Some((b, var_b)), false) => {
                self.state = BaroState::Holding;
                if self.diag.last_fused_t_ns != i64::MIN
                    && t_ns - self.diag.last_fused_t_ns < MIN_FUSION_INTERVAL_NS
                {
                    return None;
                }
                // Measured down position: p_D = −(h_baro − b).
                let y = SMatrix::<f64, 1, 1>::new(-(h_baro - b) - x.p.z);
                let mut hm = SMatrix::<f64, 1, N>::zeros();
                hm[(0, IP + 2)] = 1.0;
                let r = SMatrix::<f64, 1, 1>::new(sigma_h * sigma_h + var_b);
                let out = match gated_update(
                    p,
                    &hm,
                    &r,
                    &y,
                    params.gate_sigma,
                    t_ns,
                    false,
                    &mut self.diag,
                ) {
                    UpdateOutcome::Fused(dx) => Some(dx),
                    _ => None,
                };
                // The offset's error is common to every sample: never claim the height better.
                if p[(IP + 2, IP + 2)] < var_b {
                    p[(IP + 2, IP + 2)] = var_b;
                }
                out
            }
        }
    }

    /// The barometric height corrected by the offset, m, for diagnostics.
    pub fn corrected_height_m(&self, pressure_pa: f64) -> Option<f64> {
        self.offset.map(|(b, _)| isa_height_m(pressure_pa) - b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn isa_height_of_known_pressures() {
        assert!(isa_height_m(101_325.0).abs() < 1e-9);
        // ISA: 89 874.6 Pa at 1000 m, 54 019.9 Pa at 5000 m
        assert!((isa_height_m(89_874.6) - 1000.0).abs() < 1.0);
        assert!((isa_height_m(54_019.9) - 5000.0).abs() < 3.0);
        // slope ≈ 8.3 m/hPa at sea level, steeper higher up
        let s = metres_per_pascal(101_325.0);
        assert!((s - 0.0832).abs() < 0.0005, "{s}");
        let d = isa_height_m(96_000.0) - isa_height_m(96_001.0);
        assert!((d - metres_per_pascal(96_000.5)).abs() < 1e-4);
    }
}
