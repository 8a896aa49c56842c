//! ArduPilot DataFlash messages → [`FlightLog`], following the rules of the project's shared
//! conversions (`shared/data/real_flights/README.md`):
//!
//! * **Time**: `t_ns = boot_ms·1e6 + offset`, `offset` = median over the kept `GPS` rows of (GPS
//!   week + time of week as UNIX ms − leap seconds of that date − the row's boot ms), rounded to
//!   the ms (ties to even). Boot time is `TimeUS` (µs) or `TimeMS` (old logs); in old `GPS` rows
//!   `TimeMS` is the GPS time of week and `T` the boot ms.
//! * **IMU**: `IMU` (instance 0), rows whose time is not after the previous kept one dropped.
//! * **GNSS**: `GPS` (instance 0) rows with `Status` ≥ 3 and `NSats` ≥ `min_sats`, stamped as
//!   logged; velocity `Spd·cos GCrs`, `Spd·sin GCrs`, `VZ`; altitude `Alt` (MSL) + EGM96 `N` at the
//!   fix; sigmas from `UBX3` hAcc/vAcc/sAcc or `GPA` HAcc/VAcc/SAcc nearest within 150 ms (floors
//!   0.3 / 0.5 / 0.1), else 1.5·HDop / 2.5·HDop / 0.5.
//! * **MAG**: `MAG` (instance 0) × 1e-7 T as logged: offsets are already in the logged values and
//!   the board rotation already applied. A log whose every row is identical (dead sensor) gives none.
//! * **BARO**: `BARO` (instance 0) `Press` Pa, `Temp` °C.
//! * **Reference**: `XKF1`/`NKF1` (core 0) or `EKF1`, from the first row with a non-zero
//!   velocity/position, duplicate stamps dropped; attitude from `Roll, Pitch, Yaw` (3-2-1).
//!   Origin: `ORGN` (type 0, the EKF origin) when logged, else the median of `AHR2` Lat/Lng/Alt
//!   moved back by the reference's `PN, PE, PD` at the same stamp (`AHR2` is the EKF's output when
//!   the EKF runs); altitude + EGM96 `N` at the origin.
//! * **ATT**: the attitude flown, as [`crate::AttitudeSample`]s.
//! * **Frame**: the body frame is the vehicle's as the autopilot reports it: `AHRS_TRIM_X/Y`
//!   rotate the IMU, and the compass's `body_from_mag`, out of the board frame they are logged in
//!   ([`crate::trim`]).

use std::collections::{BTreeMap, HashSet};

use nalgebra::Vector3;
use uavnav_core::geodesy::{radius_meridian, radius_prime_vertical};
use uavnav_core::geoid::egm96_undulation_m;
use uavnav_core::rotation::from_euler_zyx;
use uavnav_core::{ImuConfig, ImuSample, Lla, TruthSample, VehicleConfig};

use crate::dataflash::{self, DfLog, Table, Value};
use crate::{
    AttitudeSample, FlightLog, ImportOptions, LogError, LogKind, TimeBase, VehicleKind, fix_type,
};
use uavnav_core::{BaroSample, GnssFix, GnssVelocity, MagSample};

/// The messages the importer reads; every other type is only counted.
const KEEP: [&str; 14] = [
    "IMU", "GPS", "GPA", "UBX3", "MAG", "BARO", "PARM", "EKF1", "XKF1", "NKF1", "ATT", "AHR2",
    "ORGN", "MSG",
];

/// UNIX time of the GPS epoch (1980-01-06), s.
const GPS_EPOCH_UNIX_S: i64 = 315_964_800;
/// Window for pairing a fix with the receiver's accuracy message, µs.
const ACCURACY_WINDOW_US: i64 = 150_000;

/// Days from 1970-01-01 to a proleptic Gregorian date (Hinnant's civil-days algorithm).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// GPS − UTC, s, at a time given as GPS seconds on the UNIX epoch. The table lists the UTC dates
/// from which each count holds (IERS Bulletin C); no leap second has been announced since 2017.
pub(crate) fn gps_leap_seconds(gps_unix_s: i64) -> i64 {
    const TABLE: [(i64, i64, i64, i64); 18] = [
        (1981, 7, 1, 1),
        (1982, 7, 1, 2),
        (1983, 7, 1, 3),
        (1985, 7, 1, 4),
        (1988, 1, 1, 5),
        (1990, 1, 1, 6),
        (1991, 1, 1, 7),
        (1992, 7, 1, 8),
        (1993, 7, 1, 9),
        (1994, 7, 1, 10),
        (1996, 1, 1, 11),
        (1997, 7, 1, 12),
        (1999, 1, 1, 13),
        (2006, 1, 1, 14),
        (2009, 1, 1, 15),
        (2012, 7, 1, 16),
        (2015, 7, 1, 17),
        (2017, 1, 1, 18),
    ];
    TABLE
        .iter()
        .rev()
        .find(|(y, m, d, n)| gps_unix_s - n >= days_from_civil(*y, *m, *d) * 86_400)
        .map_or(0, |e| e.3)
}

/// A row's boot time in µs: `TimeUS`, else `TimeMS`.
fn boot_us(t: &Table, row: &[Value]) -> Option<i64> {
    if let Some(us) = t.num(row, "TimeUS") {
        return Some(us as i64);
    }
    t.num(row, "TimeMS")
        .map(|ms| (ms as i64).saturating_mul(1000))
}

/// Whether a row belongs to the first instance (layouts with an `I`/`C` field log all
/// instances in one message; older ones use `IMU2`, `MAG2`, ... which are not read).
fn first_instance(t: &Table, row: &[Value], field: &str) -> bool {
    t.num(row, field).is_none_or(|i| i == 0.0)
}

/// One `GPS` row, before filtering.
#[derive(Debug, Clone, Copy)]
struct GpsRow {
    boot_us: i64,
    status: f64,
    nsats: f64,
    unix_ms: Option<i64>,
    hdop: f64,
    lat: f64,
    lon: f64,
    alt_msl: f64,
    spd: Option<f64>,
    gcrs: Option<f64>,
    vz: Option<f64>,
}

fn gps_rows(t: &Table) -> Vec<GpsRow> {
    // Old layout: TimeMS = GPS time of week, Week, T = boot ms. Newer: TimeUS, GMS, GWk.
    let old = t.has("T") && t.has("Week");
    let hdop = t.pick(&["HDop", "HDp"]);
    let nsats = t.pick(&["NSats", "NSat", "nSat"]);
    t.rows
        .iter()
        .filter(|r| first_instance(t, r, "I"))
        .filter_map(|r| {
            let (boot_us, tow, week) = if old {
                (
                    (t.num(r, "T")? as i64).saturating_mul(1000),
                    t.num(r, "TimeMS"),
                    t.num(r, "Week"),
                )
            } else {
                (boot_us(t, r)?, t.num(r, "GMS"), t.num(r, "GWk"))
            };
            let unix_ms = match (tow, week) {
                (Some(tow), Some(week)) if week > 0.0 => {
                    let gps_ms = GPS_EPOCH_UNIX_S * 1000 + week as i64 * 604_800_000 + tow as i64;
                    Some(gps_ms - gps_leap_seconds(gps_ms / 1000) * 1000)
                }
                _ => None,
            };
            Some(GpsRow {
                boot_us,
                status: t.num(r, "Status")?,
                nsats: nsats.and_then(|c| t.num_at(r, c)).unwrap_or(0.0),
                unix_ms,
                hdop: hdop.and_then(|c| t.num_at(r, c)).unwrap_or(f64::NAN),
                lat: t.num(r, "Lat")?,
                lon: t.num(r, "Lng")?,
                alt_msl: t.num(r, "Alt")?,
                spd: t.num(r, "Spd"),
                gcrs: t.num(r, "GCrs"),
                vz: t.num(r, "VZ"),
            })
        })
        .collect()
}

/// The receiver's accuracies (boot µs, h, v, speed), from `UBX3` or `GPA`.
fn accuracies(log: &DfLog) -> Vec<(i64, f64, f64, f64)> {
    let (name, h, v, s) = if log.table("UBX3").is_some() {
        ("UBX3", "hAcc", "vAcc", "sAcc")
    } else {
        ("GPA", "HAcc", "VAcc", "SAcc")
    };
    let Some(t) = log.table(name) else {
        return Vec::new();
    };
    let mut out: Vec<_> = t
        .rows
        .iter()
        .filter(|r| first_instance(t, r, "I") && first_instance(t, r, "Instance"))
        .filter_map(|r| Some((boot_us(t, r)?, t.num(r, h)?, t.num(r, v)?, t.num(r, s)?)))
        .collect();
    out.sort_by_key(|a| a.0);
    out
}

/// The accuracy row nearest to `t_us` within the window: the earlier on a tie, the last of rows
/// sharing one stamp (a backlog the autopilot logged at once: the last is the receiver's latest).
fn nearest(acc: &[(i64, f64, f64, f64)], t_us: i64) -> Option<(f64, f64, f64)> {
    // of rows with equal stamps the last is taken (the receiver's latest report)
    let i = acc.partition_point(|a| a.0 <= t_us);
    [i.checked_sub(1), Some(i)]
        .into_iter()
        .flatten()
        .filter_map(|j| acc.get(j))
        .filter(|a| (a.0 - t_us).abs() <= ACCURACY_WINDOW_US)
        .min_by_key(|a| (a.0 - t_us).abs())
        .map(|a| (a.1, a.2, a.3))
}

pub(crate) fn import(data: &[u8], opts: &ImportOptions) -> Result<FlightLog, LogError> {
    let keep: HashSet<&str> = KEEP.into_iter().collect();
    let log = dataflash::parse(data, &keep, opts.stop_at_damage)?;
    let mut notes = Vec::new();
    if let Some(e) = &log.damage {
        notes.push(crate::damage_note(e));
    }
    notes.extend(log.skipped_formats.iter().cloned());

    let mut params = BTreeMap::new();
    if let Some(t) = log.table("PARM") {
        for r in &t.rows {
            if let (Some(n), Some(v)) = (t.text(r, "Name"), t.num(r, "Value")) {
                params.insert(n.to_string(), v);
            }
        }
    }
    let (firmware, vehicle) = firmware(&log);

    // Clock: UNIX from the kept fixes' GNSS time.
    let gps = log.table("GPS").map(gps_rows).unwrap_or_default();
    let kept: Vec<GpsRow> = gps
        .iter()
        .copied()
        .filter(|g| g.status >= 3.0 && g.nsats >= f64::from(opts.min_sats))
        .collect();
    if gps.len() > kept.len() {
        notes.push(format!(
            "GPS: {} of {} rows dropped (Status < 3 or fewer than {} satellites)",
            gps.len() - kept.len(),
            gps.len(),
            opts.min_sats
        ));
    }
    let diffs: Vec<f64> = kept
        .iter()
        .filter_map(|g| {
            Some((g.unix_ms?.saturating_mul(1000).saturating_sub(g.boot_us)) as f64 * 1e-3)
        })
        .collect();
    let (time_base, offset_ns) = match crate::median(&diffs) {
        Some(ms) => (
            TimeBase::Unix,
            (ms.round_ties_even() as i64).saturating_mul(1_000_000),
        ),
        None => {
            notes.push("no GPS week/time of week: times are since boot".into());
            (TimeBase::Boot, 0)
        }
    };
    let t_ns = |boot_us: i64| boot_us.saturating_mul(1000).saturating_add(offset_ns);

    // IMU
    let mut imu: Vec<ImuSample> = Vec::new();
    let mut imu_dropped = 0usize;
    let t = log
        .table("IMU")
        .ok_or_else(|| LogError::Unusable("no IMU messages".into()))?;
    for r in t.rows.iter().filter(|r| first_instance(t, r, "I")) {
        let vals = ["GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ"].map(|l| t.num(r, l));
        let (Some(tu), [Some(gx), Some(gy), Some(gz), Some(ax), Some(ay), Some(az)]) =
            (boot_us(t, r), vals)
        else {
            imu_dropped += 1;
            continue;
        };
        if imu.last().is_some_and(|p| t_ns(tu) <= p.t_ns) {
            imu_dropped += 1;
            continue;
        }
        imu.push(ImuSample {
            t_ns: t_ns(tu),
            gyro_radps: Vector3::new(gx, gy, gz),
            accel_mps2: Vector3::new(ax, ay, az),
        });
    }
    if imu_dropped > 0 {
        notes.push(format!(
            "IMU: {imu_dropped} rows dropped (time not after the previous)"
        ));
    }

    // GNSS
    let acc = accuracies(&log);
    let gnss: Vec<GnssFix> = kept
        .iter()
        .map(|g| {
            let (sh, sv, ss) = match nearest(&acc, g.boot_us) {
                Some((h, v, s)) => (h.max(0.3), v.max(0.5), s.max(0.1)),
                None => (1.5 * g.hdop, 2.5 * g.hdop, 0.5),
            };
            let velocity = match (g.spd, g.gcrs) {
                (Some(spd), Some(crs)) => Some(GnssVelocity {
                    north_mps: spd * crs.to_radians().cos(),
                    east_mps: spd * crs.to_radians().sin(),
                    down_mps: g.vz,
                    sigma_mps: ss,
                }),
                _ => None,
            };
            GnssFix {
                t_ns: t_ns(g.boot_us),
                lat_deg: g.lat,
                lon_deg: g.lon,
                alt_m: g.alt_msl + egm96_undulation_m(g.lat, g.lon),
                velocity,
                sigma_h_m: sh,
                sigma_v_m: sv,
                fix_type: fix_type(g.status),
                num_sats: g.nsats as u32,
            }
        })
        .collect();

    // MAG (milligauss → tesla), BARO
    let mut mag: Vec<MagSample> = Vec::new();
    if let Some(t) = log.table("MAG") {
        for r in t.rows.iter().filter(|r| first_instance(t, r, "I")) {
            if let (Some(tu), Some(x), Some(y), Some(z)) = (
                boot_us(t, r),
                t.num(r, "MagX"),
                t.num(r, "MagY"),
                t.num(r, "MagZ"),
            ) {
                mag.push(MagSample {
                    t_ns: t_ns(tu),
                    field_t: Vector3::new(x, y, z) * 1e-7,
                });
            }
        }
        if mag.len() > 1 && mag.iter().all(|m| m.field_t == mag[0].field_t) {
            notes.push(format!(
                "MAG: all {} rows read the same value (dead compass): none kept",
                mag.len()
            ));
            mag.clear();
        }
    }
    let mut baro: Vec<BaroSample> = Vec::new();
    if let Some(t) = log.table("BARO") {
        for r in t.rows.iter().filter(|r| first_instance(t, r, "I")) {
            if let (Some(tu), Some(p)) = (boot_us(t, r), t.num(r, "Press")) {
                baro.push(BaroSample {
                    t_ns: t_ns(tu),
                    pressure_pa: p,
                    temperature_degc: t.num(r, "Temp"),
                });
            }
        }
    }

    let (reference_name, reference) = reference(&log, &t_ns);
    let reference_origin = reference_name
        .as_deref()
        .and_then(|name| origin(&log, name, &mut notes));
    let attitude_flown = log
        .table("ATT")
        .map(|t| {
            t.rows
                .iter()
                .filter_map(|r| {
                    Some(AttitudeSample {
                        t_ns: t_ns(boot_us(t, r)?),
                        nav_from_body: euler_deg(
                            t.num(r, "Roll")?,
                            t.num(r, "Pitch")?,
                            t.num(r, "Yaw")?,
                        ),
                    })
                })
                .collect()
        })
        .unwrap_or_default();

    let gnss_delay_s = match opts.gnss_delay_s {
        Some(d) => d,
        None => match ["EK3_GPS_DELAY", "EK2_GPS_DELAY", "EKF_POS_DELAY"]
            .iter()
            .find_map(|p| params.get(*p))
        {
            Some(ms) => ms * 1e-3,
            None => {
                notes.push("no GPS delay parameter: ArduPilot's default 220 ms assumed".into());
                0.22
            }
        },
    };
    let mut config = config(&params, &imu, &gnss, &mag, &baro, gnss_delay_s);
    crate::trim::apply(&params, &mut imu, &mut config, &mut notes);

    Ok(FlightLog {
        source: LogKind::ArduPilot,
        vehicle,
        firmware,
        time_base,
        time_offset_ns: offset_ns,
        imu,
        gnss,
        mag,
        baro,
        reference,
        reference_name,
        reference_origin,
        attitude_flown,
        params,
        gnss_delay_s,
        config,
        message_counts: log.counts.clone(),
        notes,
    })
}

fn euler_deg(roll: f64, pitch: f64, yaw: f64) -> nalgebra::UnitQuaternion<f64> {
    from_euler_zyx(roll.to_radians(), pitch.to_radians(), yaw.to_radians())
}

/// Firmware string and vehicle kind from the `MSG` text the autopilot writes at start.
fn firmware(log: &DfLog) -> (Option<String>, VehicleKind) {
    let Some(t) = log.table("MSG") else {
        return (None, VehicleKind::Unknown);
    };
    for r in &t.rows {
        let Some(m) = t.text(r, "Message") else {
            continue;
        };
        let kind = if m.starts_with("ArduCopter") || m.starts_with("ArduHeli") {
            VehicleKind::Copter
        } else if m.starts_with("ArduPlane") {
            VehicleKind::Plane
        } else if m.starts_with("ArduRover") {
            VehicleKind::Rover
        } else if m.starts_with("ArduSub") {
            VehicleKind::Sub
        } else {
            continue;
        };
        return (Some(m.to_string()), kind);
    }
    (None, VehicleKind::Unknown)
}

/// The EKF's estimate: `XKF1`/`NKF1` core 0, else `EKF1`.
fn reference(log: &DfLog, t_ns: &dyn Fn(i64) -> i64) -> (Option<String>, Vec<TruthSample>) {
    let Some((name, t)) = ["XKF1", "NKF1", "EKF1"]
        .iter()
        .find_map(|n| log.table(n).map(|t| (n.to_string(), t)))
    else {
        return (None, Vec::new());
    };
    let mut out: Vec<TruthSample> = Vec::new();
    for r in t.rows.iter().filter(|r| first_instance(t, r, "C")) {
        let vals =
            ["Roll", "Pitch", "Yaw", "VN", "VE", "VD", "PN", "PE", "PD"].map(|l| t.num(r, l));
        let (
            Some(tu),
            [
                Some(ro),
                Some(pi),
                Some(ya),
                Some(vn),
                Some(ve),
                Some(vd),
                Some(pn),
                Some(pe),
                Some(pd),
            ],
        ) = (boot_us(t, r), vals)
        else {
            continue;
        };
        // before its initialisation the EKF logs zeros
        if out.is_empty() && [vn, ve, vd, pn, pe, pd].iter().all(|v| *v == 0.0) {
            continue;
        }
        let tn = t_ns(tu);
        if out.last().is_some_and(|p| tn <= p.t_ns) {
            continue;
        }
        out.push(TruthSample {
            t_ns: tn,
            pos_ned_m: Vector3::new(pn, pe, pd),
            nav_from_body: euler_deg(ro, pi, ya),
            vel_ned_mps: Vector3::new(vn, ve, vd),
            gyro_bias_radps: Vector3::zeros(),
            accel_bias_mps2: Vector3::zeros(),
        });
    }
    (Some(name), out)
}

/// The origin of the reference's NED frame, altitude above the ellipsoid.
fn origin(log: &DfLog, reference: &str, notes: &mut Vec<String>) -> Option<Lla> {
    let with_geoid =
        |lat: f64, lon: f64, msl: f64| Lla::from_deg(lat, lon, msl + egm96_undulation_m(lat, lon));
    if let Some(t) = log.table("ORGN") {
        let row = t
            .rows
            .iter()
            .find(|r| t.num(r, "Type").is_none_or(|ty| ty == 0.0))?;
        return Some(with_geoid(
            t.num(row, "Lat")?,
            t.num(row, "Lng")?,
            t.num(row, "Alt")?,
        ));
    }
    // AHR2 (the EKF's position when it runs) minus the reference's NED position at the same stamp.
    let (ahr, ekf) = (log.table("AHR2")?, log.table(reference)?);
    let mut ned: BTreeMap<i64, [f64; 3]> = BTreeMap::new();
    for r in ekf.rows.iter().filter(|r| first_instance(ekf, r, "C")) {
        if let (Some(tu), Some(n), Some(e), Some(d)) = (
            boot_us(ekf, r),
            ekf.num(r, "PN"),
            ekf.num(r, "PE"),
            ekf.num(r, "PD"),
        ) && [n, e, d].iter().any(|v| *v != 0.0)
        {
            ned.entry(tu).or_insert([n, e, d]);
        }
    }
    let (mut lats, mut lons, mut alts) = (Vec::new(), Vec::new(), Vec::new());
    for r in &ahr.rows {
        let (Some(tu), Some(lat), Some(lon), Some(alt)) = (
            boot_us(ahr, r),
            ahr.num(r, "Lat"),
            ahr.num(r, "Lng"),
            ahr.num(r, "Alt"),
        ) else {
            continue;
        };
        let Some([n, e, d]) = ned.get(&tu) else {
            continue;
        };
        let phi = lat.to_radians();
        lats.push(lat - (n / (radius_meridian(phi) + alt)).to_degrees());
        lons.push(lon - (e / ((radius_prime_vertical(phi) + alt) * phi.cos())).to_degrees());
        alts.push(alt + d);
    }
    let o = (
        crate::median(&lats)?,
        crate::median(&lons)?,
        crate::median(&alts)?,
    );
    notes.push(format!(
        "reference origin: median of AHR2 − {reference} position over {} rows",
        lats.len()
    ));
    Some(with_geoid(o.0, o.1, o.2))
}

/// The suggested configuration. IMU noise densities from the EKF's process noise: the EKF adds
/// `(PNOISE·dt)²` per step to an angle (velocity) increment, which is a white rate (acceleration)
/// noise of density `PNOISE·√dt`.
fn config(
    params: &BTreeMap<String, f64>,
    imu: &[ImuSample],
    gnss: &[GnssFix],
    mag: &[MagSample],
    baro: &[BaroSample],
    delay_s: f64,
) -> VehicleConfig {
    let rate_hz = crate::median_dt_s(imu.iter().map(|s| s.t_ns)).map_or(50.0, |dt| 1.0 / dt);
    let param = |names: &[&str]| names.iter().find_map(|n| params.get(*n).copied());
    let gyro_pn = param(&["EK3_GYRO_P_NSE", "EK2_GYRO_PNOISE", "EKF_GYRO_PNOISE"]).unwrap_or(0.015);
    let acc_pn = param(&["EK3_ACC_P_NSE", "EK2_ACC_PNOISE", "EKF_ACC_PNOISE"]).unwrap_or(0.25);
    let imu_cfg = ImuConfig {
        rate_hz,
        gyro_noise_density: gyro_pn / rate_hz.sqrt(),
        // in-flight MEMS bias walks (the EKF's own bias noises are tuned for its state, not the
        // sensor)
        gyro_random_walk: 4e-5,
        accel_noise_density: acc_pn / rate_hz.sqrt(),
        accel_random_walk: 1e-3,
        // Not in the log (ArduPilot calibrates the gyros at boot): the estimator's default.
        gyro_bias_sigma_radps: 0.0,
        accel_bias_sigma_mps2: 0.0,
    };
    VehicleConfig {
        imu: imu_cfg,
        ..crate::sensor_configs(gnss, mag, baro, delay_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leap_seconds_by_date() {
        let gps = |y, m, d| days_from_civil(y, m, d) * 86_400;
        assert_eq!(days_from_civil(1980, 1, 6) * 86_400, GPS_EPOCH_UNIX_S);
        assert_eq!(gps_leap_seconds(gps(1980, 6, 1)), 0);
        assert_eq!(gps_leap_seconds(gps(2014, 12, 5)), 16);
        assert_eq!(gps_leap_seconds(gps(2016, 6, 1)), 17);
        assert_eq!(gps_leap_seconds(gps(2024, 1, 1)), 18);
        // 2017-01-01T00:00:00 UTC is GPS 2017-01-01T00:00:18
        assert_eq!(gps_leap_seconds(gps(2017, 1, 1) + 17), 17);
        assert_eq!(gps_leap_seconds(gps(2017, 1, 1) + 18), 18);
    }

    #[test]
    fn nearest_accuracy_within_window() {
        let acc = [(1_000_000, 1.0, 2.0, 0.2), (1_200_000, 3.0, 4.0, 0.4)];
        assert_eq!(nearest(&acc, 1_090_000), Some((1.0, 2.0, 0.2)));
        assert_eq!(nearest(&acc, 1_110_000), Some((3.0, 4.0, 0.4)));
        assert_eq!(nearest(&acc, 1_100_000), Some((1.0, 2.0, 0.2)));
        let dup = [(1_000_000, 1.0, 2.0, 0.2), (1_000_000, 3.0, 4.0, 0.4)];
        assert_eq!(nearest(&dup, 1_000_000), Some((3.0, 4.0, 0.4)));
        assert_eq!(nearest(&acc, 1_400_000), None);
    }
}
