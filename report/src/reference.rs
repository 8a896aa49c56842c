//! Screening a reference (another estimator's output, e.g. an autopilot's EKF in a flight log)
//! before anything is scored against it.
//!
//! A reference is not truth, and on real logs it sometimes fails outright: on public ArduPilot
//! flights we checked, the autopilot's `EKF1` sat at (1,000,000, −298,800) m from its origin for
//! minutes after a crash and a log restart, while the GNSS fixes (and our estimate) stayed within
//! metres of the take-off point. Scoring against such samples reports a "drift" of 1,000 km that
//! belongs to the reference. The fixes are what both estimators are anchored to, so a reference
//! sample far from the fix of the same moment is left out, and how many were left out is said
//! with the reference's name.

use nalgebra::Vector3;
use uavnav_core::TruthSample;

/// A GNSS fix in the reference's local NED frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixNed {
    /// Time of validity, ns.
    pub t_ns: i64,
    /// Position in the reference's frame, m.
    pub pos_ned_m: Vector3<f64>,
    /// The receiver's horizontal 1-σ, m.
    pub sigma_h_m: f64,
}

/// What the screen keeps and drops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScreenParams {
    /// Smallest horizontal distance from the fix of the same moment that makes a sample
    /// implausible, m: far beyond any receiver's error and any autopilot's honest error.
    pub min_gate_m: f64,
    /// ... or this many of the fix's own horizontal σ, when larger.
    pub gate_sigmas: f64,
    /// The gate grows by this speed times the time to the nearest fix, m/s: through a GNSS
    /// outage the vehicle may have flown anywhere within that range (faster than small UAVs
    /// fly), but not 1,000 km.
    pub max_speed_mps: f64,
}

impl Default for ScreenParams {
    fn default() -> Self {
        Self {
            min_gate_m: 100.0,
            gate_sigmas: 20.0,
            max_speed_mps: 100.0,
        }
    }
}

/// The outcome of [`screen`].
#[derive(Debug, Clone, PartialEq)]
pub struct Screened {
    /// The samples kept, in their order.
    pub kept: Vec<TruthSample>,
    /// How many were left out.
    pub dropped: usize,
    /// The largest horizontal distance from a fix among those left out (finite ones), m.
    pub worst_m: f64,
}

impl Screened {
    /// A note for the reference's name (`None` when nothing was left out).
    pub fn note(&self, params: &ScreenParams) -> Option<String> {
        (self.dropped > 0).then(|| {
            format!(
                "{} of {} samples left out as implausibly far from the GNSS fixes (over {:.0} m, \
                 plus {:.0} m/s of the time to the nearest fix; up to {:.0} m)",
                self.dropped,
                self.dropped + self.kept.len(),
                params.min_gate_m,
                params.max_speed_mps,
                self.worst_m
            )
        })
    }
}

/// Leaves out the reference samples whose horizontal position is farther from the GNSS fix
/// nearest in time than `max(min_gate_m, gate_sigmas · σ_h) + max_speed_mps · |Δt|`, and the
/// non-finite ones. Without any fix, only the finite test applies. `fixes` must be sorted by
/// time.
pub fn screen(samples: &[TruthSample], fixes: &[FixNed], params: &ScreenParams) -> Screened {
    let mut kept = Vec::with_capacity(samples.len());
    let (mut dropped, mut worst_m) = (0usize, 0.0f64);
    for s in samples {
        let finite = s.pos_ned_m.iter().all(|v| v.is_finite())
            && s.nav_from_body.coords.iter().all(|v| v.is_finite());
        let distance_m = nearest(fixes, s.t_ns).and_then(|f| {
            let d = (s.pos_ned_m - f.pos_ned_m).xy().norm();
            let age_s = (f.t_ns - s.t_ns).unsigned_abs() as f64 * 1e-9;
            let gate = params.min_gate_m.max(params.gate_sigmas * f.sigma_h_m)
                + params.max_speed_mps * age_s;
            (d > gate || d.is_nan()).then_some(d)
        });
        if finite && distance_m.is_none() {
            kept.push(*s);
        } else {
            dropped += 1;
            if let Some(d) = distance_m.filter(|d| d.is_finite()) {
                worst_m = worst_m.max(d);
            }
        }
    }
    Screened {
        kept,
        dropped,
        worst_m,
    }
}

/// The fix nearest `t_ns` in time.
fn nearest(fixes: &[FixNed], t_ns: i64) -> Option<&FixNed> {
    let i = fixes.partition_point(|f| f.t_ns < t_ns);
    [i.checked_sub(1), Some(i)]
        .into_iter()
        .flatten()
        .filter_map(|k| fixes.get(k))
        .min_by_key(|f| (f.t_ns - t_ns).unsigned_abs())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    fn sample(t_s: i64, north_m: f64) -> TruthSample {
        TruthSample {
            t_ns: t_s * 1_000_000_000,
            pos_ned_m: Vector3::new(north_m, 0.0, -10.0),
            nav_from_body: UnitQuaternion::identity(),
            vel_ned_mps: Vector3::zeros(),
            gyro_bias_radps: Vector3::zeros(),
            accel_bias_mps2: Vector3::zeros(),
        }
    }

    fn fix(t_s: i64, north_m: f64, sigma_h_m: f64) -> FixNed {
        FixNed {
            t_ns: t_s * 1_000_000_000,
            pos_ned_m: Vector3::new(north_m, 0.0, -10.0),
            sigma_h_m,
        }
    }

    #[test]
    fn a_reference_far_from_the_fixes_is_left_out_and_said() {
        let p = ScreenParams::default();
        // An autopilot estimate that follows the fixes, then sits 1,000 km away (as a diverged
        // EKF1 does), then comes back; one sample is NaN. 51 s after the last fix (an outage),
        // 5 km away is within reach and kept, 1,000 km is not.
        let fixes: Vec<_> = (0..10).map(|t| fix(t, t as f64, 1.0)).collect();
        let mut samples: Vec<_> = (0..10).map(|t| sample(t, t as f64 + 3.0)).collect();
        samples[4].pos_ned_m.x = 1.0e6;
        samples[5].pos_ned_m.x = 1.0e6;
        samples[6].pos_ned_m.x = f64::NAN;
        samples.push(sample(60, 5_000.0));
        samples.push(sample(61, 1.0e6));
        let s = screen(&samples, &fixes, &p);
        assert_eq!(s.dropped, 4);
        assert_eq!(s.kept.len(), 8);
        assert!(
            s.kept
                .iter()
                .all(|k| k.pos_ned_m.x < 20.0 || k.t_ns == 60_000_000_000)
        );
        assert!((s.worst_m - 999_996.0).abs() < 1e-6, "{}", s.worst_m);
        let note = s.note(&p).expect("a note");
        assert!(
            note.starts_with("4 of 12 samples left out as implausibly far"),
            "{note}"
        );
    }

    #[test]
    fn the_gate_widens_with_a_poor_receiver_and_nothing_is_said_when_all_is_kept() {
        let p = ScreenParams::default();
        // 150 m off a fix whose σ is 10 m (gate 200 m): kept; with a 1 m fix (gate 100 m): left out.
        let kept = screen(&[sample(1, 150.0)], &[fix(1, 0.0, 10.0)], &p);
        assert_eq!((kept.dropped, kept.note(&p)), (0, None));
        let dropped = screen(&[sample(1, 150.0)], &[fix(1, 0.0, 1.0)], &p);
        assert_eq!(dropped.dropped, 1);
        assert!((dropped.worst_m - 150.0).abs() < 1e-9);
    }
}
