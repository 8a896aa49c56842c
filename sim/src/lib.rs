//! # uavnav-sim
//!
//! A seeded, deterministic, pure (no I/O, no clock) UAV flight simulator, fixed wing or multirotor. A
//! [`Scenario`] (TOML) fixes everything; [`Flight::new`] precomputes truth, IMU, GNSS and, when the
//! scenario fits them, magnetometer and barometer; camera frames are ray-cast on demand.
//!
//! | module | what it holds |
//! |---|---|
//! | [`scenario`] | the scenario file: serde types, named defaults, errors with line/column |
//! | [`trajectory`] | closed-form fixed-wing kinematics from smooth commanded profiles; [`FlightPath`](trajectory::FlightPath) picks the kind |
//! | [`multirotor`] | closed-form multirotor kinematics: NED velocity and yaw commanded apart, tilt from the thrust |
//! | [`sensors`] | ideal IMU, IMU error model, GNSS receiver model (lever arm, Gauss–Markov, outages), magnetometer (WMM2025), barometer (ISA) |
//! | [`strapdown`] | a reference strapdown integrator (proves truth and IMU agree) |
//! | [`flight`] | [`Flight`]: the precomputed flight and its accessors |
//! | [`events`] | camera frames of a flight and its merged, time-ordered [`SensorEvent`](uavnav_core::SensorEvent) stream |
//! | [`terrain`] | the procedural, anti-aliased ground texture |
//! | [`render`] | ray casting the terrain ellipsoid, pixel noise, JPEG encoding |
//!
//! ## Physics contract (the estimator implements the same model)
//!
//! - World frame: a fixed, Earth-fixed local NED tangent frame at the scenario origin
//!   ([`uavnav_core::LocalFrame`]); the vehicle starts at its origin. Gravity is
//!   [`LocalFrame::gravity_ned`](uavnav_core::LocalFrame::gravity_ned)`(p)` (normal gravity,
//!   centrifugal included, local vertical tilt included). Earth rate in this frame:
//!   `ω_ie^n = Ω (cos φ0, 0, −sin φ0)`, φ0 = origin latitude ([`strapdown::earth_rate_ned`]).
//! - Body = FRD = IMU frame, at the centre of gravity. Gyro: `ω_ib^b = ω_nb^b + C_n^b ω_ie^n`.
//!   Accelerometer (specific force): `f^b = C_n^b (a^n − g^n(p) + 2 ω_ie^n × v^n)`, `a^n = dv/dt`
//!   in the fixed frame. Samples are instantaneous values at the sample time (EuRoC convention).
//! - IMU errors: `y = x + b + n`, white `n` with σ = density/√dt per sample, turn-on bias
//!   `b(0) ~ N(0, σ_b²)`, random walk `b(k+1) = b(k) + rw·√dt·N(0,1)`. Truth carries `b(k)`.
//! - GNSS (antenna at lever arm `r^b`, paper eqs. 32–33 in the fixed frame):
//!   `p_ant = p + C_b^n r^b`, `v_ant = v + C_b^n (ω_nb^b × r^b)`; position error = white +
//!   first-order Gauss–Markov (σ, τ) + glitch steps, per NED axis; reported `sigma_h_m` is the
//!   per-axis horizontal 1-σ `hypot(white, gm)`, likewise `sigma_v_m`. No fixes inside outages.
//!   Fix and camera times are snapped to the IMU time grid.
//! - Magnetometer (optional, `[mag]`): `m = R_bmᵀ (s · C_n^b B^n + d^b) + b + n`, `B^n` the
//!   WMM2025 field at the origin on the scenario's `date_year` (stamps are not UNIX time),
//!   `R_bm` = `body_from_mag`, `s` a calibration scale error, `d^b` disturbance windows in body
//!   axes, `b` a constant hard-iron residual drawn once, `n` white.
//! - Barometer (optional, `[baro]`): `p = p_sl (1 − 2.255 77·10⁻⁵ H)^5.255 88 + drift·t + w(t) + n`,
//!   the ISA troposphere with `H` the true height above the EGM96 geoid standing in for the
//!   geopotential height (they differ by `H²/R`, 0.16 m at 1 km), `p_sl` the day's sea-level
//!   pressure, `w` a random walk; the temperature given is the ISA air temperature at `H`.
//!   Magnetometer and barometer times are snapped to the IMU grid too.
//! - Camera: centre `p + C_b^n t_bc`, attitude `nav_from_cam = nav_from_body · R_bc` from the mount
//!   `body_from_cam` (default nadir: camera z = body down, x = body right, y = body backward).
//!   Each pixel's undistorted ray is intersected with the ellipsoid of semi-axes (a + h, b + h),
//!   h = terrain elevation — the "Earth surface" the estimator and vision crates model. Rays that
//!   miss the ground give [`render::SKY_GRAY`]. Frames are 8-bit gray JPEGs at IMU-grid times.
//! - Random streams: `Rng::derive(seed, "imu")`, `"gnss"`, `"mag"`, `"baro"`, `"terrain"`,
//!   `"image"`: adding or changing one sensor never changes another's noise.

pub mod events;
pub mod flight;
pub mod multirotor;
pub mod render;
pub mod scenario;
pub mod sensors;
pub mod strapdown;
pub mod terrain;
pub mod trajectory;

pub use flight::{Flight, SimError};
pub use render::{PixelNoise, RayTable, encode_jpeg, render_gray};
pub use scenario::{Scenario, ScenarioError};
pub use terrain::Terrain;
