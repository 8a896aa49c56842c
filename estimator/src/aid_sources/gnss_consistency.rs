//! How far a receiver's velocity can be trusted beyond its own σ: the consistency of its
//! velocities with its own positions, measured on the fixes alone (eq. V1 below).
//!
//! A receiver reports a per-fix velocity σ as if its errors were white. Fused that way at 5 Hz,
//! the velocities pin the integrated position to a few decimetres over ten seconds. Real
//! receivers' velocity errors are time-correlated: on the shared real ArduPilot plane, the
//! reported velocities integrated over 5 s fall 3.5 m short of the reported positions (about
//! 0.7 m/s along track and 0.6 m/s across it, for minutes on end; 0.2–0.3 m/s on the copters),
//! so the filter followed the integrated velocity and parked the difference in the GNSS position
//! error state (6 m from the fixes).
//!
//! Eq. V1: over a window of `W` seconds of consecutive fixes, the discrepancy
//! `D = (p_end − p_start) − ∫ v dt` (trapezoid over the fixes) has, under the receiver's own
//! model, the variance `2 σ_p² + Σ σ_v² dt² / 2` per axis. The excess of `D²` over it, divided by
//! `W²`, is the mean-square velocity error that persisted over the window, `b²`. Fusing `n`
//! velocities of a window as white noise of variance `σ_v² + b² n` makes their sum as uncertain
//! as the persistent error makes it, so the filter leaves the long-term position to the
//! positions. `b²` follows the worst recent excess of three windows together, when they
//! together exceed what the model expects by [`SIGNIFICANT_RATIO`], and relaxes with `release_s`.
//!
//! Diagnostics only need the fixes, so the monitor runs whether or not velocities are fused.

use nalgebra::Vector3;

use super::gnss_pos::GnssMeas;

/// Parameters of the velocity-consistency monitor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConsistencyParams {
    /// Window over which positions and integrated velocities are compared, s (`W` of eq. V1):
    /// long enough that the position noise of its two ends is small against the integral, short
    /// enough to follow a changing manoeuvre.
    pub window_s: f64,
    /// Time constant with which the persistent error `b²` relaxes after a worse window, s.
    pub release_s: f64,
    /// Largest gap between fixes that keeps a window going, s; a longer gap restarts it.
    pub max_gap_s: f64,
}

impl Default for ConsistencyParams {
    fn default() -> Self {
        Self {
            window_s: 5.0,
            release_s: 60.0,
            max_gap_s: 1.0,
        }
    }
}

/// Windows whose discrepancies are summed before they may raise `b²`: one window's `D²` is a
/// single chi-square draw, and a maximum over such draws read the noise's tail as a persistent
/// error (a simulated receiver whose positions wander with a 20 s correlation time, velocities
/// white: one window 9 % over its expectation held `b²` for a minute, its velocities were fused
/// with σ 0.4 m/s instead of 0.05 and the filter's vertical velocity followed the wandering
/// positions, 0.5 m/s off at a σ of 0.06).
const RECENT_WINDOWS: usize = 3;

/// How far the recent windows' summed `D²` must exceed its expectation before the excess counts:
/// white positions pass 1.3 times their expectation over three windows in 27 % (vertical, 3
/// degrees of freedom) and 25 % (horizontal, 6) of the draws, and less with receivers, whose
/// stated σ includes the slow part of their error; the shared real plane's windows in flight run
/// 2–5 times over. 1.3 rather than 2: with 2, plane_E's roll / pitch were 1.86 / 1.79° against
/// 1.75 / 1.73° (1.74 / 1.82° with one window at a time): real receivers' velocities carry small
/// persistent errors that a higher threshold leaves unmeasured.
const SIGNIFICANT_RATIO: f64 = 1.3;

#[derive(Debug, Clone, Copy, PartialEq)]
struct Window {
    t0_ns: i64,
    p0: Vector3<f64>,
    last_t_ns: i64,
    last_v: Vector3<f64>,
    /// ∫ v dt over the window, m.
    integral: Vector3<f64>,
    /// Σ σ_v² dt² / 2 over the window (variance of the integral per axis), m².
    integral_var: f64,
    /// Fixes in the window after its first.
    n: u32,
    sigma_h0: f64,
    sigma_v0: f64,
}

/// The velocity-consistency monitor of one receiver.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct VelConsistency {
    window: Option<Window>,
    /// Persistent horizontal / vertical velocity error `b²` per axis, (m/s)².
    pub persistent_var: [f64; 2],
    /// The last [`RECENT_WINDOWS`] windows' `[D² / W², E[D²] / W²]`, horizontal and vertical,
    /// (m/s)².
    recent: [[[f64; 2]; 2]; RECENT_WINDOWS],
    /// Fixes per window in the last completed window (`n` of eq. V1).
    pub fixes_per_window: f64,
    /// Windows completed.
    pub windows: u64,
}

impl VelConsistency {
    /// Takes one fix (in time order).
    pub fn push(&mut self, m: &GnssMeas, params: &ConsistencyParams) {
        let Some(v) = m.vel_ned_mps else {
            self.window = None;
            return;
        };
        let fresh = Window {
            t0_ns: m.t_ns,
            p0: m.pos_ned_m,
            last_t_ns: m.t_ns,
            last_v: v,
            integral: Vector3::zeros(),
            integral_var: 0.0,
            n: 0,
            sigma_h0: m.sigma_h_m,
            sigma_v0: m.sigma_v_m,
        };
        let Some(w) = self.window.as_mut() else {
            self.window = Some(fresh);
            return;
        };
        let dt_s = (m.t_ns - w.last_t_ns) as f64 * 1e-9;
        if !(dt_s > 0.0 && dt_s <= params.max_gap_s) {
            self.window = Some(fresh);
            return;
        }
        w.integral += (v + w.last_v) * (0.5 * dt_s);
        w.integral_var += m.sigma_vel_mps.powi(2) * dt_s * dt_s / 2.0;
        w.last_t_ns = m.t_ns;
        w.last_v = v;
        w.n += 1;
        let span_s = (m.t_ns - w.t0_ns) as f64 * 1e-9;
        if span_s < params.window_s {
            return;
        }
        // Eq. V1, horizontal (mean of N and E) and vertical.
        let d = (m.pos_ned_m - w.p0) - w.integral;
        let pos_var_h = w.sigma_h0.powi(2) + m.sigma_h_m.powi(2);
        let pos_var_v = w.sigma_v0.powi(2) + m.sigma_v_m.powi(2);
        // Observed D² and its expectation under the receiver's model, per window, over W².
        let span2 = span_s * span_s;
        let obs = [0.5 * (d.x * d.x + d.y * d.y), d.z * d.z];
        let expected = [pos_var_h + w.integral_var, pos_var_v + w.integral_var];
        let slot = (self.windows % RECENT_WINDOWS as u64) as usize;
        if self.windows == 0 {
            // Windows not yet measured count as what the model expects: a first window alone
            // is one draw too.
            self.recent = [[[expected[0] / span2; 2], [expected[1] / span2; 2]]; RECENT_WINDOWS];
        }
        self.recent[slot] = [
            [obs[0] / span2, expected[0] / span2],
            [obs[1] / span2, expected[1] / span2],
        ];
        let keep = (-span_s / params.release_s.max(1e-3)).exp();
        for (axis, b2) in self.persistent_var.iter_mut().enumerate() {
            let (o, e) = self
                .recent
                .iter()
                .fold((0.0, 0.0), |(o, e), r| (o + r[axis][0], e + r[axis][1]));
            let excess = if o > SIGNIFICANT_RATIO * e {
                (o - e) / RECENT_WINDOWS as f64
            } else {
                0.0
            };
            *b2 = excess.max(*b2 * keep);
        }
        self.fixes_per_window = f64::from(w.n);
        self.windows += 1;
        self.window = Some(fresh);
    }

    /// The variance per axis (N, E, D) with which a fix's velocity is fused: its own σ² plus the
    /// persistent error spread over a window's fixes (eq. V1), (m/s)².
    pub fn velocity_var(&self, sigma_vel_mps: f64) -> Vector3<f64> {
        let n = self.fixes_per_window.max(1.0);
        let own = sigma_vel_mps * sigma_vel_mps;
        let [h, v] = self.persistent_var;
        Vector3::new(own + h * n, own + h * n, own + v * n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fix(t_ms: i64, p: Vector3<f64>, v: Vector3<f64>) -> GnssMeas {
        GnssMeas {
            t_ns: t_ms * 1_000_000,
            pos_ned_m: p,
            vel_ned_mps: Some(v),
            vel_h_mps: Some(v.xy()),
            sigma_h_m: 0.5,
            sigma_v_m: 0.8,
            sigma_vel_mps: 0.2,
        }
    }

    /// Fixes at 5 Hz of a vehicle at 10 m/s north whose receiver reports `v_bias` too little.
    fn run(v_bias: f64) -> VelConsistency {
        let mut c = VelConsistency::default();
        let p = ConsistencyParams::default();
        for k in 0..200 {
            let pos = Vector3::new(2.0 * k as f64, 0.0, 0.0);
            c.push(
                &fix(200 * k, pos, Vector3::new(10.0 - v_bias, 0.0, 0.0)),
                &p,
            );
        }
        c
    }

    #[test]
    fn consistent_velocities_are_not_inflated() {
        let c = run(0.0);
        assert!(c.windows >= 7);
        assert_eq!(c.persistent_var, [0.0, 0.0]);
        assert!((c.velocity_var(0.2) - Vector3::repeat(0.04)).norm() < 1e-12);
    }

    #[test]
    fn a_persistent_velocity_error_is_measured() {
        // 1 m/s too slow north: D = 5 m per 5 s window, half of it per horizontal axis in the
        // mean of N and E: b² = (12.5 − 0.5 − Σσ_v²dt²/2) / 25 ≈ 0.48 (m/s)².
        let c = run(1.0);
        let b2 = c.persistent_var[0];
        assert!((b2 - 0.48).abs() < 0.01, "{b2}");
        assert_eq!(c.persistent_var[1], 0.0);
        assert_eq!(c.fixes_per_window, 25.0);
        let r = c.velocity_var(0.2);
        assert!((r.x - (0.04 + 25.0 * b2)).abs() < 1e-9, "{r}");
    }

    #[test]
    fn one_window_in_the_noise_tail_is_not_a_persistent_error() {
        // A receiver at rest whose positions scatter as it says (σ 0.5 m per axis): the fix that
        // ends the first window and starts the second lands 1.1 m off, so both windows' D² run
        // 1.16 times their expectation. Two such draws are noise, not a velocity error (taken
        // one window at a time they read as a persistent 0.06 m/s, then held for a minute).
        let p = ConsistencyParams::default();
        let mut c = VelConsistency::default();
        for k in 0..200 {
            let y = if k == 25 { 1.1 } else { 0.0 };
            c.push(
                &fix(200 * k, Vector3::new(0.0, y, 0.0), Vector3::zeros()),
                &p,
            );
            assert_eq!(c.persistent_var, [0.0, 0.0], "fix {k}");
        }
        // Positions that keep drifting from the integrated velocities are measured: 0.25 m/s
        // east against velocities of 0.
        let mut c = VelConsistency::default();
        for k in 0..200 {
            let pos = Vector3::new(0.0, 0.05 * k as f64, 0.0);
            c.push(&fix(200 * k, pos, Vector3::zeros()), &p);
        }
        // D = 1.25 m per window, half of it per horizontal axis in the mean of N and E:
        // b² = (0.78 − 0.52) / 25.
        let b2 = c.persistent_var[0];
        assert!((b2 - (0.78125 - 0.52) / 25.0).abs() < 1e-3, "{b2}");
    }

    #[test]
    fn a_gap_restarts_the_window() {
        let mut c = VelConsistency::default();
        let p = ConsistencyParams::default();
        c.push(&fix(0, Vector3::zeros(), Vector3::zeros()), &p);
        // 2 s later, 100 m away: a gap, so the jump is in no window and nothing is measured.
        for k in 0..40 {
            let t_ms = 2_000 + 200 * k;
            c.push(
                &fix(t_ms, Vector3::new(100.0, 0.0, 0.0), Vector3::zeros()),
                &p,
            );
        }
        assert!(c.windows >= 1);
        assert_eq!(c.persistent_var, [0.0, 0.0]);
    }
}
