//! Fixed-wing kinematics from smooth commanded profiles, in closed form.
//!
//! Ground speed `V(t)`, yaw rate `ψ̇(t)` and flight-path angle `γ(t)` are each a constant plus a
//! sum of septic smooth steps (C³: value, first, second and third derivatives continuous). Heading
//! `ψ(t)` is their exact integral. From them, in the fixed local NED frame:
//!
//! - velocity `v = V (cos γ cos ψ, cos γ sin ψ, −sin γ)` and its exact derivative `a = dv/dt`;
//! - attitude `nav_from_body = Rz(ψ) · Ry(γ + α) · Rx(φ)` with the coordinated-turn bank
//!   `φ = atan(V ψ̇ / g0)` (g0 = standard gravity, a design constant), `α` a constant angle of attack;
//! - body rate `ω_nb^b` from the exact ZYX Euler-rate relation.
//!
//! Position is the integral of the velocity (Gauss–Legendre on each sample interval, exact to
//! rounding at the IMU rate). Everything the IMU sees is therefore analytic and smooth, so a careful
//! strapdown integrator reproduces the truth.

use nalgebra::{UnitQuaternion, Vector3};

use crate::scenario::{TrajectoryKind, TrajectorySpec};

/// Standard gravity used only to shape the coordinated-turn bank, m/s².
pub const BANK_DESIGN_G_MPS2: f64 = 9.806_65;

/// Septic smooth step s(u) on [0, 1]: s(0)=0, s(1)=1, first three derivatives zero at both ends.
fn smoothstep(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    u.powi(4) * (35.0 + u * (-84.0 + u * (70.0 - 20.0 * u)))
}

/// ds/du = 140 u³ (1 − u)³.
fn smoothstep_d(u: f64) -> f64 {
    if !(0.0..=1.0).contains(&u) {
        return 0.0;
    }
    140.0 * (u * (1.0 - u)).powi(3)
}

/// d²s/du² = 420 u² (1 − u)² (1 − 2u).
fn smoothstep_dd(u: f64) -> f64 {
    if !(0.0..=1.0).contains(&u) {
        return 0.0;
    }
    420.0 * (u * (1.0 - u)).powi(2) * (1.0 - 2.0 * u)
}

/// ∫₀ᵘ s, for u in [0, 1]; equals 1/2 at u = 1.
fn smoothstep_int(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    u.powi(5) * (7.0 + u * (-14.0 + u * (10.0 - 2.5 * u)))
}

/// One smooth step of height `delta` over `[t0, t0 + ramp]`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Step {
    t0_s: f64,
    ramp_s: f64,
    delta: f64,
}

/// A scalar command: `base + Σ steps`, with value, rate and time integral in closed form.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    base: f64,
    steps: Vec<Step>,
}

impl Profile {
    /// A constant profile.
    pub fn constant(base: f64) -> Self {
        Self {
            base,
            steps: Vec::new(),
        }
    }

    /// Adds a smooth step of height `delta` starting at `t0_s` and lasting `ramp_s`.
    pub fn add_step(&mut self, t0_s: f64, ramp_s: f64, delta: f64) {
        self.steps.push(Step {
            t0_s,
            ramp_s,
            delta,
        });
    }

    /// Adds a pulse: up by `delta` over `ramp_s` from `t0_s`, down again ending at `t0_s + dur_s`.
    pub fn add_pulse(&mut self, t0_s: f64, dur_s: f64, ramp_s: f64, delta: f64) {
        self.add_step(t0_s, ramp_s, delta);
        self.add_step(t0_s + dur_s - ramp_s, ramp_s, -delta);
    }

    /// Value at `t_s`.
    pub fn value(&self, t_s: f64) -> f64 {
        self.base
            + self
                .steps
                .iter()
                .map(|s| s.delta * smoothstep((t_s - s.t0_s) / s.ramp_s))
                .sum::<f64>()
    }

    /// Time derivative at `t_s`.
    pub fn rate(&self, t_s: f64) -> f64 {
        self.steps
            .iter()
            .map(|s| s.delta / s.ramp_s * smoothstep_d((t_s - s.t0_s) / s.ramp_s))
            .sum()
    }

    /// Second time derivative at `t_s`.
    pub fn rate_rate(&self, t_s: f64) -> f64 {
        self.steps
            .iter()
            .map(|s| s.delta / (s.ramp_s * s.ramp_s) * smoothstep_dd((t_s - s.t0_s) / s.ramp_s))
            .sum()
    }

    /// `∫₀^t value`, for `t_s ≥ 0` and steps starting at or after 0.
    pub fn integral(&self, t_s: f64) -> f64 {
        let steps: f64 = self
            .steps
            .iter()
            .map(|s| {
                let u = (t_s - s.t0_s) / s.ramp_s;
                if u <= 0.0 {
                    0.0
                } else if u <= 1.0 {
                    s.delta * s.ramp_s * smoothstep_int(u)
                } else {
                    s.delta * (0.5 * s.ramp_s + (t_s - s.t0_s - s.ramp_s))
                }
            })
            .sum();
        self.base * t_s + steps
    }
}

/// Kinematic state at one instant (all in the fixed local NED frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    /// Velocity, m/s.
    pub vel_ned_mps: Vector3<f64>,
    /// Acceleration dv/dt, m/s².
    pub acc_ned_mps2: Vector3<f64>,
    /// Attitude, body → NED.
    pub nav_from_body: UnitQuaternion<f64>,
    /// Angular rate of body w.r.t. the NED frame, body axes, rad/s.
    pub omega_nb_body_radps: Vector3<f64>,
    /// Roll, pitch, yaw (ZYX), rad.
    pub euler_rad: Vector3<f64>,
}

/// A fixed-wing trajectory built from a [`TrajectorySpec`].
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    speed_mps: Profile,
    yaw_rate_radps: Profile,
    flight_path_rad: Profile,
    heading0_rad: f64,
    alpha_rad: f64,
}

impl Trajectory {
    /// Builds the profiles. Speed changes are applied in start order, each from the speed
    /// reached by the previous one.
    pub fn new(spec: &TrajectorySpec) -> Self {
        let mut speed = Profile::constant(spec.speed_mps);
        let mut changes = spec.speed_changes.clone();
        changes.sort_by(|a, b| a.start_s.total_cmp(&b.start_s));
        let mut current = spec.speed_mps;
        for c in &changes {
            speed.add_step(c.start_s, c.ramp_s, c.to_mps - current);
            current = c.to_mps;
        }
        let mut yaw_rate = Profile::constant(0.0);
        for t in &spec.turns {
            yaw_rate.add_pulse(t.start_s, t.duration_s, t.ramp_s, t.rate_dps.to_radians());
        }
        let mut fpa = Profile::constant(spec.flight_path_deg.to_radians());
        for c in &spec.climbs {
            fpa.add_pulse(
                c.start_s,
                c.duration_s,
                c.ramp_s,
                c.flight_path_deg.to_radians(),
            );
        }
        Self {
            speed_mps: speed,
            yaw_rate_radps: yaw_rate,
            flight_path_rad: fpa,
            heading0_rad: spec.heading_deg.to_radians(),
            alpha_rad: spec.alpha_deg.to_radians(),
        }
    }

    /// Ground speed at `t_s`, m/s.
    pub fn speed_mps(&self, t_s: f64) -> f64 {
        self.speed_mps.value(t_s)
    }

    /// Velocity only (cheaper than [`Self::kinematics`]), m/s.
    pub fn velocity(&self, t_s: f64) -> Vector3<f64> {
        let v = self.speed_mps.value(t_s);
        let g = self.flight_path_rad.value(t_s);
        let psi = self.heading0_rad + self.yaw_rate_radps.integral(t_s);
        Vector3::new(
            v * g.cos() * psi.cos(),
            v * g.cos() * psi.sin(),
            -v * g.sin(),
        )
    }

    /// Full kinematic state at `t_s` (seconds after the start).
    pub fn kinematics(&self, t_s: f64) -> Kinematics {
        let v = self.speed_mps.value(t_s);
        let v_dot = self.speed_mps.rate(t_s);
        let gam = self.flight_path_rad.value(t_s);
        let gam_dot = self.flight_path_rad.rate(t_s);
        let psi = self.heading0_rad + self.yaw_rate_radps.integral(t_s);
        let psi_dot = self.yaw_rate_radps.value(t_s);
        let psi_ddot = self.yaw_rate_radps.rate(t_s);
        let (sg, cg) = gam.sin_cos();
        let (sp, cp) = psi.sin_cos();
        let u = Vector3::new(cg * cp, cg * sp, -sg);
        let du = Vector3::new(
            -sg * gam_dot * cp - cg * sp * psi_dot,
            -sg * gam_dot * sp + cg * cp * psi_dot,
            -cg * gam_dot,
        );
        // Coordinated-turn bank and its exact rate.
        let x = v * psi_dot / BANK_DESIGN_G_MPS2;
        let phi = x.atan();
        let x_dot = (v_dot * psi_dot + v * psi_ddot) / BANK_DESIGN_G_MPS2;
        let phi_dot = x_dot / (1.0 + x * x);
        let theta = gam + self.alpha_rad;
        let theta_dot = gam_dot;
        let (sf, cf) = phi.sin_cos();
        let (st, ct) = theta.sin_cos();
        // ZYX Euler rates → body rates.
        let omega = Vector3::new(
            phi_dot - psi_dot * st,
            theta_dot * cf + psi_dot * sf * ct,
            -theta_dot * sf + psi_dot * cf * ct,
        );
        Kinematics {
            vel_ned_mps: u * v,
            acc_ned_mps2: u * v_dot + du * v,
            nav_from_body: UnitQuaternion::from_euler_angles(phi, theta, psi),
            omega_nb_body_radps: omega,
            euler_rad: Vector3::new(phi, theta, psi),
        }
    }

    /// Positions at `times_s` (increasing, first = 0 at the origin), by 3-point Gauss–Legendre
    /// quadrature of the velocity on each interval (error ≪ 1 µm at IMU rates).
    pub fn positions(&self, times_s: &[f64]) -> Vec<Vector3<f64>> {
        let nodes = [
            (-(0.6f64).sqrt(), 5.0 / 9.0),
            (0.0, 8.0 / 9.0),
            ((0.6f64).sqrt(), 5.0 / 9.0),
        ];
        let mut out = Vec::with_capacity(times_s.len());
        let mut p = Vector3::zeros();
        let mut prev = times_s.first().copied().unwrap_or(0.0);
        for &t in times_s {
            let (mid, half) = (0.5 * (t + prev), 0.5 * (t - prev));
            for (x, w) in nodes {
                p += self.velocity(mid + half * x) * (w * half);
            }
            out.push(p);
            prev = t;
        }
        out
    }
}

/// The flight's kinematics, of the kind its scenario asks for.
#[derive(Debug, Clone, PartialEq)]
pub enum FlightPath {
    /// A fixed wing.
    FixedWing(Trajectory),
    /// A multirotor.
    Multirotor(crate::multirotor::MultirotorTrajectory),
}

impl FlightPath {
    /// The kinematics `spec.kind` names.
    pub fn new(spec: &TrajectorySpec) -> Self {
        match spec.kind {
            TrajectoryKind::FixedWing => FlightPath::FixedWing(Trajectory::new(spec)),
            TrajectoryKind::Multirotor => {
                FlightPath::Multirotor(crate::multirotor::MultirotorTrajectory::new(spec))
            }
        }
    }

    /// Full kinematic state at `t_s` (seconds after the start).
    pub fn kinematics(&self, t_s: f64) -> Kinematics {
        match self {
            FlightPath::FixedWing(t) => t.kinematics(t_s),
            FlightPath::Multirotor(m) => m.kinematics(t_s),
        }
    }

    /// Positions at `times_s` (increasing, first = 0 at the origin).
    pub fn positions(&self, times_s: &[f64]) -> Vec<Vector3<f64>> {
        match self {
            FlightPath::FixedWing(t) => t.positions(times_s),
            FlightPath::Multirotor(m) => m.positions(times_s),
        }
    }

    /// The attitude angle that limits the vehicle, rad: bank for a fixed wing, tilt from the
    /// vertical for a multirotor.
    pub fn limiting_angle_rad(&self, kin: &Kinematics) -> f64 {
        match self {
            FlightPath::FixedWing(_) => kin.euler_rad.x.abs(),
            FlightPath::Multirotor(_) => crate::multirotor::MultirotorTrajectory::tilt_rad(kin),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{ClimbSpec, SpeedChangeSpec, TurnSpec};

    fn spec() -> TrajectorySpec {
        TrajectorySpec {
            turns: vec![TurnSpec {
                start_s: 2.0,
                duration_s: 10.0,
                ramp_s: 3.0,
                rate_dps: 8.0,
            }],
            climbs: vec![ClimbSpec {
                start_s: 1.0,
                duration_s: 9.0,
                ramp_s: 4.0,
                flight_path_deg: 5.0,
            }],
            speed_changes: vec![SpeedChangeSpec {
                start_s: 3.0,
                ramp_s: 5.0,
                to_mps: 36.0,
            }],
            ..TrajectorySpec::default()
        }
    }

    #[test]
    fn profile_integral_matches_quadrature() {
        let mut p = Profile::constant(0.3);
        p.add_pulse(1.0, 6.0, 2.0, 1.5);
        let n = 20_000;
        let h = 10.0 / n as f64;
        let num: f64 = (0..n).map(|i| p.value((i as f64 + 0.5) * h) * h).sum();
        assert!(
            (num - p.integral(10.0)).abs() < 1e-6,
            "{num} vs {}",
            p.integral(10.0)
        );
        let d = (p.value(2.0 + 1e-6) - p.value(2.0 - 1e-6)) / 2e-6;
        assert!((d - p.rate(2.0)).abs() < 1e-6);
        let dd = (p.rate(2.3 + 1e-6) - p.rate(2.3 - 1e-6)) / 2e-6;
        assert!((dd - p.rate_rate(2.3)).abs() < 1e-6, "{dd}");
    }

    #[test]
    fn rates_match_finite_differences() {
        let tr = Trajectory::new(&spec());
        for &t in &[0.5, 2.7, 4.1, 6.3, 9.9, 11.0] {
            let k = tr.kinematics(t);
            let h = 1e-5;
            let (kp, km) = (tr.kinematics(t + h), tr.kinematics(t - h));
            let acc = (kp.vel_ned_mps - km.vel_ned_mps) / (2.0 * h);
            assert!((acc - k.acc_ned_mps2).norm() < 1e-6, "acc at {t}");
            // nav_from_body(t+h) = nav_from_body(t−h) · Exp(ω 2h) to first order.
            let dq = km.nav_from_body.inverse() * kp.nav_from_body;
            let omega = dq.scaled_axis() / (2.0 * h);
            assert!(
                (omega - k.omega_nb_body_radps).norm() < 1e-6,
                "omega at {t}"
            );
        }
    }

    #[test]
    fn turn_banks_coordinated() {
        let tr = Trajectory::new(&spec());
        let k = tr.kinematics(6.0);
        let v = tr.speed_mps(6.0);
        let expect = (v * 8f64.to_radians() / BANK_DESIGN_G_MPS2).atan();
        assert!((k.euler_rad.x - expect).abs() < 1e-12);
    }
}
