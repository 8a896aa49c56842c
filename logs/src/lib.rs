//! # uavnav-logs
//!
//! Flight-log import: an autopilot's own log file in, uavnav's sensor samples out. Pure: the
//! readers take `&[u8]`; [`open`] is the one convenience that reads a file first.
//!
//! | module | what it holds |
//! |---|---|
//! | `dataflash` (private) | ArduPilot DataFlash `.BIN` byte layer: `FMT`-driven message decoding |
//! | `ardupilot` (private) | DataFlash messages → [`FlightLog`]: UNIX time from GPS week/time of week, GNSS filtering and sigmas, MSL → ellipsoid, EKF reference |
//! | `ulog` (private) | PX4 ULog `.ulg` byte layer: header, definitions, data, appended data |
//! | `px4` (private) | ULog topics → [`FlightLog`] (old and new GNSS layouts) |
//! | `tlog` (private) | MAVLink telemetry `.tlog` byte layer: records, v1/v2 frames, checksums, resynchronisation |
//! | `mavlink` (private) | MAVLink messages → [`FlightLog`] (what a ground station recorded) |
//! | [`error`] | [`LogError`]: every decoding error names its byte offset |
//!
//! Entry points: [`import`] (bytes, format sniffed) and [`open`] (a path).
//!
//! ## Why our own readers
//!
//! The maintained crates were checked (sources of the versions named) and fall short of what an
//! importer of field logs needs:
//! * `ardupilot-binlog` 0.2.0: errors carry no byte offset; a truncated message ends iteration
//!   silently (indistinguishable from a clean end); unknown types and bad headers are skipped
//!   without a trace; an `FMT` declaring a length below 3 underflows `msg_len - 3`.
//! * `px4-ulog` 0.6.1: errors carry no byte offset; slices by offsets taken from the file without
//!   bounds checks and `panic!`s on unexpected field types.
//! * `yule_log` 0.4.0: errors carry no byte offset, and it stops at the first appended-data offset
//!   instead of reading the appended section.
//!
//! Both formats are small, documented and self-describing, so the two byte layers here are a few
//! hundred lines each, bounds-checked throughout, and tested against truncation and corruption.
//!
//! ## Conventions of the output
//!
//! Time: `t_ns` is UNIX time (UTC) when the log has GNSS time (ArduPilot: GPS week + time of week
//! minus the leap seconds of that date; PX4: `time_utc_usec` of the GNSS topic), else time since
//! boot, see [`FlightLog::time_base`]. GNSS fixes are stamped as logged; the autopilot's GNSS delay
//! is [`FlightLog::gnss_delay_s`] (the estimator applies `t − delay`). Altitudes are above the WGS84
//! ellipsoid ([`uavnav_core::geoid`] converts MSL). Body = FRD (both autopilots' body frame).

mod ardupilot;
mod dataflash;
pub mod error;
mod mavlink;
mod px4;
mod tlog;
pub mod trim;
mod ulog;

use std::collections::BTreeMap;

pub use error::LogError;
pub use uavnav_core::{BaroSample, GnssFix, GnssVelocity, MagSample};
use uavnav_core::{ImuSample, Lla, TruthSample, VehicleConfig};

/// Which autopilot wrote the log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LogKind {
    /// ArduPilot DataFlash `.BIN`.
    ArduPilot,
    /// PX4 ULog `.ulg`.
    Px4,
    /// MAVLink telemetry `.tlog`, as a ground station records it.
    Mavlink,
}

/// What kind of vehicle the log says it is (firmware name, `MAV_TYPE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum VehicleKind {
    /// The log does not say.
    #[default]
    Unknown,
    /// Multirotor / helicopter.
    Copter,
    /// Fixed wing.
    Plane,
    /// Fixed wing with vertical take-off.
    Vtol,
    /// Ground or surface vehicle.
    Rover,
    /// Submarine.
    Sub,
}

impl VehicleKind {
    /// The kind a MAVLink `MAV_TYPE` names (PX4's `MAV_TYPE` parameter, `HEARTBEAT.type`).
    pub fn from_mav_type(mav_type: i64) -> Self {
        match mav_type {
            1 => VehicleKind::Plane,
            2..=4 | 13..=15 => VehicleKind::Copter,
            19..=22 => VehicleKind::Vtol,
            10 | 11 => VehicleKind::Rover,
            12 => VehicleKind::Sub,
            _ => VehicleKind::Unknown,
        }
    }
}

/// The clock `t_ns` is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TimeBase {
    /// Nanoseconds since the UNIX epoch (UTC), from the log's GNSS time.
    Unix,
    /// Nanoseconds since the autopilot booted (the log has no usable GNSS time).
    Boot,
}

/// An attitude-only reference (ArduPilot `ATT`: the DCM attitude the vehicle flew on).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeSample {
    /// Time, ns.
    pub t_ns: i64,
    /// Rotation of body (FRD) vectors into local NED, Hamilton.
    pub nav_from_body: nalgebra::UnitQuaternion<f64>,
}

/// Import choices.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// GNSS delay, s, overriding the log's parameter (`EK3_GPS_DELAY`, `EKF2_GPS_DELAY`, ...).
    pub gnss_delay_s: Option<f64>,
    /// Minimum satellites for a kept fix (ArduPilot `NSats`, PX4 `satellites_used`).
    pub min_sats: u32,
    /// Stop at the first corrupt byte and return what came before it (with a note) instead of
    /// failing. A log that merely ends inside a message (cut by a power loss) is always read up
    /// to its last whole message, with a note naming the byte offset.
    pub stop_at_damage: bool,
}

impl Default for ImportOptions {
    fn default() -> Self {
        Self {
            gnss_delay_s: None,
            min_sats: 6,
            stop_at_damage: false,
        }
    }
}

/// One imported flight: sensor streams on one clock, the autopilot's own estimate as a reference,
/// its parameters and a suggested configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct FlightLog {
    /// Which autopilot wrote it.
    pub source: LogKind,
    /// Vehicle type, when the log says.
    pub vehicle: VehicleKind,
    /// Firmware description (ArduPilot's version message; PX4 `ver_sw_release`/`ver_sw`).
    pub firmware: Option<String>,
    /// The clock of every `t_ns`.
    pub time_base: TimeBase,
    /// Added to the autopilot's boot time to get `t_ns`, ns.
    pub time_offset_ns: i64,
    /// First IMU instance, body FRD, strictly increasing time.
    pub imu: Vec<ImuSample>,
    /// Kept GNSS fixes (3-D fix or better, at least `min_sats`), stamped as logged, altitude
    /// above the ellipsoid.
    pub gnss: Vec<GnssFix>,
    /// First magnetometer, tesla, calibrated as the autopilot logs it (empty when dead).
    pub mag: Vec<MagSample>,
    /// First barometer.
    pub baro: Vec<BaroSample>,
    /// The autopilot's own estimate (not ground truth) in local NED at [`Self::reference_origin`].
    pub reference: Vec<TruthSample>,
    /// Which message or topic [`Self::reference`] came from.
    pub reference_name: Option<String>,
    /// Origin of the reference's NED frame (altitude above the ellipsoid).
    pub reference_origin: Option<Lla>,
    /// The attitude the vehicle flew on, when logged apart from the reference (ArduPilot `ATT`).
    pub attitude_flown: Vec<AttitudeSample>,
    /// Every parameter in the log (last value wins).
    pub params: BTreeMap<String, f64>,
    /// The autopilot's GNSS delay (stamp − validity), s.
    pub gnss_delay_s: f64,
    /// A configuration derived from the log (rates, noise densities, delay).
    pub config: VehicleConfig,
    /// Messages (ArduPilot) or topic messages (PX4) in the file, by name.
    pub message_counts: BTreeMap<String, usize>,
    /// What was dropped or assumed, and why.
    pub notes: Vec<String>,
}

/// Imports a log from its bytes; the format is recognised from the first bytes.
pub fn import(data: &[u8], options: &ImportOptions) -> Result<FlightLog, LogError> {
    let mut log = if ulog::sniff(data) {
        px4::import(data, options)
    } else if dataflash::sniff(data) {
        ardupilot::import(data, options)
    } else if mavlink::sniff(data) {
        mavlink::import(data, options)
    } else {
        Err(LogError::UnknownFormat)
    }?;
    // The estimator takes a fixed wing's heading from its course when nothing else tells it.
    log.config.airframe = match log.vehicle {
        VehicleKind::Plane => uavnav_core::Airframe::FixedWing,
        VehicleKind::Copter => uavnav_core::Airframe::Multirotor,
        _ => uavnav_core::Airframe::Unknown,
    };
    Ok(log)
}

/// Reads a file and [`import`]s it.
pub fn open(
    path: impl AsRef<std::path::Path>,
    options: &ImportOptions,
) -> Result<FlightLog, LogError> {
    let path = path.as_ref();
    let data = std::fs::read(path).map_err(|e| LogError::Io {
        path: path.display().to_string(),
        reason: e.to_string(),
    })?;
    import(&data, options)
}

/// Median of a slice (sorted copy; the mean of the middle two for an even count). `None` when
/// empty.
/// The import note for where parsing stopped early.
pub(crate) fn damage_note(e: &LogError) -> String {
    if e.is_cut_tail() {
        format!(
            "the log ends inside a message (cut short, as when the logger loses power): {e}; that partial message dropped, everything before it kept"
        )
    } else {
        format!("stopped at the damage, everything after it dropped: {e}")
    }
}

/// The clock of a log from its boot → UNIX offsets (µs, one per message that pairs the two):
/// UNIX with their median, else since boot with a note saying that `source` was missing.
pub(crate) fn time_base(
    offsets_us: &[f64],
    source: &str,
    notes: &mut Vec<String>,
) -> (TimeBase, i64) {
    match median(offsets_us) {
        Some(us) => (TimeBase::Unix, (us.round() as i64).saturating_mul(1000)),
        None => {
            notes.push(format!("no {source}: times are since boot"));
            (TimeBase::Boot, 0)
        }
    }
}

pub(crate) fn median(values: &[f64]) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// GNSS, magnetometer and barometer configurations for the streams present: rates from the median
/// interval, the GNSS delay, default noise (the IMU is left at its default for the caller to set).
pub(crate) fn sensor_configs(
    gnss: &[GnssFix],
    mag: &[MagSample],
    baro: &[BaroSample],
    gnss_delay_s: f64,
) -> VehicleConfig {
    let rate =
        |t: Vec<i64>, default: f64| median_dt_s(t.into_iter()).map_or(default, |dt| 1.0 / dt);
    VehicleConfig {
        gnss: (!gnss.is_empty()).then(|| uavnav_core::GnssConfig {
            rate_hz: rate(gnss.iter().map(|g| g.t_ns).collect(), 5.0),
            delay_ns: uavnav_core::s_to_ns(gnss_delay_s),
            ..uavnav_core::GnssConfig::default()
        }),
        mag: (!mag.is_empty()).then(|| uavnav_core::MagConfig {
            rate_hz: rate(mag.iter().map(|m| m.t_ns).collect(), 10.0),
            ..uavnav_core::MagConfig::default()
        }),
        baro: (!baro.is_empty()).then(|| uavnav_core::BaroConfig {
            rate_hz: rate(baro.iter().map(|b| b.t_ns).collect(), 10.0),
            ..uavnav_core::BaroConfig::default()
        }),
        ..VehicleConfig::default()
    }
}

/// Median sample interval of increasing stamps, s.
/// The configuration of a log that carries no IMU noise terms (PX4, MAVLink telemetry): the
/// IMU's rate from its stamps (`default_rate_hz` with fewer than two) and in-flight MEMS values.
pub(crate) fn mems_config(
    imu: &[ImuSample],
    default_rate_hz: f64,
    gnss: &[GnssFix],
    mag: &[MagSample],
    baro: &[BaroSample],
    delay_s: f64,
) -> VehicleConfig {
    let rate_hz = median_dt_s(imu.iter().map(|s| s.t_ns)).map_or(default_rate_hz, |dt| 1.0 / dt);
    VehicleConfig {
        imu: uavnav_core::ImuConfig {
            rate_hz,
            gyro_noise_density: 2.1e-3,
            gyro_random_walk: 4e-5,
            accel_noise_density: 3.5e-2,
            accel_random_walk: 1e-3,
            // Not in the log: the estimator's default.
            gyro_bias_sigma_radps: 0.0,
            accel_bias_sigma_mps2: 0.0,
        },
        ..sensor_configs(gnss, mag, baro, delay_s)
    }
}

pub(crate) fn median_dt_s(t_ns: impl Iterator<Item = i64>) -> Option<f64> {
    let t: Vec<i64> = t_ns.collect();
    let dts: Vec<f64> = t
        .windows(2)
        .map(|w| w[1].saturating_sub(w[0]) as f64 * 1e-9)
        .collect();
    median(&dts).filter(|dt| *dt > 0.0)
}

/// The fix type from the code both autopilots log (ArduPilot `GPS.Status`, PX4 `fix_type`, the
/// MAVLink `GPS_FIX_TYPE` numbering): 2 2-D, 3 3-D, 4 DGPS, 5 RTK float, 6 and above RTK fixed.
pub(crate) fn fix_type(code: f64) -> uavnav_core::FixType {
    use uavnav_core::FixType;
    match code as i64 {
        2 => FixType::Fix2d,
        3 => FixType::Fix3d,
        4 => FixType::Dgps,
        5 => FixType::RtkFloat,
        s if s >= 6 => FixType::RtkFixed,
        _ => FixType::None,
    }
}
