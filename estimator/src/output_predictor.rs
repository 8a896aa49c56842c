//! The output predictor: a pose for every IMU sample although the EKF runs at the delayed fusion
//! horizon (PX4 EKF2 `output_predictor`).
//!
//! Unlike PX4's complementary-filter tracking, this one is exact and simple: it keeps the IMU
//! samples newer than the horizon; without a correction it integrates each new sample onto the
//! output state (the same integration the EKF will later repeat with the same biases); after a
//! correction at the horizon it re-integrates from the corrected horizon state (at most
//! `fusion_delay × rate` samples, a few µs, only at measurement times).

use nalgebra::Vector3;
use uavnav_core::{ImuSample, LocalFrame};

use crate::prediction::{GravityCache, ImuMean, integrate_nominal};
use crate::state::Nominal;

/// The mean of two instantaneous IMU samples (trapezoidal integration over the interval).
pub fn mean_of(a: &ImuSample, b: &ImuSample) -> ImuMean {
    ImuMean {
        gyro: (a.gyro_radps + b.gyro_radps) * 0.5,
        accel: (a.accel_mps2 + b.accel_mps2) * 0.5,
    }
}

/// Output state at the newest IMU sample.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputPredictor {
    /// Output nominal state (biases copied from the EKF).
    pub x: Option<Nominal>,
    gravity: Option<GravityCache>,
}

impl Default for OutputPredictor {
    fn default() -> Self {
        Self::new()
    }
}

impl OutputPredictor {
    /// Empty (no output before initialisation).
    pub fn new() -> Self {
        Self {
            x: None,
            gravity: None,
        }
    }

    /// Integrates from the previous newest sample `prev` to the new one `cur`.
    pub fn advance(
        &mut self,
        frame: &LocalFrame,
        prev: &ImuSample,
        cur: &ImuSample,
        w_ie: &Vector3<f64>,
        gm_tau_s: f64,
    ) {
        let Some(x) = self.x.as_mut() else { return };
        let g = self
            .gravity
            .get_or_insert_with(|| GravityCache::new(frame, &x.p))
            .at(frame, &x.p);
        let dt_s = (cur.t_ns - prev.t_ns) as f64 * 1e-9;
        integrate_nominal(x, &mean_of(prev, cur), dt_s, &g, w_ie, gm_tau_s);
        x.t_ns = cur.t_ns;
    }

    /// Restarts from the horizon state `horizon` (valid at `samples[0]`) and integrates through
    /// the newer samples.
    pub fn resync<'a>(
        &mut self,
        frame: &LocalFrame,
        horizon: &Nominal,
        samples: impl Iterator<Item = &'a ImuSample>,
        w_ie: &Vector3<f64>,
        gm_tau_s: f64,
    ) {
        let mut x = *horizon;
        x.clone = None;
        self.x = Some(x);
        let mut prev: Option<&ImuSample> = None;
        for s in samples {
            if let Some(p) = prev {
                self.advance(frame, p, s, w_ie, gm_tau_s);
            }
            prev = Some(s);
        }
    }
}
