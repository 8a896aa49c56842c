//! The scenario file: a TOML document that fixes a whole simulated flight, seed included.
//!
//! Angles are in degrees in the file (it is an edge, written by people; every such key ends in
//! `_deg` or `_dps`); everything else is SI. Every table and key except `seed` and `duration_s`
//! has a named default; the optional sensors (`[mag]`, `[baro]`) are fitted only when their table
//! is present, and then every key in it has a default. Unknown keys are rejected; a bad value is
//! reported with its line and column.

use serde::de::Error as _;
use serde::{Deserialize, Deserializer};

mod mag_baro;

pub use mag_baro::{
    BaroSpec, DEFAULT_BARO_SIGMA_PA, DEFAULT_MAG_BARO_RATE_HZ, DEFAULT_MAG_BIAS_SIGMA_T,
    DEFAULT_MAG_SIGMA_T, ISA_SEA_LEVEL_PA, MagDisturbanceSpec, MagSpec,
};

/// Default start time of a flight, ns (1000 s: clear of zero so that time arithmetic bugs show).
pub const DEFAULT_T0_NS: i64 = 1_000_000_000_000;
/// Default origin latitude, degrees (near Capua, Italy, where the paper's authors fly).
pub const DEFAULT_ORIGIN_LAT_DEG: f64 = 41.1;
/// Default origin longitude, degrees.
pub const DEFAULT_ORIGIN_LON_DEG: f64 = 14.2;
/// Default origin height above the WGS84 ellipsoid, m.
pub const DEFAULT_ORIGIN_ALT_M: f64 = 250.0;
/// Default initial ground speed, m/s.
pub const DEFAULT_SPEED_MPS: f64 = 30.0;
/// Default angle of attack (pitch minus flight-path angle), degrees.
pub const DEFAULT_ALPHA_DEG: f64 = 2.0;
/// Default IMU rate, Hz.
pub const DEFAULT_IMU_RATE_HZ: f64 = 200.0;
/// Default 1-σ gyro turn-on bias per axis, rad/s (≈ 10 °/h, tactical MEMS).
pub const DEFAULT_GYRO_BIAS_SIGMA_RADPS: f64 = 5.0e-5;
/// Default 1-σ accelerometer turn-on bias per axis, m/s² (≈ 1 mg).
pub const DEFAULT_ACCEL_BIAS_SIGMA_MPS2: f64 = 0.01;
/// Default GNSS rate, Hz.
pub const DEFAULT_GNSS_RATE_HZ: f64 = 5.0;
/// Default camera rate, Hz.
pub const DEFAULT_CAMERA_RATE_HZ: f64 = 10.0;
/// Default terrain elevation above the ellipsoid, m.
pub const DEFAULT_TERRAIN_ELEVATION_M: f64 = 50.0;
/// Default date of the flight, decimal year (inside WMM2025's validity, 2025–2030). Sample stamps
/// start at `t0_ns`, which is not UNIX time, so the date the magnetic field is evaluated at is
/// given on its own.
pub const DEFAULT_DATE_YEAR: f64 = 2026.5;
/// A scenario file could not be read: what is wrong and where.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}, column {column}: {message}")]
pub struct ScenarioError {
    /// 1-based line of the offending text (0 when unknown).
    pub line: usize,
    /// 1-based column of the offending text (0 when unknown).
    pub column: usize,
    /// What is wrong.
    pub message: String,
}

/// A whole simulated flight.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Free-text name.
    #[serde(default)]
    pub name: String,
    /// Seed of every random stream (IMU, GNSS, terrain texture, image noise).
    pub seed: u64,
    /// Flight duration, s.
    #[serde(deserialize_with = "positive")]
    pub duration_s: f64,
    /// Time of the first sample, ns.
    #[serde(default = "default_t0_ns")]
    pub t0_ns: i64,
    /// The truth origin: the local NED frame's origin and the vehicle's position at `t0_ns`.
    #[serde(default)]
    pub origin: OriginSpec,
    /// The commanded flight.
    #[serde(default)]
    pub trajectory: TrajectorySpec,
    /// The IMU.
    #[serde(default)]
    pub imu: ImuSpec,
    /// The GNSS receiver.
    #[serde(default)]
    pub gnss: GnssSpec,
    /// The camera.
    #[serde(default)]
    pub camera: CameraSpec,
    /// The ground.
    #[serde(default)]
    pub terrain: TerrainSpec,
    /// Date of the flight, decimal year (e.g. 2026.5 = early July 2026): the magnetic field is
    /// the WMM2025 field at the origin on this date.
    #[serde(default = "default_date_year", deserialize_with = "date_year")]
    pub date_year: f64,
    /// The magnetometer; absent = none fitted.
    #[serde(default)]
    pub mag: Option<MagSpec>,
    /// The barometer; absent = none fitted.
    #[serde(default)]
    pub baro: Option<BaroSpec>,
}

fn default_t0_ns() -> i64 {
    DEFAULT_T0_NS
}

fn default_date_year() -> f64 {
    DEFAULT_DATE_YEAR
}

impl Scenario {
    /// Parses a scenario from TOML text; the error carries line and column.
    pub fn from_toml_str(text: &str) -> Result<Scenario, ScenarioError> {
        toml::from_str(text).map_err(|e| {
            let (line, column) = e.span().map(|s| line_col(text, s.start)).unwrap_or((0, 0));
            ScenarioError {
                line,
                column,
                message: e.message().trim().to_string(),
            }
        })
    }
}

/// 1-based line and column of a byte offset.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

/// Where the flight starts.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OriginSpec {
    /// Latitude, degrees.
    pub lat_deg: f64,
    /// Longitude, degrees.
    pub lon_deg: f64,
    /// Height above the WGS84 ellipsoid, m.
    pub alt_m: f64,
}

impl Default for OriginSpec {
    fn default() -> Self {
        Self {
            lat_deg: DEFAULT_ORIGIN_LAT_DEG,
            lon_deg: DEFAULT_ORIGIN_LON_DEG,
            alt_m: DEFAULT_ORIGIN_ALT_M,
        }
    }
}

/// Which kinematics fly the trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TrajectoryKind {
    /// A fixed wing: nose first, coordinated turns ([`crate::trajectory`]).
    #[default]
    FixedWing,
    /// A multirotor: NED velocity and yaw commanded apart, tilt from the acceleration
    /// ([`crate::multirotor`]). It starts hovering.
    Multirotor,
}

/// The commanded flight: initial state plus turns, climbs and speed changes (fixed wing) or
/// velocity changes and yaw turns (multirotor), each smoothly ramped. Keys of the other kind are
/// refused, so a file never holds a command that is silently ignored.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(try_from = "TrajectoryRaw")]
pub struct TrajectorySpec {
    /// The kinematics (`kind = "fixed-wing"`, the default, or `"multirotor"`).
    pub kind: TrajectoryKind,
    /// Initial ground speed, m/s (fixed wing).
    pub speed_mps: f64,
    /// Initial heading (course over ground for a fixed wing, yaw for a multirotor, clockwise from
    /// north), degrees.
    pub heading_deg: f64,
    /// Initial flight-path angle (positive climbing), degrees (fixed wing).
    pub flight_path_deg: f64,
    /// Angle of attack: pitch = flight-path angle + this, degrees (fixed wing).
    pub alpha_deg: f64,
    /// Yaw-rate pulses: coordinated turns for a fixed wing, yaw without bank for a multirotor.
    pub turns: Vec<TurnSpec>,
    /// Climbs and descents (flight-path-angle pulses; fixed wing).
    pub climbs: Vec<ClimbSpec>,
    /// Speed changes (steps; fixed wing).
    pub speed_changes: Vec<SpeedChangeSpec>,
    /// Velocity changes (steps of the NED velocity; multirotor).
    pub velocity_changes: Vec<VelocityChangeSpec>,
}

impl Default for TrajectorySpec {
    fn default() -> Self {
        Self {
            kind: TrajectoryKind::FixedWing,
            speed_mps: DEFAULT_SPEED_MPS,
            heading_deg: 0.0,
            flight_path_deg: 0.0,
            alpha_deg: DEFAULT_ALPHA_DEG,
            turns: Vec::new(),
            climbs: Vec::new(),
            speed_changes: Vec::new(),
            velocity_changes: Vec::new(),
        }
    }
}

/// A number > 0 that keeps its own line in errors inside an optional key.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(transparent)]
struct Positive(#[serde(deserialize_with = "positive")] f64);

/// The trajectory table as written: which keys are present matters (see [`TrajectorySpec`]).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct TrajectoryRaw {
    #[serde(default)]
    kind: TrajectoryKind,
    speed_mps: Option<Positive>,
    heading_deg: Option<f64>,
    flight_path_deg: Option<f64>,
    alpha_deg: Option<f64>,
    #[serde(default)]
    turns: Vec<TurnSpec>,
    climbs: Option<Vec<ClimbSpec>>,
    speed_changes: Option<Vec<SpeedChangeSpec>>,
    velocity_changes: Option<Vec<VelocityChangeSpec>>,
}

impl TryFrom<TrajectoryRaw> for TrajectorySpec {
    type Error = String;
    fn try_from(r: TrajectoryRaw) -> Result<Self, String> {
        let fixed_wing_keys = [
            ("speed_mps", r.speed_mps.is_some()),
            ("flight_path_deg", r.flight_path_deg.is_some()),
            ("alpha_deg", r.alpha_deg.is_some()),
            ("climbs", r.climbs.is_some()),
            ("speed_changes", r.speed_changes.is_some()),
        ];
        match r.kind {
            TrajectoryKind::Multirotor => {
                if let Some((key, _)) = fixed_wing_keys.iter().find(|(_, given)| *given) {
                    return Err(format!(
                        "`{key}` is a fixed-wing key; a multirotor trajectory takes heading_deg, \
                         turns and velocity_changes"
                    ));
                }
            }
            TrajectoryKind::FixedWing => {
                if r.velocity_changes.is_some() {
                    return Err(
                        "`velocity_changes` needs kind = \"multirotor\" (a fixed wing takes \
                         speed_changes, climbs and turns)"
                            .into(),
                    );
                }
            }
        }
        let d = TrajectorySpec::default();
        Ok(Self {
            kind: r.kind,
            speed_mps: r.speed_mps.map_or(d.speed_mps, |p| p.0),
            heading_deg: r.heading_deg.unwrap_or(d.heading_deg),
            flight_path_deg: r.flight_path_deg.unwrap_or(d.flight_path_deg),
            alpha_deg: r.alpha_deg.unwrap_or(d.alpha_deg),
            turns: r.turns,
            climbs: r.climbs.unwrap_or_default(),
            speed_changes: r.speed_changes.unwrap_or_default(),
            velocity_changes: r.velocity_changes.unwrap_or_default(),
        })
    }
}

/// A multirotor velocity change: the NED velocity moves smoothly to `to_ned_mps` over `ramp_s`.
/// Changes apply in start order, each from the velocity the previous one commanded.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VelocityChangeSpec {
    /// Start, s after `t0_ns`.
    #[serde(deserialize_with = "non_negative")]
    pub start_s: f64,
    /// Ramp time, s.
    #[serde(deserialize_with = "positive")]
    pub ramp_s: f64,
    /// Velocity after the ramp, north, east, down, m/s.
    #[serde(deserialize_with = "finite3")]
    pub to_ned_mps: [f64; 3],
}

/// A turn: the yaw rate rises smoothly to `rate_dps` over `ramp_s`, holds, and falls back to zero
/// by `start_s + duration_s`. Overlapping turns add.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, try_from = "TurnRaw")]
pub struct TurnSpec {
    /// Start, s after `t0_ns`.
    pub start_s: f64,
    /// Total duration including both ramps, s.
    pub duration_s: f64,
    /// Ramp time in and out, s.
    pub ramp_s: f64,
    /// Yaw rate held in the turn (positive = right turn), degrees/s.
    pub rate_dps: f64,
}

/// A climb or descent: the flight-path angle rises smoothly by `flight_path_deg`, holds, and
/// returns. Overlapping climbs add.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, try_from = "ClimbRaw")]
pub struct ClimbSpec {
    /// Start, s after `t0_ns`.
    pub start_s: f64,
    /// Total duration including both ramps, s.
    pub duration_s: f64,
    /// Ramp time in and out, s.
    pub ramp_s: f64,
    /// Flight-path angle added during the climb (negative = descent), degrees.
    pub flight_path_deg: f64,
}

/// A turn as written, before its checks.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct TurnRaw {
    start_s: f64,
    duration_s: f64,
    ramp_s: f64,
    rate_dps: f64,
}

/// A climb as written, before its checks.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct ClimbRaw {
    start_s: f64,
    duration_s: f64,
    ramp_s: f64,
    flight_path_deg: f64,
}

fn check_pulse(start_s: f64, duration_s: f64, ramp_s: f64) -> Result<(), String> {
    if !(start_s.is_finite() && start_s >= 0.0) {
        return Err(format!("start_s must be ≥ 0, got {start_s}"));
    }
    if !(ramp_s.is_finite() && ramp_s > 0.0) {
        return Err(format!("ramp_s must be > 0, got {ramp_s}"));
    }
    if !(duration_s.is_finite() && duration_s >= 2.0 * ramp_s) {
        return Err(format!(
            "duration_s ({duration_s}) must be at least twice ramp_s ({ramp_s})"
        ));
    }
    Ok(())
}

impl TryFrom<TurnRaw> for TurnSpec {
    type Error = String;
    fn try_from(r: TurnRaw) -> Result<Self, String> {
        check_pulse(r.start_s, r.duration_s, r.ramp_s)?;
        Ok(Self {
            start_s: r.start_s,
            duration_s: r.duration_s,
            ramp_s: r.ramp_s,
            rate_dps: r.rate_dps,
        })
    }
}

impl TryFrom<ClimbRaw> for ClimbSpec {
    type Error = String;
    fn try_from(r: ClimbRaw) -> Result<Self, String> {
        check_pulse(r.start_s, r.duration_s, r.ramp_s)?;
        Ok(Self {
            start_s: r.start_s,
            duration_s: r.duration_s,
            ramp_s: r.ramp_s,
            flight_path_deg: r.flight_path_deg,
        })
    }
}

/// A speed change: the ground speed moves smoothly to `to_mps` over `ramp_s`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpeedChangeSpec {
    /// Start, s after `t0_ns`.
    #[serde(deserialize_with = "non_negative")]
    pub start_s: f64,
    /// Ramp time, s.
    #[serde(deserialize_with = "positive")]
    pub ramp_s: f64,
    /// Ground speed after the ramp, m/s.
    #[serde(deserialize_with = "positive")]
    pub to_mps: f64,
}

/// IMU grade and rate (white noise, bias random walk, turn-on bias).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuSpec {
    /// Sample rate, Hz.
    #[serde(deserialize_with = "positive")]
    pub rate_hz: f64,
    /// Gyro white noise density, rad/s/√Hz.
    #[serde(deserialize_with = "non_negative")]
    pub gyro_noise_density: f64,
    /// Gyro bias random walk, rad/s²/√Hz.
    #[serde(deserialize_with = "non_negative")]
    pub gyro_random_walk: f64,
    /// Accelerometer white noise density, m/s²/√Hz.
    #[serde(deserialize_with = "non_negative")]
    pub accel_noise_density: f64,
    /// Accelerometer bias random walk, m/s³/√Hz.
    #[serde(deserialize_with = "non_negative")]
    pub accel_random_walk: f64,
    /// 1-σ gyro turn-on bias per axis, rad/s.
    #[serde(deserialize_with = "non_negative")]
    pub gyro_bias_sigma_radps: f64,
    /// 1-σ accelerometer turn-on bias per axis, m/s².
    #[serde(deserialize_with = "non_negative")]
    pub accel_bias_sigma_mps2: f64,
}

impl Default for ImuSpec {
    fn default() -> Self {
        let t = uavnav_core::ImuConfig::TACTICAL_MEMS;
        Self {
            rate_hz: DEFAULT_IMU_RATE_HZ,
            gyro_noise_density: t.gyro_noise_density,
            gyro_random_walk: t.gyro_random_walk,
            accel_noise_density: t.accel_noise_density,
            accel_random_walk: t.accel_random_walk,
            gyro_bias_sigma_radps: DEFAULT_GYRO_BIAS_SIGMA_RADPS,
            accel_bias_sigma_mps2: DEFAULT_ACCEL_BIAS_SIGMA_MPS2,
        }
    }
}

/// GNSS receiver: rate, errors, lever arm, outages and glitches.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GnssSpec {
    /// Whether the vehicle carries a receiver.
    pub enabled: bool,
    /// Fix rate, Hz (fix times are snapped to the IMU grid).
    #[serde(deserialize_with = "positive")]
    pub rate_hz: f64,
    /// Antenna phase centre in the body frame (x fwd, y right, z down), m.
    pub lever_arm_m: [f64; 3],
    /// 1-σ white horizontal position noise per axis, m.
    #[serde(deserialize_with = "non_negative")]
    pub white_sigma_h_m: f64,
    /// 1-σ white vertical position noise, m.
    #[serde(deserialize_with = "non_negative")]
    pub white_sigma_v_m: f64,
    /// 1-σ steady-state Gauss–Markov horizontal position error per axis, m.
    #[serde(deserialize_with = "non_negative")]
    pub gm_sigma_h_m: f64,
    /// 1-σ steady-state Gauss–Markov vertical position error, m.
    #[serde(deserialize_with = "non_negative")]
    pub gm_sigma_v_m: f64,
    /// Correlation time of the Gauss–Markov error, s.
    #[serde(deserialize_with = "positive")]
    pub gm_tau_s: f64,
    /// 1-σ white velocity noise per axis, m/s.
    #[serde(deserialize_with = "non_negative")]
    pub vel_sigma_mps: f64,
    /// Satellites reported in each fix.
    pub num_sats: u32,
    /// Windows with no fixes.
    pub outages: Vec<WindowSpec>,
    /// Undetected position steps.
    pub glitches: Vec<GlitchSpec>,
}

impl Default for GnssSpec {
    fn default() -> Self {
        Self {
            enabled: true,
            rate_hz: DEFAULT_GNSS_RATE_HZ,
            lever_arm_m: [0.0; 3],
            white_sigma_h_m: 0.5,
            white_sigma_v_m: 0.8,
            gm_sigma_h_m: 1.5,
            gm_sigma_v_m: 2.5,
            gm_tau_s: 300.0,
            vel_sigma_mps: 0.05,
            num_sats: 12,
            outages: Vec::new(),
            glitches: Vec::new(),
        }
    }
}

/// A time window `[start_s, end_s)` after `t0_ns`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, try_from = "WindowRaw")]
pub struct WindowSpec {
    /// Start, s.
    pub start_s: f64,
    /// End (exclusive), s.
    pub end_s: f64,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct WindowRaw {
    start_s: f64,
    end_s: f64,
}

impl TryFrom<WindowRaw> for WindowSpec {
    type Error = String;
    fn try_from(r: WindowRaw) -> Result<Self, String> {
        if !(r.start_s.is_finite()
            && r.end_s.is_finite()
            && r.start_s >= 0.0
            && r.end_s > r.start_s)
        {
            return Err(format!(
                "window needs 0 ≤ start_s < end_s, got start_s {} end_s {}",
                r.start_s, r.end_s
            ));
        }
        Ok(Self {
            start_s: r.start_s,
            end_s: r.end_s,
        })
    }
}

impl WindowSpec {
    /// Whether `t_s` (s after `t0_ns`) falls in the window.
    pub fn contains(&self, t_s: f64) -> bool {
        t_s >= self.start_s && t_s < self.end_s
    }
}

/// A GNSS glitch: the reported position jumps by `offset_ned_m` during the window.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GlitchSpec {
    /// Start, s after `t0_ns`.
    #[serde(deserialize_with = "non_negative")]
    pub start_s: f64,
    /// Duration, s.
    #[serde(deserialize_with = "positive")]
    pub duration_s: f64,
    /// Position offset north, east, down, m.
    pub offset_ned_m: [f64; 3],
}

/// Camera: resolution, intrinsics, distortion, mount, rate, image quality.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraSpec {
    /// Whether the vehicle carries the camera.
    pub enabled: bool,
    /// Frame rate, Hz (frame times are snapped to the IMU grid).
    #[serde(deserialize_with = "positive")]
    pub rate_hz: f64,
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Focal length x, px.
    #[serde(deserialize_with = "positive")]
    pub fx: f64,
    /// Focal length y, px.
    #[serde(deserialize_with = "positive")]
    pub fy: f64,
    /// Principal point x, px.
    pub cx: f64,
    /// Principal point y, px.
    pub cy: f64,
    /// Radial-tangential distortion `[k1, k2, p1, p2]` (all zero = ideal pinhole).
    pub distortion: [f64; 4],
    /// Mount rotation `body_from_cam` as ZYX Euler angles [roll, pitch, yaw], degrees.
    /// `[0, 0, 90]` = nadir: camera z = body down, camera x = body right, camera y = body backward.
    pub body_from_cam_rpy_deg: [f64; 3],
    /// Camera centre in the body frame, m.
    pub body_from_cam_xyz_m: [f64; 3],
    /// JPEG quality, 1–100.
    pub jpeg_quality: u8,
    /// 1-σ white pixel noise, gray levels (0–255 scale).
    #[serde(deserialize_with = "non_negative")]
    pub noise_sigma: f64,
}

impl Default for CameraSpec {
    fn default() -> Self {
        Self {
            enabled: true,
            rate_hz: DEFAULT_CAMERA_RATE_HZ,
            width: 640,
            height: 480,
            fx: 500.0,
            fy: 500.0,
            cx: 319.5,
            cy: 239.5,
            distortion: [-0.05, 0.01, 0.0, 0.0],
            body_from_cam_rpy_deg: [0.0, 0.0, 90.0],
            body_from_cam_xyz_m: [0.0; 3],
            jpeg_quality: 90,
            noise_sigma: 2.0,
        }
    }
}

/// The ground: a textured surface at a fixed height above the WGS84 ellipsoid.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TerrainSpec {
    /// Terrain elevation above the WGS84 ellipsoid, m.
    pub elevation_m: f64,
}

impl Default for TerrainSpec {
    fn default() -> Self {
        Self {
            elevation_m: DEFAULT_TERRAIN_ELEVATION_M,
        }
    }
}

/// A decimal year the magnetic model can be extrapolated to with some sense (1900–2100).
fn date_year<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    let v = f64::deserialize(d)?;
    if v.is_finite() && (1900.0..=2100.0).contains(&v) {
        Ok(v)
    } else {
        Err(D::Error::custom(format!(
            "must be a decimal year in 1900–2100 (e.g. 2026.5), got {v}"
        )))
    }
}

/// Any finite number (signed rates): rejected at its own line otherwise.
fn finite<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    let v = f64::deserialize(d)?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(D::Error::custom(format!(
            "must be a finite number, got {v}"
        )))
    }
}

/// A finite 3-vector: rejected at its own line otherwise.
fn finite3<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 3], D::Error> {
    let v = <[f64; 3]>::deserialize(d)?;
    if v.iter().all(|x| x.is_finite()) {
        Ok(v)
    } else {
        Err(D::Error::custom(format!("must be finite, got {v:?}")))
    }
}

/// A finite number > 0 (rates, durations): rejected at its own line otherwise.
fn positive<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    let v = f64::deserialize(d)?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(D::Error::custom(format!("must be a number > 0, got {v}")))
    }
}

/// A finite number ≥ 0 (noise levels): rejected at its own line otherwise.
fn non_negative<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    let v = f64::deserialize(d)?;
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(D::Error::custom(format!("must be a number ≥ 0, got {v}")))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn minimal_file_takes_defaults() {
        let s = Scenario::from_toml_str("seed = 3\nduration_s = 10\n").unwrap();
        assert_eq!(s.seed, 3);
        assert_eq!(s.t0_ns, DEFAULT_T0_NS);
        assert_eq!(s.imu, ImuSpec::default());
    }

    #[test]
    fn trajectory_keys_of_the_other_kind_are_refused() {
        let e = Scenario::from_toml_str(
            "seed = 1\nduration_s = 1\n[trajectory]\nkind = \"multirotor\"\nspeed_mps = 3\n",
        )
        .unwrap_err();
        assert!(e.message.contains("speed_mps"), "{e}");
        let e = Scenario::from_toml_str(
            "seed = 1\nduration_s = 1\n[trajectory]\nvelocity_changes = []\n",
        )
        .unwrap_err();
        assert!(e.message.contains("multirotor"), "{e}");
        let e = Scenario::from_toml_str("seed = 1\nduration_s = 1\n[trajectory]\nspeed_mps = -3\n")
            .unwrap_err();
        assert_eq!(e.line, 4, "{e}");
        let s = Scenario::from_toml_str(
            "seed = 1\nduration_s = 1\n[trajectory]\nkind = \"multirotor\"\nheading_deg = 30\n",
        )
        .unwrap();
        assert_eq!(s.trajectory.kind, TrajectoryKind::Multirotor);
        assert_eq!(s.trajectory.heading_deg, 30.0);
        assert_eq!(s.trajectory.speed_mps, DEFAULT_SPEED_MPS);
    }

    #[test]
    fn line_col_counts_from_one() {
        assert_eq!(line_col("ab\ncd", 0), (1, 1));
        assert_eq!(line_col("ab\ncd", 4), (2, 2));
    }
}
