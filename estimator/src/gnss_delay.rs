//! The GNSS velocity's own delay, learnt from the data (our addition; `eskf` only).
//!
//! A fix stamped `t` was valid at `t − delay`, and the configured delay (a flight log's
//! `EK*_GPS_DELAY`, 0.22 s by default on ArduPilot) is what the autopilot assumed, not what the
//! hardware did. On the public ArduPilot logs the GNSS velocity lags the IMU by 0.16–0.28 s on the
//! copters but by 0.00–0.04 s on both fixed wings, whose velocities were then fused 0.22 s before
//! they were valid: a turn at 4 m/s² then reads as a 0.9 m/s velocity error, which the filter puts
//! into its tilt. The delay is a property of the receiver and of how its messages are stamped, so
//! it is learnt per vehicle rather than chosen per airframe. Only the velocity's: the positions
//! keep the configured delay (`eskf/delay.rs` carries each velocity to their time, eq. L2).
//!
//! **Eq. L1.** Over a window of stamps `[t0, t1]`, the change of the GNSS velocity equals the
//! integral of the horizontal kinematic acceleration over the window shifted by the delay `d`:
//! `r(d) = (v(t1) − v(t0)) − ∫_{t0−d}^{t1−d} a dt`, `a = (R(q) (f − b_a))_{NE}` (the specific
//! force rotated by the filter's attitude at the horizon less its accelerometer bias; gravity has
//! no horizontal part). Every candidate `d` of a grid around the configured delay accumulates
//! `|r(d)|²` over disjoint windows of about a second. The smallest sum, refined by a parabola, is
//! taken once it beats the delay in use by [`EVIDENCE`] in units of the residual variance (a
//! hover, whose acceleration is nil, tells nothing and moves nothing). The delay in use then moves
//! towards it by at most [`STEP_NS`] per fix.
//!
//! Lifecycle: windows are taken only while the heading is aligned (the acceleration is rotated by
//! it) and the IMU runs without gaps ([`GnssDelayLearner::interrupt`] breaks the integral); a
//! filter rebuilt from scratch learns again from the configured delay.

use std::collections::VecDeque;

/// Spacing of the candidate delays, ns.
pub const GRID_STEP_NS: i64 = 20_000_000;
/// Candidates below the configured delay (0.4 s: a log whose stamps already had 0.22 s taken
/// off, as the shared flights' folders have, is found at −0.22 s of a configured 0).
pub const GRID_BELOW: usize = 20;
/// Candidates above the configured delay (0.1 s: a velocity older than its position is carried
/// forward from the few samples kept behind the horizon, the rest at the oldest one's value).
pub const GRID_ABOVE: usize = 5;
const GRID_LEN: usize = GRID_BELOW + GRID_ABOVE + 1;
/// The window between the two fixes of a pair, ns: long enough for the acceleration to build a
/// velocity change well above the receiver's noise, short enough for the filter's attitude and
/// bias errors to stay small in the integral.
pub const WINDOW_NS: i64 = 1_000_000_000;
/// A fix later than this after the previous one starts a new window instead (a gap).
pub const MAX_WINDOW_NS: i64 = 2_000_000_000;
/// Spacing of the stored knots of the acceleration's integral, ns: interpolated linearly, the
/// integral's error is about `jerk · Δt² / 8` (2 mm/s at 10 m/s³).
pub const KNOT_NS: i64 = 40_000_000;
/// How much of the integral is kept, ns: the longest window and the grid's span.
pub const KNOT_SPAN_NS: i64 = 2_600_000_000;
/// Bound on the knots kept (24 bytes each: about 3 kB per vehicle with the deque's growth).
pub const MAX_KNOTS: usize = (KNOT_SPAN_NS / KNOT_NS) as usize + 8;
/// Bound on the windows waiting for the horizon to cover them.
pub const MAX_PENDING: usize = 8;
/// Windows needed before the delay may move.
pub const MIN_WINDOWS: u32 = 30;
/// How much smaller the best candidate's sum must be than the sum at the delay in use, in units
/// of the residual variance per window, before the delay moves (a likelihood ratio of e^12.5).
pub const EVIDENCE: f64 = 25.0;
/// Each window's weight decays by this per later window (a memory of about 100 windows, under
/// two minutes): the attitude the early windows were integrated with was itself pulled by the
/// wrong delay, towards it, and so was their minimum.
pub const FORGET: f64 = 0.99;
/// A window whose best residual is larger than this, m/s, is left out: a GNSS glitch or an
/// integration broken by something else says nothing about the delay.
pub const MAX_RESIDUAL_MPS: f64 = 1.5;
/// The largest change of the delay in use per fix, ns: the velocity's correction changes
/// smoothly, by at most `|a| · 20 ms` from one fix to the next.
pub const STEP_NS: i64 = 20_000_000;

/// A pair of GNSS velocities waiting for the integral to cover it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Window {
    t0_ns: i64,
    v0: [f64; 2],
    t1_ns: i64,
    v1: [f64; 2],
}

/// What the learner shows (health and the report).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DelayDiag {
    /// The delay in use, s.
    pub delay_s: f64,
    /// Windows accumulated.
    pub windows: u32,
    /// Windows left out for a residual above [`MAX_RESIDUAL_MPS`].
    pub outliers: u32,
    /// The evidence of the last test (see [`EVIDENCE`]).
    pub evidence: f64,
}

/// Learns the effective GNSS delay (eq. L1).
#[derive(Debug, Clone, PartialEq)]
pub struct GnssDelayLearner {
    configured_ns: i64,
    delay_ns: i64,
    target_ns: i64,
    cost: [f64; GRID_LEN],
    windows: u32,
    /// The windows' summed weight (see [`FORGET`]).
    weight: f64,
    outliers: u32,
    evidence: f64,
    /// `(t_ns, ∫a dt north, east)` at the horizon, oldest first, contiguous.
    knots: VecDeque<(i64, [f64; 2])>,
    /// The running integral and the time it is at.
    cum: [f64; 2],
    cum_t_ns: Option<i64>,
    anchor: Option<(i64, [f64; 2])>,
    pending: VecDeque<Window>,
}

impl GnssDelayLearner {
    /// A learner starting from the configured delay.
    pub fn new(configured_ns: i64) -> Self {
        Self {
            configured_ns,
            delay_ns: configured_ns,
            target_ns: configured_ns,
            cost: [0.0; GRID_LEN],
            windows: 0,
            weight: 0.0,
            outliers: 0,
            evidence: 0.0,
            knots: VecDeque::new(),
            cum: [0.0; 2],
            cum_t_ns: None,
            anchor: None,
            pending: VecDeque::new(),
        }
    }

    /// The delay learnt (the configured one until the data say otherwise), ns.
    pub fn delay_ns(&self) -> i64 {
        self.delay_ns
    }

    /// The configured delay, ns.
    pub fn configured_ns(&self) -> i64 {
        self.configured_ns
    }

    /// Diagnostics.
    pub fn diag(&self) -> DelayDiag {
        DelayDiag {
            delay_s: self.delay_ns as f64 * 1e-9,
            windows: self.windows,
            outliers: self.outliers,
            evidence: self.evidence,
        }
    }

    fn candidate_ns(&self, i: usize) -> i64 {
        self.configured_ns
            .saturating_add((i as i64 - GRID_BELOW as i64) * GRID_STEP_NS)
    }

    /// The integral can no longer be continued (heading not aligned, IMU gap, filter restart).
    pub fn interrupt(&mut self) {
        self.knots.clear();
        self.cum_t_ns = None;
    }

    /// Adds the horizontal kinematic acceleration `a_ne` (m/s²) over the IMU interval
    /// `[t0_ns, t1_ns]` at the horizon, then evaluates the windows it now covers.
    pub fn push_accel(&mut self, t0_ns: i64, t1_ns: i64, a_ne: [f64; 2]) {
        if t1_ns <= t0_ns || !(a_ne[0].is_finite() && a_ne[1].is_finite()) {
            self.interrupt();
            return;
        }
        if self.cum_t_ns != Some(t0_ns) {
            self.knots.clear();
            self.knots.push_back((t0_ns, self.cum));
        }
        let dt_s = t1_ns.saturating_sub(t0_ns) as f64 * 1e-9;
        self.cum[0] += a_ne[0] * dt_s;
        self.cum[1] += a_ne[1] * dt_s;
        self.cum_t_ns = Some(t1_ns);
        if self
            .knots
            .back()
            .is_none_or(|k| t1_ns.saturating_sub(k.0) >= KNOT_NS)
        {
            if self.knots.len() >= MAX_KNOTS {
                self.knots.pop_front();
            }
            self.knots.push_back((t1_ns, self.cum));
        }
        while self
            .knots
            .front()
            .is_some_and(|k| t1_ns.saturating_sub(k.0) > KNOT_SPAN_NS)
        {
            self.knots.pop_front();
        }
        self.evaluate_ready();
    }

    /// Adds a GNSS velocity (north, east, m/s) at its stamp (as it arrived, before any delay is
    /// taken off), then moves the delay in use one step towards the learnt one.
    pub fn push_velocity(&mut self, stamp_ns: i64, v_ne: [f64; 2]) {
        // Saturating: stamps are only known to increase, not to be near each other.
        match self
            .anchor
            .map(|(t0, v0)| (t0, v0, stamp_ns.saturating_sub(t0)))
        {
            Some((t0, v0, span)) if (WINDOW_NS..=MAX_WINDOW_NS).contains(&span) => {
                if self.pending.len() >= MAX_PENDING {
                    self.pending.pop_front();
                }
                self.pending.push_back(Window {
                    t0_ns: t0,
                    v0,
                    t1_ns: stamp_ns,
                    v1: v_ne,
                });
                self.anchor = Some((stamp_ns, v_ne));
            }
            Some((_, _, span)) if span > 0 && span < WINDOW_NS => {}
            _ => self.anchor = Some((stamp_ns, v_ne)),
        }
        let step = self
            .target_ns
            .saturating_sub(self.delay_ns)
            .clamp(-STEP_NS, STEP_NS);
        self.delay_ns = self.delay_ns.saturating_add(step);
    }

    /// The integral at `t_ns`, interpolated between knots; `None` outside them.
    fn integral_at(&self, t_ns: i64) -> Option<[f64; 2]> {
        let (first, last) = (self.knots.front()?, self.knots.back()?);
        if t_ns < first.0 || t_ns > last.0 {
            return None;
        }
        let i = self.knots.partition_point(|k| k.0 <= t_ns);
        let (a, b) = (self.knots[i.saturating_sub(1)], self.knots.get(i).copied());
        let Some(b) = b else { return Some(a.1) };
        let w = (t_ns - a.0) as f64 / (b.0 - a.0).max(1) as f64;
        Some([
            a.1[0] + w * (b.1[0] - a.1[0]),
            a.1[1] + w * (b.1[1] - a.1[1]),
        ])
    }

    fn evaluate_ready(&mut self) {
        // The knots, not the running integral, are what a window is read from.
        let Some(last_t) = self.knots.back().map(|k| k.0) else {
            return;
        };
        let lo = self.candidate_ns(0);
        while let Some(w) = self.pending.front().copied() {
            if w.t1_ns.saturating_sub(lo) > last_t {
                return; // the horizon has not reached the window's latest shift yet
            }
            self.pending.pop_front();
            let mut r2 = [0.0; GRID_LEN];
            let mut covered = true;
            for (i, r) in r2.iter_mut().enumerate() {
                let d = self.candidate_ns(i);
                let (Some(a), Some(b)) = (
                    self.integral_at(w.t0_ns.saturating_sub(d)),
                    self.integral_at(w.t1_ns.saturating_sub(d)),
                ) else {
                    covered = false;
                    break;
                };
                let rn = (w.v1[0] - w.v0[0]) - (b[0] - a[0]);
                let re = (w.v1[1] - w.v0[1]) - (b[1] - a[1]);
                *r = rn * rn + re * re;
            }
            if !covered {
                continue;
            }
            if r2.iter().copied().fold(f64::INFINITY, f64::min) > MAX_RESIDUAL_MPS.powi(2) {
                self.outliers = self.outliers.saturating_add(1);
                continue;
            }
            for (c, r) in self.cost.iter_mut().zip(r2) {
                *c = *c * FORGET + r;
            }
            self.weight = self.weight * FORGET + 1.0;
            self.windows = self.windows.saturating_add(1);
            self.decide();
        }
    }

    /// The cost at `d_ns`, interpolated linearly on the grid.
    fn cost_at(&self, d_ns: i64) -> f64 {
        let x = d_ns.saturating_sub(self.candidate_ns(0)) as f64 / GRID_STEP_NS as f64;
        let x = x.clamp(0.0, (GRID_LEN - 1) as f64);
        let i = (x.floor() as usize).min(GRID_LEN - 2);
        let w = x - i as f64;
        self.cost[i] * (1.0 - w) + self.cost[i + 1] * w
    }

    fn decide(&mut self) {
        if self.windows < MIN_WINDOWS {
            return;
        }
        let (best, c_min) =
            self.cost
                .iter()
                .copied()
                .enumerate()
                .fold(
                    (0, f64::INFINITY),
                    |m, (i, c)| if c < m.1 { (i, c) } else { m },
                );
        // Residual variance per window (two axes), floored at the receiver's usual velocity noise.
        let var = (c_min / self.weight).max(2.0 * 0.05f64.powi(2));
        self.evidence = (self.cost_at(self.delay_ns) - c_min) / var;
        if self.evidence <= EVIDENCE {
            return;
        }
        // A parabola through the best point and its neighbours (an interior minimum).
        let mut d = self.candidate_ns(best) as f64;
        if best > 0 && best + 1 < GRID_LEN {
            let (l, m, r) = (self.cost[best - 1], self.cost[best], self.cost[best + 1]);
            let den = l - 2.0 * m + r;
            if den > 0.0 {
                d += (0.5 * (l - r) / den).clamp(-0.5, 0.5) * GRID_STEP_NS as f64;
            }
        }
        self.target_ns = d.round() as i64;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vehicle swinging sinusoidally east (acceleration `A sin ωt`), its receiver reporting the
    /// velocity `true_delay_ns` late, stamps every 0.2 s; the filter configured with
    /// `configured_ns`.
    fn learn(configured_ns: i64, true_delay_ns: i64, amplitude_mps2: f64) -> GnssDelayLearner {
        let mut l = GnssDelayLearner::new(configured_ns);
        let w = 2.0 * std::f64::consts::PI / 4.0;
        let v = |t_s: f64| amplitude_mps2 / w * (1.0 - (w * t_s).cos());
        let dt_ns = 10_000_000;
        let horizon_lag_ns = 200_000_000 + configured_ns.max(0);
        let mut next_fix_ns = 0;
        for k in 0..12_000i64 {
            let t_ns = k * dt_ns;
            // The receiver's fix stamped `t_ns` carries the velocity of `t_ns - true_delay`.
            if t_ns >= next_fix_ns {
                let tv = (t_ns - true_delay_ns) as f64 * 1e-9;
                l.push_velocity(t_ns, [0.0, v(tv)]);
                next_fix_ns += 200_000_000;
            }
            // The horizon integrates behind the newest sample.
            let h0 = t_ns - horizon_lag_ns;
            let h1 = h0 + dt_ns;
            let tm = (h0 + h1) as f64 * 0.5e-9;
            l.push_accel(h0, h1, [0.0, amplitude_mps2 * (w * tm).sin()]);
        }
        l
    }

    #[test]
    fn finds_a_shorter_delay_than_configured() {
        let l = learn(220_000_000, 0, 2.0);
        assert!(l.delay_ns().abs() < 10_000_000, "{:?}", l.diag());
    }

    #[test]
    fn finds_a_negative_delay_of_pre_shifted_stamps() {
        let l = learn(0, -220_000_000, 2.0);
        assert!(
            (l.delay_ns() + 220_000_000).abs() < 10_000_000,
            "{:?}",
            l.diag()
        );
    }

    #[test]
    fn keeps_the_configured_delay_when_it_is_right() {
        let l = learn(220_000_000, 220_000_000, 2.0);
        assert_eq!(l.delay_ns(), 220_000_000, "{:?}", l.diag());
    }

    #[test]
    fn a_vehicle_that_does_not_accelerate_moves_nothing() {
        let l = learn(220_000_000, 0, 0.0);
        assert_eq!(l.delay_ns(), 220_000_000, "{:?}", l.diag());
    }

    #[test]
    fn extreme_stamps_neither_overflow_nor_move_the_delay() {
        let mut l = GnssDelayLearner::new(200_000_000);
        l.push_velocity(i64::MIN + 1, [0.0, 0.0]);
        l.push_velocity(i64::MAX, [1.0, 0.0]);
        l.push_accel(i64::MIN, i64::MIN + 10, [1.0, 0.0]);
        l.push_accel(i64::MAX - 10, i64::MAX, [1.0, 0.0]);
        l.push_velocity(i64::MAX, [1.0, 0.0]);
        assert_eq!(l.delay_ns(), 200_000_000);
        assert_eq!(l.cost_at(i64::MIN), 0.0);
    }

    #[test]
    fn an_interrupted_integral_covers_no_window() {
        let ms = 1_000_000;
        let mut l = GnssDelayLearner::new(0);
        l.push_accel(0, 50 * ms, [1.0, 0.0]);
        assert!(l.integral_at(25 * ms).is_some());
        l.interrupt();
        assert_eq!(l.integral_at(25 * ms), None);
        l.push_accel(60 * ms, 110 * ms, [1.0, 0.0]);
        assert_eq!(l.integral_at(55 * ms), None);
        let i = l.integral_at(85 * ms).unwrap();
        assert!((i[0] - l.integral_at(60 * ms).unwrap()[0] - 0.025).abs() < 1e-12);
    }
}
