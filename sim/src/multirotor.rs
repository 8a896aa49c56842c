//! Multirotor kinematics from smooth commanded profiles, in closed form.
//!
//! The NED velocity `v(t)` (each axis a constant plus septic smooth steps, from hover) and the yaw
//! command `ψ(t)` (the integral of yaw-rate pulses) are commanded apart, so the vehicle hovers,
//! flies sideways or backwards and yaws in place. The attitude follows from the thrust: a rotor
//! disc pushes along body −z, so body z points along `−f/|f|` with `f = a − g0·e_down` the design
//! specific force (g0 = standard gravity, a design constant as for the fixed wing's bank), and
//! body x is the unit vector closest to `(cos ψ, sin ψ, 0)` that is perpendicular to body z
//! (body y = z × x_c normalised, x = y × z). The body rate comes from the exact derivatives of
//! those axes (they need the jerk, the velocity's second derivative, which the C³ steps provide),
//! `ω = (z·ẏ, x·ż, y·ẋ)`, and position is the velocity's exact integral. Everything the IMU sees
//! is analytic, so a careful strapdown integrator reproduces the truth.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

use crate::scenario::TrajectorySpec;
use crate::trajectory::{BANK_DESIGN_G_MPS2, Kinematics, Profile};

/// A multirotor trajectory built from a [`TrajectorySpec`] of kind multirotor.
#[derive(Debug, Clone, PartialEq)]
pub struct MultirotorTrajectory {
    /// North, east, down velocity, m/s.
    vel: [Profile; 3],
    yaw_rate_radps: Profile,
    yaw0_rad: f64,
}

impl MultirotorTrajectory {
    /// Builds the profiles. Velocity changes are applied in start order, each from the velocity
    /// the previous one commanded; the flight starts hovering.
    pub fn new(spec: &TrajectorySpec) -> Self {
        let mut vel = [
            Profile::constant(0.0),
            Profile::constant(0.0),
            Profile::constant(0.0),
        ];
        let mut changes = spec.velocity_changes.clone();
        changes.sort_by(|a, b| a.start_s.total_cmp(&b.start_s));
        let mut current = [0.0; 3];
        for c in &changes {
            for (axis, profile) in vel.iter_mut().enumerate() {
                let delta = c.to_ned_mps[axis] - current[axis];
                if delta != 0.0 {
                    profile.add_step(c.start_s, c.ramp_s, delta);
                }
            }
            current = c.to_ned_mps;
        }
        let mut yaw_rate = Profile::constant(0.0);
        for t in &spec.turns {
            yaw_rate.add_pulse(t.start_s, t.duration_s, t.ramp_s, t.rate_dps.to_radians());
        }
        Self {
            vel,
            yaw_rate_radps: yaw_rate,
            yaw0_rad: spec.heading_deg.to_radians(),
        }
    }

    /// Velocity, m/s.
    pub fn velocity(&self, t_s: f64) -> Vector3<f64> {
        Vector3::from_fn(|i, _| self.vel[i].value(t_s))
    }

    /// Full kinematic state at `t_s` (seconds after the start).
    pub fn kinematics(&self, t_s: f64) -> Kinematics {
        let v = self.velocity(t_s);
        let a = Vector3::from_fn(|i, _| self.vel[i].rate(t_s));
        let jerk = Vector3::from_fn(|i, _| self.vel[i].rate_rate(t_s));
        let psi = self.yaw0_rad + self.yaw_rate_radps.integral(t_s);
        let psi_dot = self.yaw_rate_radps.value(t_s);
        // Body z against the design specific force, and its rate: d(f/|f|) = (ḟ − n (n·ḟ)) / |f|.
        let f = a - Vector3::new(0.0, 0.0, BANK_DESIGN_G_MPS2);
        let f_norm = f.norm();
        let n = f / f_norm;
        let z = -n;
        let z_dot = -(jerk - n * n.dot(&jerk)) / f_norm;
        // Body y perpendicular to z and to the yaw direction, then x completes the triad.
        let (sp, cp) = psi.sin_cos();
        let xc = Vector3::new(cp, sp, 0.0);
        let xc_dot = Vector3::new(-sp, cp, 0.0) * psi_dot;
        let w = z.cross(&xc);
        let w_norm = w.norm();
        let y = w / w_norm;
        let w_dot = z_dot.cross(&xc) + z.cross(&xc_dot);
        let y_dot = (w_dot - y * y.dot(&w_dot)) / w_norm;
        let x = y.cross(&z);
        let x_dot = y_dot.cross(&z) + y.cross(&z_dot);
        // Ṙ = R [ω]×, so [ω]× = Rᵀ Ṙ: ω = (z·ẏ, x·ż, y·ẋ) with R's columns x, y, z.
        let omega = Vector3::new(z.dot(&y_dot), x.dot(&z_dot), y.dot(&x_dot));
        let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
        let q = UnitQuaternion::from_rotation_matrix(&rot);
        let (roll, pitch, yaw) = q.euler_angles();
        Kinematics {
            vel_ned_mps: v,
            acc_ned_mps2: a,
            nav_from_body: q,
            omega_nb_body_radps: omega,
            euler_rad: Vector3::new(roll, pitch, yaw),
        }
    }

    /// Positions at `times_s` (increasing, first = 0 at the origin): the exact integral of the
    /// velocity profiles.
    pub fn positions(&self, times_s: &[f64]) -> Vec<Vector3<f64>> {
        let t0 = times_s.first().copied().unwrap_or(0.0);
        let p0 = Vector3::from_fn(|i, _| self.vel[i].integral(t0));
        times_s
            .iter()
            .map(|&t| Vector3::from_fn(|i, _| self.vel[i].integral(t)) - p0)
            .collect()
    }

    /// Tilt of body z from the local vertical, rad (what limits a multirotor, as bank does a
    /// fixed wing).
    pub fn tilt_rad(kin: &Kinematics) -> f64 {
        let z = kin.nav_from_body.transform_vector(&Vector3::z());
        z.z.clamp(-1.0, 1.0).acos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{TrajectoryKind, TurnSpec, VelocityChangeSpec};

    fn spec() -> TrajectorySpec {
        TrajectorySpec {
            kind: TrajectoryKind::Multirotor,
            heading_deg: 20.0,
            turns: vec![TurnSpec {
                start_s: 1.0,
                duration_s: 6.0,
                ramp_s: 2.0,
                rate_dps: 40.0,
            }],
            velocity_changes: vec![
                VelocityChangeSpec {
                    start_s: 0.5,
                    ramp_s: 2.0,
                    to_ned_mps: [3.0, -4.0, -1.0],
                },
                VelocityChangeSpec {
                    start_s: 3.0,
                    ramp_s: 1.5,
                    to_ned_mps: [-5.0, 2.0, 0.5],
                },
            ],
            ..TrajectorySpec::default()
        }
    }

    #[test]
    fn rates_match_finite_differences() {
        let tr = MultirotorTrajectory::new(&spec());
        for &t in &[0.0, 0.9, 1.7, 2.2, 3.4, 4.1, 5.5, 8.0] {
            let k = tr.kinematics(t);
            let h = 1e-5;
            let (kp, km) = (tr.kinematics(t + h), tr.kinematics(t - h));
            let acc = (kp.vel_ned_mps - km.vel_ned_mps) / (2.0 * h);
            assert!((acc - k.acc_ned_mps2).norm() < 1e-6, "acc at {t}");
            let dq = km.nav_from_body.inverse() * kp.nav_from_body;
            let omega = dq.scaled_axis() / (2.0 * h);
            assert!(
                (omega - k.omega_nb_body_radps).norm() < 1e-6,
                "omega at {t}: {omega:?} vs {:?}",
                k.omega_nb_body_radps
            );
        }
    }

    #[test]
    fn hover_is_level_and_thrust_tilts_into_the_acceleration() {
        let tr = MultirotorTrajectory::new(&spec());
        let k = tr.kinematics(0.0);
        assert!(k.euler_rad.x.abs() < 1e-12 && k.euler_rad.y.abs() < 1e-12);
        assert!((k.euler_rad.z - 20f64.to_radians()).abs() < 1e-12);
        // Specific force along body −z at every instant.
        for t in [1.5, 3.7] {
            let k = tr.kinematics(t);
            let f = k.acc_ned_mps2 - Vector3::new(0.0, 0.0, BANK_DESIGN_G_MPS2);
            let fb = k.nav_from_body.inverse_transform_vector(&f);
            assert!(
                fb.x.abs() < 1e-9 && fb.y.abs() < 1e-9 && fb.z < 0.0,
                "{fb:?}"
            );
        }
    }

    #[test]
    fn positions_integrate_the_velocity() {
        let tr = MultirotorTrajectory::new(&spec());
        let times: Vec<f64> = (0..=800).map(|i| i as f64 * 0.01).collect();
        let p = tr.positions(&times);
        let mut num = Vector3::zeros();
        for w in times.windows(2) {
            let m = 0.5 * (w[0] + w[1]);
            num += tr.velocity(m) * (w[1] - w[0]);
        }
        assert!((num - p[800]).norm() < 1e-4, "{num:?} vs {:?}", p[800]);
    }
}
