//! Sensor models: the ideal IMU from the kinematics, IMU errors, and the GNSS receiver.

use nalgebra::{UnitQuaternion, Vector3};
use uavnav_core::rng::Rng;
use uavnav_core::{FixType, GnssFix, ImuSample, LocalFrame, TruthSample};

use crate::scenario::{GnssSpec, ImuSpec};
use crate::trajectory::Kinematics;

/// The noise-free IMU at one instant (the crate doc's physics contract):
/// `ω_ib^b = ω_nb^b + C_n^b ω_ie^n`, `f^b = C_n^b (a^n − g^n(p) + 2 ω_ie^n × v^n)`.
pub fn ideal_imu(
    t_ns: i64,
    kin: &Kinematics,
    gravity_ned: &Vector3<f64>,
    omega_ie_ned: &Vector3<f64>,
) -> ImuSample {
    let q = &kin.nav_from_body;
    let gyro = kin.omega_nb_body_radps + q.inverse_transform_vector(omega_ie_ned);
    let f_ned = kin.acc_ned_mps2 - gravity_ned + 2.0 * omega_ie_ned.cross(&kin.vel_ned_mps);
    ImuSample {
        t_ns,
        gyro_radps: gyro,
        accel_mps2: q.inverse_transform_vector(&f_ned),
    }
}

/// IMU errors: turn-on bias + bias random walk + white noise, from the `"imu"` random stream.
#[derive(Debug, Clone)]
pub struct ImuErrors {
    rng: Rng,
    spec: ImuSpec,
    dt_s: f64,
    gyro_bias: Vector3<f64>,
    accel_bias: Vector3<f64>,
}

impl ImuErrors {
    /// Draws the turn-on biases.
    pub fn new(spec: &ImuSpec, seed: u64, dt_s: f64) -> Self {
        let mut rng = Rng::derive(seed, "imu");
        let gyro_bias = rng.gaussian3(spec.gyro_bias_sigma_radps);
        let accel_bias = rng.gaussian3(spec.accel_bias_sigma_mps2);
        Self {
            rng,
            spec: spec.clone(),
            dt_s,
            gyro_bias,
            accel_bias,
        }
    }

    /// Corrupts one ideal sample; returns it with the biases in force at that sample, then walks
    /// the biases to the next sample. White noise per sample has σ = density / √dt.
    pub fn apply(&mut self, ideal: &ImuSample) -> (ImuSample, Vector3<f64>, Vector3<f64>) {
        let sq = self.dt_s.sqrt();
        let gn = self.rng.gaussian3(self.spec.gyro_noise_density / sq);
        let an = self.rng.gaussian3(self.spec.accel_noise_density / sq);
        let out = ImuSample {
            t_ns: ideal.t_ns,
            gyro_radps: ideal.gyro_radps + self.gyro_bias + gn,
            accel_mps2: ideal.accel_mps2 + self.accel_bias + an,
        };
        let biases = (self.gyro_bias, self.accel_bias);
        self.gyro_bias += self.rng.gaussian3(self.spec.gyro_random_walk * sq);
        self.accel_bias += self.rng.gaussian3(self.spec.accel_random_walk * sq);
        (out, biases.0, biases.1)
    }
}

/// Antenna position and velocity in NED from the body state (paper eqs. 32–33 in the fixed frame):
/// `p_ant = p + C_b^n r^b`, `v_ant = v + C_b^n (ω_nb^b × r^b)`.
pub fn antenna_state(
    pos_ned_m: &Vector3<f64>,
    vel_ned_mps: &Vector3<f64>,
    nav_from_body: &UnitQuaternion<f64>,
    omega_nb_body_radps: &Vector3<f64>,
    lever_arm_body_m: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    (
        pos_ned_m + nav_from_body.transform_vector(lever_arm_body_m),
        vel_ned_mps + nav_from_body.transform_vector(&omega_nb_body_radps.cross(lever_arm_body_m)),
    )
}

/// Indices into a uniform sample grid (rate `grid_hz`) of the instants `j / rate_hz`, j = 0, 1, …
pub fn grid_indices(rate_hz: f64, grid_hz: f64, n_grid: usize) -> Vec<usize> {
    let mut out = Vec::new();
    for j in 0.. {
        let k = (j as f64 * grid_hz / rate_hz).round() as usize;
        if k >= n_grid {
            break;
        }
        if out.last() != Some(&k) {
            out.push(k);
        }
    }
    out
}

/// The GNSS receiver: fixes at `indices` of the truth grid, with white and first-order
/// Gauss–Markov position errors, white velocity noise, glitches and outages. Random numbers are
/// drawn at every epoch, outages included, so an outage never shifts the noise of later fixes.
pub fn simulate_gnss(
    spec: &GnssSpec,
    seed: u64,
    frame: &LocalFrame,
    t0_ns: i64,
    truth: &[TruthSample],
    omega_nb: &[Vector3<f64>],
    indices: &[usize],
) -> Vec<GnssFix> {
    let mut rng = Rng::derive(seed, "gnss");
    let lever = Vector3::from(spec.lever_arm_m);
    let gm_sigma = Vector3::new(spec.gm_sigma_h_m, spec.gm_sigma_h_m, spec.gm_sigma_v_m);
    let mut gm = gm_sigma.component_mul(&rng.gaussian3(1.0));
    let mut prev_t_ns: Option<i64> = None;
    let mut fixes = Vec::with_capacity(indices.len());
    for &k in indices {
        let s = &truth[k];
        if let Some(p) = prev_t_ns {
            let phi = (-((s.t_ns - p) as f64 * 1e-9) / spec.gm_tau_s).exp();
            let drive = gm_sigma * (1.0 - phi * phi).sqrt();
            gm = gm * phi + drive.component_mul(&rng.gaussian3(1.0));
        }
        prev_t_ns = Some(s.t_ns);
        let white = Vector3::new(
            spec.white_sigma_h_m,
            spec.white_sigma_h_m,
            spec.white_sigma_v_m,
        )
        .component_mul(&rng.gaussian3(1.0));
        let vel_noise = rng.gaussian3(spec.vel_sigma_mps);
        let t_s = (s.t_ns - t0_ns) as f64 * 1e-9;
        if spec.outages.iter().any(|w| w.contains(t_s)) {
            continue;
        }
        let glitch: Vector3<f64> = spec
            .glitches
            .iter()
            .filter(|g| t_s >= g.start_s && t_s < g.start_s + g.duration_s)
            .map(|g| Vector3::from(g.offset_ned_m))
            .sum();
        let (p_ant, v_ant) = antenna_state(
            &s.pos_ned_m,
            &s.vel_ned_mps,
            &s.nav_from_body,
            &omega_nb[k],
            &lever,
        );
        let lla = frame.ned_to_lla(&(p_ant + gm + white + glitch));
        fixes.push(GnssFix {
            t_ns: s.t_ns,
            lat_deg: lla.lat_deg(),
            lon_deg: lla.lon_deg(),
            alt_m: lla.alt_m,
            velocity: Some(uavnav_core::GnssVelocity::ned(
                v_ant + vel_noise,
                spec.vel_sigma_mps,
            )),
            sigma_h_m: spec.white_sigma_h_m.hypot(spec.gm_sigma_h_m),
            sigma_v_m: spec.white_sigma_v_m.hypot(spec.gm_sigma_v_m),
            fix_type: FixType::Fix3d,
            num_sats: spec.num_sats,
        });
    }
    fixes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_snaps_and_stops() {
        assert_eq!(grid_indices(5.0, 200.0, 100), vec![0, 40, 80]);
        assert_eq!(grid_indices(3.0, 10.0, 8), vec![0, 3, 7]);
    }
}
