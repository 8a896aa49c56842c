//! MAVLink telemetry (`.tlog`) → [`FlightLog`]: what a ground station recorded of one vehicle.
//!
//! Messages read (MAVLink common set, wire layouts as defined there):
//! * IMU: `RAW_IMU` from ArduPilot, which sends it scaled (mG, mrad/s, mGauss, FRD body), else
//!   `SCALED_IMU2` (the same units by definition). Its magnetometer fields are the compass.
//! * GNSS: `GPS_RAW_INT`: position (MSL altitude made ellipsoidal with EGM96, or the
//!   `alt_ellipsoid` extension), ground speed and course as a horizontal velocity (no vertical
//!   component: the estimator fuses such fixes for position only), and accuracy from the `h_acc`,
//!   `v_acc`, `vel_acc` extensions when sent, else from HDOP/VDOP ([`UERE_M`]).
//! * Barometer: `SCALED_PRESSURE` (hPa, cdegC).
//! * Clock: `SYSTEM_TIME` pairs the vehicle's boot time with UNIX time; without it, times are
//!   since boot.
//! * Reference: `ATTITUDE` with `GLOBAL_POSITION_INT` (the autopilot's own estimate).
//! * Vehicle type: `HEARTBEAT.type`.
//! * Parameters: `PARAM_VALUE` (sent when the ground station read them; last value wins). From
//!   ArduPilot, `AHRS_TRIM_X/Y` rotate the IMU into the vehicle frame `ATTITUDE` is reported in,
//!   as for a `.BIN` ([`crate::trim`]).
//!
//! Only the system that sent the most IMU messages is read (a tlog also holds the ground
//! station's own heartbeats, and may hold other vehicles). Telemetry streams are slow (a ground
//! station asks for 2–10 Hz by default); the import says so in its notes when the IMU is below
//! [`SLOW_IMU_HZ`].

use std::collections::BTreeMap;

use nalgebra::{UnitQuaternion, Vector3};
use uavnav_core::geoid::egm96_undulation_m;
use uavnav_core::{
    BaroSample, GnssFix, GnssVelocity, ImuSample, Lla, LocalFrame, MagSample, TruthSample,
};

use crate::tlog::{self, Fields, Frame};
use crate::{FlightLog, ImportOptions, LogError, LogKind, VehicleKind};

/// User-equivalent range error, m: HDOP × this is the horizontal σ when the receiver sends no
/// accuracy (single-frequency code positioning).
pub const UERE_M: f64 = 2.5;
/// Velocity σ when the receiver sends none, m/s.
pub const DEFAULT_VEL_SIGMA_MPS: f64 = 0.3;
/// Below this IMU rate the import notes that attitude will follow the motion poorly, Hz.
pub const SLOW_IMU_HZ: f64 = 20.0;
/// GNSS delay assumed when the user gives none, s (ArduPilot's default `EK3_GPS_DELAY`; a tlog
/// does not carry the parameter in a form read here).
pub const DEFAULT_GNSS_DELAY_S: f64 = 0.22;

const G: f64 = 9.806_65;
const HEARTBEAT: u32 = 0;
const SYSTEM_TIME: u32 = 2;
const PARAM_VALUE: u32 = 22;
const GPS_RAW_INT: u32 = 24;
const RAW_IMU: u32 = 27;
const SCALED_PRESSURE: u32 = 29;
const ATTITUDE: u32 = 30;
const GLOBAL_POSITION_INT: u32 = 33;
const SCALED_IMU2: u32 = 116;
/// `HEARTBEAT.autopilot` of ArduPilot.
const MAV_AUTOPILOT_ARDUPILOTMEGA: u8 = 3;

fn name(id: u32) -> String {
    match id {
        HEARTBEAT => "HEARTBEAT".into(),
        SYSTEM_TIME => "SYSTEM_TIME".into(),
        PARAM_VALUE => "PARAM_VALUE".into(),
        GPS_RAW_INT => "GPS_RAW_INT".into(),
        RAW_IMU => "RAW_IMU".into(),
        SCALED_PRESSURE => "SCALED_PRESSURE".into(),
        ATTITUDE => "ATTITUDE".into(),
        GLOBAL_POSITION_INT => "GLOBAL_POSITION_INT".into(),
        SCALED_IMU2 => "SCALED_IMU2".into(),
        other => format!("MAVLINK_{other}"),
    }
}

pub(crate) fn sniff(data: &[u8]) -> bool {
    tlog::sniff(data)
}

pub(crate) fn import(data: &[u8], opts: &ImportOptions) -> Result<FlightLog, LogError> {
    let t = tlog::parse(data);
    let mut notes = Vec::new();
    if let Some(at) = t.cut_at {
        notes.push(format!(
            "the log ends inside a record at byte {at} (cut short); everything before it kept"
        ));
    }
    if t.crc_errors > 0 || t.resyncs > 0 {
        notes.push(format!(
            "{} frames with a bad checksum skipped, framing lost and found again {} times",
            t.crc_errors, t.resyncs
        ));
    }
    let mut message_counts: BTreeMap<String, usize> = BTreeMap::new();
    for f in &t.frames {
        *message_counts.entry(name(f.id)).or_default() += 1;
    }
    for (id, n) in &t.unknown {
        *message_counts.entry(name(*id)).or_default() += n;
    }

    // The vehicle: the system that sent the most IMU messages.
    let mut imu_by_sys: BTreeMap<u8, usize> = BTreeMap::new();
    for f in t
        .frames
        .iter()
        .filter(|f| f.id == RAW_IMU || f.id == SCALED_IMU2)
    {
        *imu_by_sys.entry(f.sys).or_default() += 1;
    }
    let Some((&sys, _)) = imu_by_sys
        .iter()
        .max_by_key(|(s, n)| (**n, std::cmp::Reverse(**s)))
    else {
        return Err(LogError::Unusable(
            "no RAW_IMU or SCALED_IMU2 messages in the telemetry".into(),
        ));
    };
    if imu_by_sys.len() > 1 {
        notes.push(format!(
            "several vehicles in the telemetry: system {sys} read"
        ));
    }
    let of = |id: u32| t.frames.iter().filter(move |f| f.sys == sys && f.id == id);

    let heartbeat = of(HEARTBEAT).next_back().map(|f| Fields(&f.payload));
    let ardupilot = heartbeat
        .as_ref()
        .is_some_and(|h| h.u8(5) == MAV_AUTOPILOT_ARDUPILOTMEGA);
    let vehicle = heartbeat.as_ref().map_or(VehicleKind::Unknown, |h| {
        VehicleKind::from_mav_type(i64::from(h.u8(4)))
    });

    // Boot → UNIX offset from SYSTEM_TIME.
    let diffs: Vec<f64> = of(SYSTEM_TIME)
        .filter_map(|f| {
            let p = Fields(&f.payload);
            let unix = p.u64(0);
            (unix > 0).then(|| unix as f64 - p.u32(8) * 1e3)
        })
        .collect();
    let (time_base, offset_ns) = crate::time_base(&diffs, "SYSTEM_TIME with UNIX time", &mut notes);
    let boot_us = |us: f64| (us as i64).saturating_mul(1000).saturating_add(offset_ns);
    let boot_ms = |ms: f64| boot_us(ms * 1e3);

    let (mut imu, mag) = imu_and_mag(&t.frames, sys, ardupilot, &boot_us, &boot_ms, &mut notes)?;
    let gnss = gnss(of(GPS_RAW_INT), opts, &boot_us, &mut notes);
    let baro: Vec<BaroSample> = of(SCALED_PRESSURE)
        .map(|f| {
            let p = Fields(&f.payload);
            BaroSample {
                t_ns: boot_ms(p.u32(0)),
                pressure_pa: p.f32(4) * 100.0,
                temperature_degc: Some(p.i16(12) * 0.01),
            }
        })
        .filter(|b| b.pressure_pa.is_finite() && b.pressure_pa > 0.0)
        .collect();
    let baro = monotonic(baro, |b| b.t_ns, "SCALED_PRESSURE", &mut notes);
    let (reference, reference_origin) = reference(of(ATTITUDE), of(GLOBAL_POSITION_INT), &boot_ms);

    let rate_hz = crate::median_dt_s(imu.iter().map(|s| s.t_ns)).map_or(0.0, |dt| 1.0 / dt);
    if rate_hz < SLOW_IMU_HZ {
        notes.push(format!(
            "IMU at {rate_hz:.1} Hz (a telemetry stream): the attitude between samples is not \
             seen, so estimates follow the motion poorly; an onboard log (.BIN, .ulg) has the IMU \
             at full rate"
        ));
    }
    let gnss_delay_s = opts.gnss_delay_s.unwrap_or_else(|| {
        notes.push(format!(
            "GNSS delay not known from the telemetry: {DEFAULT_GNSS_DELAY_S} s assumed"
        ));
        DEFAULT_GNSS_DELAY_S
    });
    let mut config = crate::mems_config(&imu, 0.0, &gnss, &mag, &baro, gnss_delay_s);
    let mut params: BTreeMap<String, f64> = BTreeMap::new();
    for f in of(PARAM_VALUE) {
        let p = Fields(&f.payload);
        let value = p.f32(0);
        let id = p.text(8, 16);
        if !id.is_empty() && value.is_finite() {
            params.insert(id, value);
        }
    }
    if ardupilot {
        crate::trim::apply(&params, &mut imu, &mut config, &mut notes);
    }
    Ok(FlightLog {
        source: LogKind::Mavlink,
        vehicle,
        firmware: heartbeat.map(|h| format!("MAVLink autopilot {}", h.u8(5))),
        time_base,
        time_offset_ns: offset_ns,
        imu,
        gnss,
        mag,
        baro,
        reference_name: (!reference.is_empty())
            .then(|| "ATTITUDE + GLOBAL_POSITION_INT".to_string()),
        reference,
        reference_origin,
        attitude_flown: Vec::new(),
        params,
        gnss_delay_s,
        config,
        message_counts,
        notes,
    })
}

/// IMU samples and the compass in them, from `RAW_IMU` (ArduPilot) or `SCALED_IMU2`.
fn imu_and_mag(
    frames: &[Frame],
    sys: u8,
    ardupilot: bool,
    boot_us: &dyn Fn(f64) -> i64,
    boot_ms: &dyn Fn(f64) -> i64,
    notes: &mut Vec<String>,
) -> Result<(Vec<ImuSample>, Vec<MagSample>), LogError> {
    let raw = ardupilot && frames.iter().any(|f| f.sys == sys && f.id == RAW_IMU);
    let (id, first) = if raw { (RAW_IMU, 8) } else { (SCALED_IMU2, 4) };
    if !raw && frames.iter().any(|f| f.sys == sys && f.id == RAW_IMU) {
        notes
            .push("RAW_IMU left out: not from ArduPilot, so its units are the sensor's own".into());
    }
    let mut imu: Vec<ImuSample> = Vec::new();
    let mut mag = Vec::new();
    let mut back_in_time = 0usize;
    for f in frames.iter().filter(|f| f.sys == sys && f.id == id) {
        let p = Fields(&f.payload);
        let t_ns = if raw {
            boot_us(p.u64(0) as f64)
        } else {
            boot_ms(p.u32(0))
        };
        let v = |k: usize| {
            Vector3::new(
                p.i16(first + 6 * k),
                p.i16(first + 6 * k + 2),
                p.i16(first + 6 * k + 4),
            )
        };
        if imu.last().is_some_and(|s| t_ns <= s.t_ns) {
            back_in_time += 1;
            continue;
        }
        imu.push(ImuSample {
            t_ns,
            gyro_radps: v(1) * 1e-3,
            accel_mps2: v(0) * (G * 1e-3),
        });
        let m = v(2);
        if m != Vector3::zeros() {
            // mGauss → tesla
            mag.push(MagSample {
                t_ns,
                field_t: m * 1e-7,
            });
        }
    }
    let mag = monotonic(mag, |m| m.t_ns, "magnetometer", notes);
    if back_in_time > 0 {
        notes.push(format!(
            "{}: {back_in_time} samples not after the previous one left out",
            name(id)
        ));
    }
    if imu.is_empty() {
        return Err(LogError::Unusable("no IMU samples in the telemetry".into()));
    }
    Ok((imu, mag))
}

/// Fixes from `GPS_RAW_INT` (see the module doc).
fn gnss<'a>(
    frames: impl Iterator<Item = &'a Frame>,
    opts: &ImportOptions,
    boot_us: &dyn Fn(f64) -> i64,
    notes: &mut Vec<String>,
) -> Vec<GnssFix> {
    let (mut out, mut total) = (Vec::new(), 0usize);
    for f in frames {
        total += 1;
        let p = Fields(&f.payload);
        let (fix, sats) = (p.u8(28), p.u8(29));
        if fix < 3 || (sats != 255 && u32::from(sats) < opts.min_sats) {
            continue;
        }
        let us = p.u64(0);
        // `time_usec` is UNIX time or time since boot, as the sender chooses.
        let t_ns = if us > 946_684_800_000_000 {
            (us as i64).saturating_mul(1000)
        } else {
            boot_us(us as f64)
        };
        let (lat, lon) = (p.i32(8) * 1e-7, p.i32(12) * 1e-7);
        let ell = p.i32(30);
        let alt_m = if ell != 0.0 {
            ell * 1e-3
        } else {
            p.i32(16) * 1e-3 + egm96_undulation_m(lat, lon)
        };
        let dop = |v: f64| (v != 65535.0).then_some(v * 0.01);
        let (h_acc, v_acc, vel_acc) = (p.u32(34) * 1e-3, p.u32(38) * 1e-3, p.u32(42) * 1e-3);
        let sigma_h_m = if h_acc > 0.0 {
            h_acc
        } else {
            dop(p.u16(20)).map_or(5.0, |d| d * UERE_M)
        }
        .max(0.3);
        let sigma_v_m = if v_acc > 0.0 {
            v_acc
        } else {
            dop(p.u16(22)).map_or(1.5 * sigma_h_m, |d| d * UERE_M)
        }
        .max(0.5);
        let (vel, cog) = (p.u16(24), p.u16(26));
        let velocity = (vel != 65535.0 && cog != 65535.0).then(|| {
            let (v, c) = (vel * 0.01, (cog * 0.01).to_radians());
            GnssVelocity {
                north_mps: v * c.cos(),
                east_mps: v * c.sin(),
                down_mps: None,
                sigma_mps: if vel_acc > 0.0 {
                    vel_acc.max(0.05)
                } else {
                    DEFAULT_VEL_SIGMA_MPS
                },
            }
        });
        out.push(GnssFix {
            t_ns,
            lat_deg: lat,
            lon_deg: lon,
            alt_m,
            velocity,
            sigma_h_m,
            sigma_v_m,
            fix_type: crate::fix_type(f64::from(fix)),
            num_sats: u32::from(sats),
        });
    }
    if out.len() < total {
        notes.push(format!(
            "GPS_RAW_INT: {} of {total} messages dropped (fix_type < 3 or fewer than {} satellites)",
            total - out.len(),
            opts.min_sats
        ));
    }
    monotonic(out, |g| g.t_ns, "GPS_RAW_INT", notes)
}

/// Keeps the samples whose stamp is after the previous kept one (telemetry links deliver some
/// messages late or twice), with a note of how many were left out.
fn monotonic<T>(
    samples: Vec<T>,
    t_ns: impl Fn(&T) -> i64,
    what: &str,
    notes: &mut Vec<String>,
) -> Vec<T> {
    let n = samples.len();
    let mut out: Vec<T> = Vec::with_capacity(n);
    for s in samples {
        if out.last().is_none_or(|p| t_ns(&s) > t_ns(p)) {
            out.push(s);
        }
    }
    if out.len() < n {
        notes.push(format!(
            "{what}: {} samples not after the previous one left out",
            n - out.len()
        ));
    }
    out
}

/// `GLOBAL_POSITION_INT` with the latest `ATTITUDE` at each, in a local frame at the first.
fn reference<'a>(
    att: impl Iterator<Item = &'a Frame>,
    pos: impl Iterator<Item = &'a Frame>,
    boot_ms: &dyn Fn(f64) -> i64,
) -> (Vec<TruthSample>, Option<Lla>) {
    let quats: Vec<(i64, UnitQuaternion<f64>)> = att
        .map(|f| {
            let p = Fields(&f.payload);
            (
                boot_ms(p.u32(0)),
                UnitQuaternion::from_euler_angles(p.f32(4), p.f32(8), p.f32(12)),
            )
        })
        .collect();
    let mut frame: Option<LocalFrame> = None;
    let mut out: Vec<TruthSample> = Vec::new();
    for f in pos {
        let p = Fields(&f.payload);
        let (lat, lon) = (p.i32(4) * 1e-7, p.i32(8) * 1e-7);
        if lat == 0.0 && lon == 0.0 {
            continue;
        }
        let lla = Lla::from_deg(lat, lon, p.i32(12) * 1e-3 + egm96_undulation_m(lat, lon));
        let fr = *frame.get_or_insert_with(|| LocalFrame::new(lla));
        let t_ns = boot_ms(p.u32(0));
        let i = quats.partition_point(|q| q.0 <= t_ns);
        let Some(q) = i.checked_sub(1).and_then(|j| quats.get(j)) else {
            continue;
        };
        if out.last().is_some_and(|s| t_ns <= s.t_ns) {
            continue;
        }
        out.push(TruthSample {
            t_ns,
            pos_ned_m: fr.lla_to_ned(&lla),
            nav_from_body: q.1,
            vel_ned_mps: Vector3::new(p.i16(20), p.i16(22), p.i16(24)) * 0.01,
            gyro_bias_radps: Vector3::zeros(),
            accel_bias_mps2: Vector3::zeros(),
        });
    }
    (out, frame.map(|f| f.origin()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::TimeBase;
    use crate::tlog::tests::record_v1;

    #[test]
    fn a_small_telemetry_log_imports_with_its_units() {
        let rx = 1_533_737_161_905_000u64;
        let mut data = Vec::new();
        // HEARTBEAT: quadrotor, ArduPilot.
        data.extend(record_v1(rx, 0, &[0, 0, 0, 0, 2, 3, 0, 0, 3]));
        // SYSTEM_TIME: UNIX 1 533 737 145 465 009 µs at boot 608 582 ms.
        let mut st = 1_533_737_145_465_009u64.to_le_bytes().to_vec();
        st.extend(608_582u32.to_le_bytes());
        data.extend(record_v1(rx, 2, &st));
        for k in 0..5u64 {
            let mut imu = (608_582_234 + 250_000 * k).to_le_bytes().to_vec();
            for v in [33i16, -10, -999, -9, 3, -231, -146, -160, -541] {
                imu.extend(v.to_le_bytes());
            }
            data.extend(record_v1(rx + k, 27, &imu));
        }
        let mut gps = 608_463_000u64.to_le_bytes().to_vec();
        for v in [-353_629_847i32, 1_491_649_392, 587_850] {
            gps.extend(v.to_le_bytes());
        }
        for v in [121u16, 200, 187, 18_282] {
            gps.extend(v.to_le_bytes());
        }
        gps.extend([6u8, 10]);
        data.extend(record_v1(rx, 24, &gps));
        let log = crate::import(&data, &ImportOptions::default()).expect("imports");
        assert_eq!(log.source, LogKind::Mavlink);
        assert_eq!(log.vehicle, VehicleKind::Copter);
        assert_eq!(log.time_base, TimeBase::Unix);
        assert_eq!(log.imu.len(), 5);
        let s = log.imu[0];
        assert_eq!(s.t_ns, 1_533_737_145_465_243_000);
        assert!((s.accel_mps2.z + 0.999 * G).abs() < 1e-9);
        assert!((s.gyro_radps.z + 0.231).abs() < 1e-12);
        assert!((log.mag[0].field_t.z + 541e-7).abs() < 1e-15);
        let g = log.gnss[0];
        assert!((g.lat_deg + 35.362_984_7).abs() < 1e-9);
        assert!((g.sigma_h_m - 1.21 * UERE_M).abs() < 1e-9);
        let v = g.velocity.expect("velocity");
        assert!(v.down_mps.is_none());
        assert!((v.horizontal_mps().norm() - 1.87).abs() < 1e-9);
        assert!(log.notes.iter().any(|n| n.contains("telemetry stream")));
    }
}
