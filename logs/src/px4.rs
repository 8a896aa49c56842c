//! PX4 ULog topics → [`FlightLog`].
//!
//! * **IMU**: `sensor_combined` `gyro_rad[3]`, `accelerometer_m_s2[3]` (FRD) at `timestamp`.
//!   PX4 writes it after its board rotation (`SENS_BOARD_ROT` and the level offsets
//!   `SENS_BOARD_X/Y/Z_OFF`), so it is already in the vehicle frame its attitude refers to: no
//!   trim to apply, unlike ArduPilot's `AHRS_TRIM` ([`crate::trim`]).
//! * **GNSS**: `vehicle_gps_position` or `sensor_gps`, old layout (`lat`/`lon` 1e-7°, `alt`/
//!   `alt_ellipsoid` mm) or new (`latitude_deg`, `altitude_msl_m`, `altitude_ellipsoid_m`), fixes
//!   with `fix_type` ≥ 3 and enough satellites; altitude: the ellipsoidal one when given, else MSL
//!   + EGM96 `N`; sigmas `eph`, `epv`, `s_variance_m_s` (a standard deviation despite the name).
//! * **MAG**: `vehicle_magnetometer` (calibrated, body frame) else `sensor_mag` (raw, sensor
//!   frame: noted), gauss × 1e-4 T.
//! * **BARO**: `sensor_baro` `pressure` (Pa; hPa in old firmware, detected), else
//!   `vehicle_air_data` `baro_pressure_pa`.
//! * **Reference**: `vehicle_local_position` (NED at `ref_lat/ref_lon/ref_alt`, MSL + `N`) with
//!   the latest `vehicle_attitude` `q` at each sample.
//! * **Time**: UNIX from the GNSS `time_utc_usec` (median of `time_utc_usec − timestamp`, µs), else
//!   boot time.

use std::collections::BTreeMap;

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use uavnav_core::geoid::egm96_undulation_m;
use uavnav_core::{ImuSample, Lla, TruthSample};

use crate::ulog::{self, Topic};
use crate::{FlightLog, ImportOptions, LogError, LogKind, VehicleKind, fix_type};
use uavnav_core::{BaroSample, GnssFix, GnssVelocity, MagSample};

fn vec3(t: &Topic, r: &[u8], name: &str) -> Option<Vector3<f64>> {
    Some(Vector3::new(
        t.get(r, &format!("{name}[0]"))?,
        t.get(r, &format!("{name}[1]"))?,
        t.get(r, &format!("{name}[2]"))?,
    ))
}

pub(crate) fn import(data: &[u8], opts: &ImportOptions) -> Result<FlightLog, LogError> {
    let log = ulog::parse(data, opts.stop_at_damage)?;
    let mut notes = Vec::new();
    if let Some(e) = &log.damage {
        notes.push(crate::damage_note(e));
    }
    let mut message_counts = BTreeMap::new();
    for t in &log.topics {
        let key = if t.multi_id == 0 {
            t.name.clone()
        } else {
            format!("{}[{}]", t.name, t.multi_id)
        };
        *message_counts.entry(key).or_default() += t.rows.len();
    }

    let gps = log
        .topic("vehicle_gps_position")
        .or_else(|| log.topic("sensor_gps"));
    // UNIX time from the receiver's UTC
    let diffs: Vec<f64> = gps
        .map(|t| {
            t.rows
                .iter()
                .filter_map(|r| {
                    let utc = t.get(r, "time_utc_usec")?;
                    (utc > 0.0).then(|| utc - t.get(r, "timestamp").unwrap_or(f64::NAN))
                })
                .collect()
        })
        .unwrap_or_default();
    let (time_base, offset_ns) = crate::time_base(&diffs, "GNSS UTC time", &mut notes);
    // Saturating: a corrupt stamp must give an absurd time that later checks refuse, not a panic.
    let t_ns = |us: f64| (us as i64).saturating_mul(1000).saturating_add(offset_ns);

    let sc = log
        .topic("sensor_combined")
        .ok_or_else(|| LogError::Unusable("no sensor_combined messages".into()))?;
    let mut imu: Vec<ImuSample> = Vec::new();
    for r in &sc.rows {
        let (Some(ts), Some(g), Some(a)) = (
            sc.get(r, "timestamp"),
            vec3(sc, r, "gyro_rad"),
            vec3(sc, r, "accelerometer_m_s2"),
        ) else {
            continue;
        };
        if imu.last().is_some_and(|p| t_ns(ts) <= p.t_ns) {
            continue;
        }
        imu.push(ImuSample {
            t_ns: t_ns(ts),
            gyro_radps: g,
            accel_mps2: a,
        });
    }

    let mut gnss = Vec::new();
    if let Some(t) = gps {
        let new = t.layout.has("latitude_deg");
        for r in &t.rows {
            let fix = t.get(r, "fix_type").unwrap_or(0.0);
            let sats = t.get(r, "satellites_used").unwrap_or(0.0);
            if fix < 3.0 || sats < f64::from(opts.min_sats) {
                continue;
            }
            let (lat, lon, msl, ell) = if new {
                (
                    t.get(r, "latitude_deg"),
                    t.get(r, "longitude_deg"),
                    t.get(r, "altitude_msl_m"),
                    t.get(r, "altitude_ellipsoid_m"),
                )
            } else {
                (
                    t.get(r, "lat").map(|v| v * 1e-7),
                    t.get(r, "lon").map(|v| v * 1e-7),
                    t.get(r, "alt").map(|v| v * 1e-3),
                    t.get(r, "alt_ellipsoid").map(|v| v * 1e-3),
                )
            };
            let (Some(ts), Some(lat), Some(lon), Some(msl)) =
                (t.get(r, "timestamp"), lat, lon, msl)
            else {
                continue;
            };
            let alt_m = match ell {
                Some(h) if h != 0.0 => h,
                _ => msl + egm96_undulation_m(lat, lon),
            };
            let velocity = match (
                t.get(r, "vel_n_m_s"),
                t.get(r, "vel_e_m_s"),
                t.get(r, "vel_ned_valid"),
            ) {
                (Some(n), Some(e), valid) if valid != Some(0.0) => Some(GnssVelocity {
                    north_mps: n,
                    east_mps: e,
                    down_mps: t.get(r, "vel_d_m_s"),
                    sigma_mps: t.get(r, "s_variance_m_s").unwrap_or(0.5).max(0.1),
                }),
                _ => None,
            };
            gnss.push(GnssFix {
                t_ns: t_ns(ts),
                lat_deg: lat,
                lon_deg: lon,
                alt_m,
                velocity,
                sigma_h_m: t.get(r, "eph").unwrap_or(2.5).max(0.3),
                sigma_v_m: t.get(r, "epv").unwrap_or(4.0).max(0.5),
                fix_type: fix_type(fix),
                num_sats: sats as u32,
            });
        }
        if gnss.len() < t.rows.len() {
            notes.push(format!(
                "{}: {} of {} messages dropped (fix_type < 3 or fewer than {} satellites)",
                t.name,
                t.rows.len() - gnss.len(),
                t.rows.len(),
                opts.min_sats
            ));
        }
    }

    let mut mag = Vec::new();
    let mag_topic = match log.topic("vehicle_magnetometer") {
        Some(t) => Some((t, "magnetometer_ga")),
        None => log.topic("sensor_mag").map(|t| {
            notes.push("MAG from sensor_mag: raw sensor frame, not calibrated".into());
            (t, "")
        }),
    };
    if let Some((t, field)) = mag_topic {
        for r in &t.rows {
            let v = if field.is_empty() {
                Some(Vector3::new(t.get(r, "x"), t.get(r, "y"), t.get(r, "z")))
                    .and_then(|v| Some(Vector3::new(v.x?, v.y?, v.z?)))
            } else {
                vec3(t, r, field)
            };
            if let (Some(ts), Some(v)) = (t.get(r, "timestamp"), v) {
                mag.push(MagSample {
                    t_ns: t_ns(ts),
                    field_t: v * 1e-4,
                });
            }
        }
    }

    let mut baro = Vec::new();
    if let Some(t) = log.topic("sensor_baro") {
        let p: Vec<f64> = t.rows.iter().filter_map(|r| t.get(r, "pressure")).collect();
        // PX4 before 1.13 logged hPa
        let scale = if crate::median(&p).is_some_and(|m| m < 2000.0) {
            100.0
        } else {
            1.0
        };
        for r in &t.rows {
            if let (Some(ts), Some(p)) = (t.get(r, "timestamp"), t.get(r, "pressure")) {
                baro.push(BaroSample {
                    t_ns: t_ns(ts),
                    pressure_pa: p * scale,
                    temperature_degc: t.get(r, "temperature"),
                });
            }
        }
    } else if let Some(t) = log.topic("vehicle_air_data") {
        for r in &t.rows {
            if let (Some(ts), Some(p)) = (t.get(r, "timestamp"), t.get(r, "baro_pressure_pa")) {
                baro.push(BaroSample {
                    t_ns: t_ns(ts),
                    pressure_pa: p,
                    temperature_degc: t.get(r, "baro_temp_celcius"),
                });
            }
        }
    }

    let (reference, reference_origin) = reference(&log, &t_ns);
    let params = log.params.clone();
    let gnss_delay_s = match opts.gnss_delay_s {
        Some(d) => d,
        None => match params.get("EKF2_GPS_DELAY") {
            Some(ms) => ms * 1e-3,
            None => {
                notes.push("no EKF2_GPS_DELAY: PX4's default 110 ms assumed".into());
                0.11
            }
        },
    };
    let vehicle = params.get("MAV_TYPE").map_or(VehicleKind::Unknown, |v| {
        VehicleKind::from_mav_type(*v as i64)
    });
    let firmware = log
        .info
        .get("ver_sw_release")
        .map(|v| format!("PX4 ver_sw_release {v}"))
        .or_else(|| log.info.get("ver_sw").map(|v| format!("PX4 {v}")));
    let config = crate::mems_config(&imu, 250.0, &gnss, &mag, &baro, gnss_delay_s);

    Ok(FlightLog {
        source: LogKind::Px4,
        vehicle,
        firmware,
        time_base,
        time_offset_ns: offset_ns,
        imu,
        gnss,
        mag,
        baro,
        reference_name: (!reference.is_empty()).then(|| "vehicle_local_position".to_string()),
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

/// `vehicle_local_position` with the latest `vehicle_attitude` at each sample.
fn reference(log: &ulog::ULog, t_ns: &dyn Fn(f64) -> i64) -> (Vec<TruthSample>, Option<Lla>) {
    let (Some(lp), Some(att)) = (
        log.topic("vehicle_local_position"),
        log.topic("vehicle_attitude"),
    ) else {
        return (Vec::new(), None);
    };
    let quats: Vec<(f64, UnitQuaternion<f64>)> = att
        .rows
        .iter()
        .filter_map(|r| {
            let q = Quaternion::new(
                att.get(r, "q[0]")?,
                att.get(r, "q[1]")?,
                att.get(r, "q[2]")?,
                att.get(r, "q[3]")?,
            );
            (q.norm() > 0.5).then(|| {
                (
                    att.get(r, "timestamp").unwrap_or(0.0),
                    UnitQuaternion::from_quaternion(q),
                )
            })
        })
        .collect();
    let mut origin = None;
    let mut out: Vec<TruthSample> = Vec::new();
    for r in &lp.rows {
        let vals = ["timestamp", "x", "y", "z", "vx", "vy", "vz"].map(|f| lp.get(r, f));
        let [
            Some(ts),
            Some(x),
            Some(y),
            Some(z),
            Some(vx),
            Some(vy),
            Some(vz),
        ] = vals
        else {
            continue;
        };
        let i = quats.partition_point(|q| q.0 <= ts);
        let Some(q) = i.checked_sub(1).and_then(|j| quats.get(j)) else {
            continue;
        };
        if origin.is_none() && lp.get(r, "xy_global") == Some(1.0) {
            origin = match (
                lp.get(r, "ref_lat"),
                lp.get(r, "ref_lon"),
                lp.get(r, "ref_alt"),
            ) {
                (Some(la), Some(lo), Some(al)) => {
                    Some(Lla::from_deg(la, lo, al + egm96_undulation_m(la, lo)))
                }
                _ => None,
            };
        }
        if out.last().is_some_and(|p| t_ns(ts) <= p.t_ns) {
            continue;
        }
        out.push(TruthSample {
            t_ns: t_ns(ts),
            pos_ned_m: Vector3::new(x, y, z),
            nav_from_body: q.1,
            vel_ned_mps: Vector3::new(vx, vy, vz),
            gyro_bias_radps: Vector3::zeros(),
            accel_bias_mps2: Vector3::zeros(),
        });
    }
    (out, origin)
}
