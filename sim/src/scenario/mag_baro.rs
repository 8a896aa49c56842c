//! The optional sensors' tables, `[mag]` and `[baro]`: present = fitted.

use serde::Deserialize;

use super::{WindowRaw, WindowSpec, finite, non_negative, positive};

/// Default magnetometer and barometer rate, Hz.
pub const DEFAULT_MAG_BARO_RATE_HZ: f64 = 10.0;
/// Default 1-σ magnetometer white noise per axis and sample, T (a MEMS magnetometer, ~0.1 µT).
pub const DEFAULT_MAG_SIGMA_T: f64 = 1.0e-7;
/// Default 1-σ of the constant hard-iron residual per axis, T (0.5 µT: about 1 % of the field,
/// what is left after a good calibration).
pub const DEFAULT_MAG_BIAS_SIGMA_T: f64 = 5.0e-7;
/// Default 1-σ barometer white noise per sample, Pa (MS5611-class, highest oversampling).
pub const DEFAULT_BARO_SIGMA_PA: f64 = 1.0;
/// ISA sea-level pressure, Pa.
pub const ISA_SEA_LEVEL_PA: f64 = 101_325.0;

/// Magnetometer: `m = R_bmᵀ (scale · C_nbᵀ B_ned + d_b) + b + n` (the crate doc's physics contract).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MagSpec {
    /// Sample rate, Hz (sample times are snapped to the IMU grid).
    #[serde(deserialize_with = "positive")]
    pub rate_hz: f64,
    /// 1-σ white noise per axis and sample, T.
    #[serde(deserialize_with = "non_negative")]
    pub sigma_t: f64,
    /// 1-σ per axis of the constant hard-iron residual `b`, drawn once per flight, T.
    #[serde(deserialize_with = "non_negative")]
    pub bias_sigma_t: f64,
    /// Calibration scale error: the sensor reads `scale` × the true field (real compasses read
    /// 0.6–0.8 of the model strength after a calibration that normalises the field).
    #[serde(deserialize_with = "positive")]
    pub scale: f64,
    /// Mount rotation `body_from_mag` as ZYX Euler angles [roll, pitch, yaw], degrees.
    pub body_from_mag_rpy_deg: [f64; 3],
    /// Disturbed-field windows (motor currents, a steel structure below): a field added in the
    /// body axes, as read (after `scale`).
    pub disturbances: Vec<MagDisturbanceSpec>,
}

impl Default for MagSpec {
    fn default() -> Self {
        Self {
            rate_hz: DEFAULT_MAG_BARO_RATE_HZ,
            sigma_t: DEFAULT_MAG_SIGMA_T,
            bias_sigma_t: DEFAULT_MAG_BIAS_SIGMA_T,
            scale: 1.0,
            body_from_mag_rpy_deg: [0.0; 3],
            disturbances: Vec::new(),
        }
    }
}

/// A disturbed magnetic field: `field_body_t` is added to the reading in `[start_s, end_s)`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, try_from = "DisturbanceRaw")]
pub struct MagDisturbanceSpec {
    /// When, s after `t0_ns`.
    pub window: WindowSpec,
    /// The added field, body axes (x fwd, y right, z down), T.
    pub field_body_t: [f64; 3],
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct DisturbanceRaw {
    start_s: f64,
    end_s: f64,
    field_body_t: [f64; 3],
}

impl TryFrom<DisturbanceRaw> for MagDisturbanceSpec {
    type Error = String;
    fn try_from(r: DisturbanceRaw) -> Result<Self, String> {
        let window = WindowSpec::try_from(WindowRaw {
            start_s: r.start_s,
            end_s: r.end_s,
        })?;
        if !r.field_body_t.iter().all(|x| x.is_finite()) {
            return Err("field_body_t must be finite".into());
        }
        Ok(Self {
            window,
            field_body_t: r.field_body_t,
        })
    }
}

/// Barometer: static pressure of the ISA troposphere at the true height above mean sea level,
/// on a day whose sea-level pressure is `sea_level_pa`, plus an offset that drifts (weather) and
/// walks, plus white noise (the crate doc's physics contract).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BaroSpec {
    /// Sample rate, Hz (sample times are snapped to the IMU grid).
    #[serde(deserialize_with = "positive")]
    pub rate_hz: f64,
    /// 1-σ white noise per sample, Pa.
    #[serde(deserialize_with = "non_negative")]
    pub sigma_pressure_pa: f64,
    /// Sea-level pressure of the day, Pa (the ISA's 101 325 Pa by default): a constant offset of
    /// the pressure height, which only a reference (GNSS) can remove.
    #[serde(deserialize_with = "positive")]
    pub sea_level_pa: f64,
    /// Linear pressure drift (weather), Pa/s; e.g. −0.03 Pa/s ≈ −1 hPa an hour, a falling glass.
    #[serde(deserialize_with = "finite")]
    pub drift_pa_per_s: f64,
    /// Random-walk pressure offset, Pa/√s (sensor warming, wash); 0 = none.
    #[serde(deserialize_with = "non_negative")]
    pub random_walk_pa_per_sqrt_s: f64,
}

impl Default for BaroSpec {
    fn default() -> Self {
        Self {
            rate_hz: DEFAULT_MAG_BARO_RATE_HZ,
            sigma_pressure_pa: DEFAULT_BARO_SIGMA_PA,
            sea_level_pa: ISA_SEA_LEVEL_PA,
            drift_pa_per_s: 0.0,
            random_walk_pa_per_sqrt_s: 0.0,
        }
    }
}
