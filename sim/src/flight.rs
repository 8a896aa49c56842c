//! A whole simulated flight: truth, IMU, GNSS, magnetometer, barometer and camera times
//! precomputed from a [`Scenario`].

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use uavnav_core::magnetic::MagneticModel;
use uavnav_core::{
    BaroConfig, BaroSample, CameraConfig, CameraModel, Distortion, GnssConfig, GnssFix, ImuConfig,
    ImuSample, Lla, LocalFrame, MagConfig, MagSample, TruthSample, VehicleConfig,
};

use std::sync::{Arc, OnceLock};

use uavnav_core::rng::Rng;

use crate::render::RayTable;
use crate::scenario::Scenario;
use crate::scenario::TrajectoryKind;
use crate::sensors::{
    ImuErrors, body_from_mag, grid_indices, ideal_imu, simulate_baro, simulate_gnss, simulate_mag,
};
use crate::strapdown::earth_rate_ned;
use crate::terrain::Terrain;
use crate::trajectory::FlightPath;

/// Lowest height above the terrain a scenario may fly, m.
pub const MIN_HEIGHT_AGL_M: f64 = 10.0;
/// Steepest bank (fixed wing) or tilt (multirotor) a scenario may command, rad (60°).
pub const MAX_BANK_RAD: f64 = std::f64::consts::FRAC_PI_3;

/// Why a flight cannot be simulated or a frame not produced.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// The scenario parses but describes an impossible flight.
    #[error("invalid scenario: {0}")]
    Invalid(String),
    /// A camera frame index past the end.
    #[error("camera frame {index} out of range (flight has {len} frames)")]
    FrameIndex {
        /// Requested index.
        index: usize,
        /// Number of frames.
        len: usize,
    },
    /// The image encoder failed.
    #[error("JPEG encoding failed: {0}")]
    Encode(String),
}

/// A precomputed flight. Frames are rendered on demand.
#[derive(Debug, Clone)]
pub struct Flight {
    pub(crate) scenario: Scenario,
    pub(crate) frame: LocalFrame,
    truth: Vec<TruthSample>,
    ideal: Vec<ImuSample>,
    imu: Vec<ImuSample>,
    gnss: Vec<GnssFix>,
    mag: Vec<MagSample>,
    /// The magnetometer's hard-iron residual (zero without a magnetometer), T.
    mag_bias_t: Vector3<f64>,
    baro: Vec<BaroSample>,
    /// The barometer's pressure offset (drift + random walk) at each sample, Pa.
    baro_offsets_pa: Vec<f64>,
    pub(crate) camera_times_ns: Vec<i64>,
    /// Truth index of each camera frame.
    pub(crate) camera_truth_index: Vec<usize>,
    /// The ground.
    pub(crate) terrain: Terrain,
    /// The camera's undistorted rays, built on the first render.
    pub(crate) rays: OnceLock<Arc<RayTable>>,
    /// Seed of the image-noise streams.
    pub(crate) image_seed: u64,
}

impl Flight {
    /// Simulates everything but the images.
    pub fn new(scenario: &Scenario) -> Result<Flight, SimError> {
        let s = scenario;
        let dt_ns = (1e9 / s.imu.rate_hz).round() as i64;
        if dt_ns <= 0 {
            return Err(SimError::Invalid(format!(
                "imu.rate_hz {} is too high",
                s.imu.rate_hz
            )));
        }
        let n = (s.duration_s * 1e9 / dt_ns as f64 + 1e-6).floor() as usize + 1;
        if n < 2 {
            return Err(SimError::Invalid(
                "duration_s is shorter than one IMU period".into(),
            ));
        }
        check_camera(s)?;
        let origin = Lla::from_deg(s.origin.lat_deg, s.origin.lon_deg, s.origin.alt_m);
        let frame = LocalFrame::new(origin);
        let omega_ie = earth_rate_ned(origin.lat_rad);
        let traj = FlightPath::new(&s.trajectory);
        let times_s: Vec<f64> = (0..n).map(|k| (k as i64 * dt_ns) as f64 * 1e-9).collect();
        let positions = traj.positions(&times_s);
        let mut errors = ImuErrors::new(&s.imu, s.seed, dt_ns as f64 * 1e-9);
        let (mut truth, mut ideal, mut imu, mut omega_nb) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for (k, (t_s, p)) in times_s.iter().zip(&positions).enumerate() {
            let t_ns = s.t0_ns + k as i64 * dt_ns;
            let kin = traj.kinematics(*t_s);
            check_state(&frame, s, *t_s, p, traj.limiting_angle_rad(&kin))?;
            let clean = ideal_imu(t_ns, &kin, &frame.gravity_ned(p), &omega_ie);
            let (noisy, bg, ba) = errors.apply(&clean);
            truth.push(TruthSample {
                t_ns,
                pos_ned_m: *p,
                nav_from_body: kin.nav_from_body,
                vel_ned_mps: kin.vel_ned_mps,
                gyro_bias_radps: bg,
                accel_bias_mps2: ba,
            });
            ideal.push(clean);
            imu.push(noisy);
            omega_nb.push(kin.omega_nb_body_radps);
        }
        let gnss = if s.gnss.enabled {
            let idx = grid_indices(s.gnss.rate_hz, s.imu.rate_hz, n);
            simulate_gnss(&s.gnss, s.seed, &frame, s.t0_ns, &truth, &omega_nb, &idx)
        } else {
            Vec::new()
        };
        let (mag, mag_bias_t) = match &s.mag {
            Some(m) => {
                let idx = grid_indices(m.rate_hz, s.imu.rate_hz, n);
                let field = MagneticModel::field(&origin, s.date_year).ned_t;
                simulate_mag(m, s.seed, &field, s.t0_ns, &truth, &idx)
            }
            None => (Vec::new(), Vector3::zeros()),
        };
        let (baro, baro_offsets_pa) = match &s.baro {
            Some(b) => {
                let idx = grid_indices(b.rate_hz, s.imu.rate_hz, n);
                simulate_baro(b, s.seed, &frame, s.t0_ns, &truth, &idx)
            }
            None => (Vec::new(), Vec::new()),
        };
        let camera_truth_index = if s.camera.enabled {
            grid_indices(s.camera.rate_hz, s.imu.rate_hz, n)
        } else {
            Vec::new()
        };
        let camera_times_ns = camera_truth_index.iter().map(|&k| truth[k].t_ns).collect();
        Ok(Flight {
            scenario: s.clone(),
            frame,
            truth,
            ideal,
            imu,
            gnss,
            mag,
            mag_bias_t,
            baro,
            baro_offsets_pa,
            camera_times_ns,
            camera_truth_index,
            terrain: Terrain::new(origin, s.terrain.elevation_m, s.seed),
            rays: OnceLock::new(),
            image_seed: Rng::derive(s.seed, "image").next_u64(),
        })
    }

    /// The scenario this flight was made from.
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// The truth origin (the local NED frame's origin, the EuRoC `R` frame).
    pub fn origin(&self) -> Lla {
        self.frame.origin()
    }

    /// The local NED frame at the origin.
    pub fn local_frame(&self) -> &LocalFrame {
        &self.frame
    }

    /// What the estimator is told about the vehicle.
    pub fn vehicle_config(&self) -> VehicleConfig {
        let s = &self.scenario;
        VehicleConfig {
            imu: ImuConfig {
                rate_hz: s.imu.rate_hz,
                gyro_noise_density: s.imu.gyro_noise_density,
                gyro_random_walk: s.imu.gyro_random_walk,
                accel_noise_density: s.imu.accel_noise_density,
                accel_random_walk: s.imu.accel_random_walk,
                gyro_bias_sigma_radps: s.imu.gyro_bias_sigma_radps,
                accel_bias_sigma_mps2: s.imu.accel_bias_sigma_mps2,
            },
            gnss: s.gnss.enabled.then(|| GnssConfig {
                rate_hz: s.gnss.rate_hz,
                lever_arm_body_m: Vector3::from(s.gnss.lever_arm_m),
                delay_ns: 0,
                ..GnssConfig::default()
            }),
            mag: s.mag.as_ref().map(|m| MagConfig {
                rate_hz: m.rate_hz,
                body_from_mag: body_from_mag(m),
                sigma_t: m.sigma_t,
            }),
            baro: s.baro.as_ref().map(|b| BaroConfig {
                rate_hz: b.rate_hz,
                sigma_pressure_pa: b.sigma_pressure_pa,
            }),
            camera: s.camera.enabled.then(|| CameraConfig {
                rate_hz: s.camera.rate_hz,
                model: self.camera_model(),
                body_from_cam: self.body_from_cam(),
            }),
            terrain_elevation_m: s.terrain.elevation_m,
            profile: Default::default(),
            // which kinematics flew it: the estimator may take a fixed wing's heading from its course
            airframe: match s.trajectory.kind {
                TrajectoryKind::FixedWing => uavnav_core::Airframe::FixedWing,
                TrajectoryKind::Multirotor => uavnav_core::Airframe::Multirotor,
            },
        }
    }

    /// The camera intrinsics.
    pub fn camera_model(&self) -> CameraModel {
        camera_model(&self.scenario)
    }

    /// The camera mount: `p_body = body_from_cam · p_cam`.
    pub fn body_from_cam(&self) -> Isometry3<f64> {
        let c = &self.scenario.camera;
        let [r, p, y] = c.body_from_cam_rpy_deg.map(f64::to_radians);
        Isometry3::from_parts(
            Translation3::from(Vector3::from(c.body_from_cam_xyz_m)),
            UnitQuaternion::from_euler_angles(r, p, y),
        )
    }

    /// Truth at every IMU sample time.
    pub fn truth(&self) -> &[TruthSample] {
        &self.truth
    }

    /// The IMU as measured (noise and biases included).
    pub fn imu(&self) -> &[ImuSample] {
        &self.imu
    }

    /// The noise-free, bias-free IMU at the same times.
    pub fn ideal_imu(&self) -> Vec<ImuSample> {
        self.ideal.clone()
    }

    /// The GNSS fixes (none inside outages).
    pub fn gnss(&self) -> &[GnssFix] {
        &self.gnss
    }

    /// The magnetometer samples (empty without a `[mag]` table).
    pub fn mag(&self) -> &[MagSample] {
        &self.mag
    }

    /// The Earth field the magnetometer sees: WMM2025 at the origin on `date_year`, local NED, T.
    /// The flight's few kilometres change it by a few nT, below the sensor noise, so it is one
    /// vector for the whole flight.
    pub fn mag_field_ned_t(&self) -> Vector3<f64> {
        MagneticModel::field(&self.origin(), self.scenario.date_year).ned_t
    }

    /// The magnetometer's constant hard-iron residual in its own axes (zero without one), T.
    pub fn mag_bias_t(&self) -> Vector3<f64> {
        self.mag_bias_t
    }

    /// The barometer samples (empty without a `[baro]` table).
    pub fn baro(&self) -> &[BaroSample] {
        &self.baro
    }

    /// The barometer's pressure offset (weather drift + random walk) at each of its samples, Pa.
    pub fn baro_offsets_pa(&self) -> &[f64] {
        &self.baro_offsets_pa
    }

    /// Camera frame times (on the IMU grid), ns.
    pub fn camera_times_ns(&self) -> &[i64] {
        &self.camera_times_ns
    }

    /// The ground.
    pub fn terrain(&self) -> &Terrain {
        &self.terrain
    }

    /// Truth at camera frame `index`, if it exists.
    pub fn camera_truth(&self, index: usize) -> Option<&TruthSample> {
        self.camera_truth_index.get(index).map(|&k| &self.truth[k])
    }
}

/// The camera intrinsics of a scenario.
pub(crate) fn camera_model(s: &Scenario) -> CameraModel {
    let c = &s.camera;
    let [k1, k2, p1, p2] = c.distortion;
    let distortion = if c.distortion == [0.0; 4] {
        Distortion::None
    } else {
        Distortion::RadTan { k1, k2, p1, p2 }
    };
    CameraModel {
        width: c.width,
        height: c.height,
        fx: c.fx,
        fy: c.fy,
        cx: c.cx,
        cy: c.cy,
        distortion,
    }
}

fn check_camera(s: &Scenario) -> Result<(), SimError> {
    let c = &s.camera;
    if !c.enabled {
        return Ok(());
    }
    if c.width == 0 || c.height == 0 || c.width > 8192 || c.height > 8192 {
        return Err(SimError::Invalid(format!(
            "camera size {}×{} must be 1..=8192 px",
            c.width, c.height
        )));
    }
    if !(1..=100).contains(&c.jpeg_quality) {
        return Err(SimError::Invalid(format!(
            "camera.jpeg_quality {} must be 1..=100",
            c.jpeg_quality
        )));
    }
    if ![c.cx, c.cy]
        .iter()
        .chain(&c.distortion)
        .chain(&c.body_from_cam_rpy_deg)
        .all(|x| x.is_finite())
    {
        return Err(SimError::Invalid("camera parameters must be finite".into()));
    }
    Ok(())
}

fn check_state(
    frame: &LocalFrame,
    s: &Scenario,
    t_s: f64,
    p: &Vector3<f64>,
    limiting_angle_rad: f64,
) -> Result<(), SimError> {
    if limiting_angle_rad > MAX_BANK_RAD {
        let what = match s.trajectory.kind {
            TrajectoryKind::FixedWing => "bank",
            TrajectoryKind::Multirotor => "tilt",
        };
        let fix = match s.trajectory.kind {
            TrajectoryKind::FixedWing => "reduce the turn rate or speed",
            TrajectoryKind::Multirotor => "lengthen the velocity change's ramp_s",
        };
        return Err(SimError::Invalid(format!(
            "{what} {:.1}° at t = {t_s:.2} s exceeds {:.0}°: {fix}",
            limiting_angle_rad.to_degrees(),
            MAX_BANK_RAD.to_degrees()
        )));
    }
    let agl = frame.ned_to_lla(p).alt_m - s.terrain.elevation_m;
    if agl < MIN_HEIGHT_AGL_M {
        return Err(SimError::Invalid(format!(
            "the vehicle is {agl:.1} m above the terrain at t = {t_s:.2} s (minimum {MIN_HEIGHT_AGL_M} m)"
        )));
    }
    Ok(())
}
