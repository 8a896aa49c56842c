//! Sensor models: the ideal IMU from the kinematics, IMU errors, the GNSS receiver, the
//! magnetometer and the barometer.

use nalgebra::{UnitQuaternion, Vector3};
use uavnav_core::geoid::egm96_undulation_m;
use uavnav_core::rng::Rng;
use uavnav_core::{BaroSample, FixType, GnssFix, ImuSample, LocalFrame, MagSample, TruthSample};

use crate::scenario::{BaroSpec, GnssSpec, ImuSpec, MagSpec};
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

/// The magnetometer at `indices` of the truth grid, from the `"mag"` random stream:
/// `m = R_bmᵀ (scale · C_nbᵀ B_ned + d_b) + b + n`, with `B_ned` the Earth field in the local frame,
/// `d_b` the disturbances in force, `b` the hard-iron residual drawn once (returned with the
/// samples) and `n` white. The noise is drawn at every sample, disturbed or not, so a disturbance
/// never shifts later noise.
pub fn simulate_mag(
    spec: &MagSpec,
    seed: u64,
    field_ned_t: &Vector3<f64>,
    t0_ns: i64,
    truth: &[TruthSample],
    indices: &[usize],
) -> (Vec<MagSample>, Vector3<f64>) {
    let mut rng = Rng::derive(seed, "mag");
    let bias = rng.gaussian3(spec.bias_sigma_t);
    let body_from_mag = body_from_mag(spec);
    let samples = indices
        .iter()
        .map(|&k| {
            let s = &truth[k];
            let noise = rng.gaussian3(spec.sigma_t);
            let t_s = (s.t_ns - t0_ns) as f64 * 1e-9;
            let disturbance: Vector3<f64> = spec
                .disturbances
                .iter()
                .filter(|d| d.window.contains(t_s))
                .map(|d| Vector3::from(d.field_body_t))
                .sum();
            let body =
                spec.scale * s.nav_from_body.inverse_transform_vector(field_ned_t) + disturbance;
            MagSample {
                t_ns: s.t_ns,
                field_t: body_from_mag.inverse_transform_vector(&body) + bias + noise,
            }
        })
        .collect();
    (samples, bias)
}

/// The magnetometer mount `body_from_mag` of a scenario (ZYX Euler angles, as the camera's).
pub fn body_from_mag(spec: &MagSpec) -> UnitQuaternion<f64> {
    let [r, p, y] = spec.body_from_mag_rpy_deg.map(f64::to_radians);
    UnitQuaternion::from_euler_angles(r, p, y)
}

/// ISA troposphere lapse coefficient, 1/m (`L / T₀`).
const ISA_K_PER_M: f64 = 2.255_77e-5;
/// ISA troposphere exponent (`g₀ M / (R L)`).
const ISA_EXPONENT: f64 = 5.255_88;

/// Static pressure of the ISA troposphere, Pa: `p = p_sl (1 − 2.255 77·10⁻⁵ h)^5.255 88`, with `h`
/// the geopotential height. Callers pass the height above mean sea level (EGM96 geoid) for it:
/// the two differ by `h²/R` (0.16 m at 1 km) and by the local gravity's departure from g₀ (a few
/// parts in a thousand of the height), far below the sensor's offset, which only a reference
/// removes anyway. A `p_sl` other than 101 325 Pa shifts the curve as an altimeter set to the day's
/// sea-level pressure does.
pub fn isa_pressure_pa(height_msl_m: f64, sea_level_pa: f64) -> f64 {
    sea_level_pa * (1.0 - ISA_K_PER_M * height_msl_m).powf(ISA_EXPONENT)
}

/// Height above mean sea level of an ISA static pressure, m (the inverse of [`isa_pressure_pa`]).
pub fn isa_height_m(pressure_pa: f64, sea_level_pa: f64) -> f64 {
    (1.0 - (pressure_pa / sea_level_pa).powf(1.0 / ISA_EXPONENT)) / ISA_K_PER_M
}

/// ISA troposphere temperature at a height above mean sea level, °C (15 °C − 6.5 K/km).
pub fn isa_temperature_degc(height_msl_m: f64) -> f64 {
    15.0 - 6.5e-3 * height_msl_m
}

/// The barometer at `indices` of the truth grid, from the `"baro"` random stream:
/// `p = isa_pressure_pa(h_msl, sea_level_pa) + drift·t + w(t) + n`, `h_msl` the true height above
/// the EGM96 geoid, `w` a random walk from 0 and `n` white. Returns the samples and the pressure
/// offset `drift·t + w(t)` in force at each (truth for tests and estimator checks). The temperature
/// reported is the ISA air temperature at the true height.
pub fn simulate_baro(
    spec: &BaroSpec,
    seed: u64,
    frame: &LocalFrame,
    t0_ns: i64,
    truth: &[TruthSample],
    indices: &[usize],
) -> (Vec<BaroSample>, Vec<f64>) {
    let mut rng = Rng::derive(seed, "baro");
    let mut walk = 0.0;
    let mut prev_t_ns: Option<i64> = None;
    let mut samples = Vec::with_capacity(indices.len());
    let mut offsets = Vec::with_capacity(indices.len());
    for &k in indices {
        let s = &truth[k];
        if let Some(p) = prev_t_ns {
            let dt_s = (s.t_ns - p) as f64 * 1e-9;
            walk += spec.random_walk_pa_per_sqrt_s * dt_s.sqrt() * rng.gaussian();
        }
        prev_t_ns = Some(s.t_ns);
        let noise = spec.sigma_pressure_pa * rng.gaussian();
        let lla = frame.ned_to_lla(&s.pos_ned_m);
        let h_msl = lla.alt_m - egm96_undulation_m(lla.lat_deg(), lla.lon_deg());
        let offset = spec.drift_pa_per_s * (s.t_ns - t0_ns) as f64 * 1e-9 + walk;
        samples.push(BaroSample {
            t_ns: s.t_ns,
            pressure_pa: isa_pressure_pa(h_msl, spec.sea_level_pa) + offset + noise,
            temperature_degc: Some(isa_temperature_degc(h_msl)),
        });
        offsets.push(offset);
    }
    (samples, offsets)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_snaps_and_stops() {
        assert_eq!(grid_indices(5.0, 200.0, 100), vec![0, 40, 80]);
        assert_eq!(grid_indices(3.0, 10.0, 8), vec![0, 3, 7]);
    }

    #[test]
    fn isa_pressure_round_trips_and_matches_the_table() {
        // ISA table: 1000 m → 89 876 Pa, 0 m → 101 325 Pa.
        assert!((isa_pressure_pa(0.0, 101_325.0) - 101_325.0).abs() < 1e-9);
        assert!((isa_pressure_pa(1000.0, 101_325.0) - 89_876.0).abs() < 2.0);
        for h in [-100.0, 0.0, 250.0, 3000.0] {
            let p = isa_pressure_pa(h, 100_900.0);
            assert!((isa_height_m(p, 100_900.0) - h).abs() < 1e-6, "{h}");
        }
        assert!((isa_temperature_degc(1000.0) - 8.5).abs() < 1e-12);
    }
}
