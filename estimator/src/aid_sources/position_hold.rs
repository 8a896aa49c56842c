//! Position hold: the pseudo-measurement that keeps an `eskf` with no position or velocity source
//! bounded (PX4 EKF2's "fake position" fusion).
//!
//! Without GNSS (or vision translation) nothing observes the velocity: integrated accelerometer
//! errors grow it without bound, and with it the tilt is no longer held (the tilt is seen only
//! through where the specific force, rotated by it, takes the velocity). Fusing "the vehicle is
//! within `σ` of where it was" (eq. H1: `z = p_hold`, `h(x) = p`, `H = [I 0 …]`, `R = σ² I`) says
//! the mean acceleration over tens of seconds is nearly zero, which makes the tilt observable
//! from gravity, as an AHRS does, while the position and velocity it implies are not reported
//! ([`crate::Mode::AttitudeOnly`]).
//!
//! A vehicle that really travels from the hold point is not refused (that would leave the
//! velocity unbounded again): the measurement's variance is raised until the innovation sits on
//! the gate (a Huber-type weight), so a true displacement of `d ≫ σ` pulls only as hard as one of
//! a few `σ`.
//!
//! Lifecycle:
//! * **off** until the filter starts without GNSS (`eskf::gnssless`), or until a filter that had
//!   GNSS has dead-reckoned past what it can (`eskf::outage`: held where it was then);
//! * **active**: fused every [`HOLD_PERIOD_NS`] at the horizon; the vertical only when nothing
//!   else holds the height (a barometer does); no other position or velocity source runs
//!   meanwhile (vision gives rotation only without GNSS);
//! * **stopped** once GNSS is back (a filter started without GNSS is rebuilt; after an outage the
//!   fix resets the position and velocity); a later outage starts it again.
//!
//! Diagnostics: the innovation, its variance and the test ratio before the weighting; a
//! down-weighted update counts as `rejected` (the vehicle is moving away from the hold point).

use nalgebra::{SMatrix, SVector};

use super::{InnovDiag, UpdateOutcome, chi2_gate, gated_update};
use crate::state::{Cov, ErrVec, IP, N, Nominal};

/// Interval between two hold updates, ns (PX4 fuses its fake position at the filter rate; the
/// information per update only matters through `σ²/T`, and 5 Hz keeps the cost negligible).
pub const HOLD_PERIOD_NS: i64 = 200_000_000;

/// State of the source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum HoldState {
    /// Not fusing (the filter has not started without GNSS).
    #[default]
    Off,
    /// Fusing the hold point.
    Active,
    /// Stopped: GNSS is back (an outage later starts it again).
    Stopped,
}

/// The position-hold source.
#[derive(Debug, Clone, PartialEq)]
pub struct PositionHold {
    /// Lifecycle state.
    pub state: HoldState,
    /// Innovation diagnostics.
    pub diag: InnovDiag,
    /// The point held, local NED, m.
    pub point_ned_m: Option<nalgebra::Vector3<f64>>,
    last_t_ns: Option<i64>,
}

impl Default for PositionHold {
    fn default() -> Self {
        Self {
            state: HoldState::Off,
            diag: InnovDiag::new(),
            point_ned_m: None,
            last_t_ns: None,
        }
    }
}

impl PositionHold {
    /// Starts holding at the filter's position (kept if already holding).
    pub fn start(&mut self, x: &Nominal) {
        if self.state == HoldState::Stopped {
            return;
        }
        if self.point_ned_m.is_none() {
            self.point_ned_m = Some(x.p);
        }
        self.state = HoldState::Active;
    }

    /// Starts holding at the filter's position now, after an outage of the position sources (a
    /// hold stopped before starts afresh there).
    pub fn start_in_outage(&mut self, x: &Nominal) {
        self.point_ned_m = Some(x.p);
        self.last_t_ns = None;
        self.state = HoldState::Active;
    }

    /// Stops (GNSS is back); the point is forgotten.
    pub fn stop(&mut self) {
        self.state = HoldState::Stopped;
        self.point_ned_m = None;
    }

    /// Fuses the hold point at `t_ns` when active and due (eq. H1); `vertical` also holds the
    /// height. Returns the correction to inject.
    pub fn fuse(
        &mut self,
        x: &Nominal,
        p: &mut Cov,
        t_ns: i64,
        sigma_m: f64,
        vertical: bool,
        gate_sigma: f64,
    ) -> Option<ErrVec> {
        if self.state != HoldState::Active {
            return None;
        }
        if self.last_t_ns.is_some_and(|l| t_ns - l < HOLD_PERIOD_NS) {
            return None;
        }
        self.last_t_ns = Some(t_ns);
        let point = self.point_ned_m?;
        let y = point - x.p;
        if vertical {
            self.update::<3>(p, &y, sigma_m, gate_sigma, t_ns)
        } else {
            self.update::<2>(p, &y.xy(), sigma_m, gate_sigma, t_ns)
        }
    }

    fn update<const M: usize>(
        &mut self,
        p: &mut Cov,
        y: &SVector<f64, M>,
        sigma_m: f64,
        gate_sigma: f64,
        t_ns: i64,
    ) -> Option<ErrVec> {
        let mut h = SMatrix::<f64, M, N>::zeros();
        for k in 0..M {
            h[(k, IP + k)] = 1.0;
        }
        // The test ratio with the nominal σ; beyond the gate the variance is scaled so that the
        // innovation sits on it (`NIS(λR) ≤ NIS(R)/λ` for λ ≥ 1, so λ = ratio is enough).
        let mut s = SMatrix::<f64, M, M>::identity() * (sigma_m * sigma_m);
        for a in 0..M {
            for b in 0..M {
                s[(a, b)] += p[(IP + a, IP + b)];
            }
        }
        let nis = s.cholesky().map(|c| y.dot(&c.solve(y)))?;
        let ratio = nis / chi2_gate(M, gate_sigma);
        let weight = ratio.max(1.0);
        let r = SMatrix::<f64, M, M>::identity() * (sigma_m * sigma_m * weight);
        let mut diag = self.diag;
        let out = gated_update(p, &h, &r, y, gate_sigma, t_ns, true, &mut diag);
        diag.test_ratio = ratio;
        if ratio > 1.0 {
            diag.rejected += 1;
        }
        self.diag = diag;
        match out {
            UpdateOutcome::Fused(dx) => Some(dx),
            UpdateOutcome::Rejected | UpdateOutcome::Singular => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{UnitQuaternion, Vector3};

    use super::*;

    fn nominal(p: Vector3<f64>) -> Nominal {
        Nominal {
            t_ns: 0,
            p,
            v: Vector3::zeros(),
            q: UnitQuaternion::identity(),
            bg: Vector3::zeros(),
            ba: Vector3::zeros(),
            gm: Vector3::zeros(),
            clone: None,
        }
    }

    #[test]
    fn a_near_hold_is_an_ordinary_update_and_a_far_one_is_down_weighted() {
        let mut hold = PositionHold::default();
        hold.start(&nominal(Vector3::zeros()));
        let mut p = Cov::identity() * 25.0;
        // 3 m off with σ 10 m and 5 m of state σ: fused at face value, K = 25 / 125.
        let dx = hold
            .fuse(
                &nominal(Vector3::new(3.0, 0.0, 0.0)),
                &mut p,
                0,
                10.0,
                false,
                3.29,
            )
            .expect("fused");
        assert!((dx[IP] + 3.0 * 25.0 / 125.0).abs() < 1e-12, "{}", dx[IP]);
        assert!(hold.diag.test_ratio < 1.0 && hold.diag.rejected == 0);
        // Not again within the period.
        assert!(
            hold.fuse(
                &nominal(Vector3::zeros()),
                &mut p,
                HOLD_PERIOD_NS - 1,
                10.0,
                false,
                3.29
            )
            .is_none()
        );
        // 500 m away: beyond the gate, fused with the variance scaled so the pull stays that of
        // an innovation on the gate (at most √(χ²₂) ≈ 3.6 of the innovation σ).
        let mut p = Cov::identity() * 25.0;
        let dx = hold
            .fuse(
                &nominal(Vector3::new(500.0, 0.0, 0.0)),
                &mut p,
                HOLD_PERIOD_NS,
                10.0,
                false,
                3.29,
            )
            .expect("fused, down-weighted");
        let pull = -dx[IP];
        assert!(pull > 0.0 && pull < 3.7 * 125f64.sqrt(), "{pull}");
        assert!(hold.diag.test_ratio > 1.0 && hold.diag.rejected == 1);
        // Vertical untouched without `vertical`.
        assert_eq!(dx[IP + 2], 0.0);
        hold.stop();
        assert!(
            hold.fuse(
                &nominal(Vector3::zeros()),
                &mut p,
                10 * HOLD_PERIOD_NS,
                10.0,
                true,
                3.29
            )
            .is_none()
        );
    }
}
