//! Input validation: every sample is checked before it can touch the filter, so a rejected input
//! leaves the state exactly as it was.

use uavnav_core::{BaroSample, Egomotion, FixType, GnssFix, ImuSample, MagSample};

use crate::params::EstimatorParams;

/// Why an input was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    /// A NaN or infinite value.
    #[error("{what} is not finite")]
    NonFinite {
        /// Which field.
        what: &'static str,
    },
    /// Older than the previous input of the same stream.
    #[error("time goes backwards: {t_ns} ns after {last_t_ns} ns")]
    TimeBackwards {
        /// The input's time.
        t_ns: i64,
        /// The previous input's time.
        last_t_ns: i64,
    },
    /// Same time as the previous input of the same stream.
    #[error("duplicate sample at {t_ns} ns")]
    Duplicate {
        /// The repeated time.
        t_ns: i64,
    },
    /// A gap larger than allowed since the previous input.
    #[error("time jump of {gap_ns} ns exceeds {max_ns} ns")]
    TimeJump {
        /// The gap.
        gap_ns: i64,
        /// The limit.
        max_ns: i64,
    },
    /// A physically absurd value.
    #[error("{what} = {value} is out of range")]
    Absurd {
        /// Which field.
        what: &'static str,
        /// Its value.
        value: f64,
    },
    /// A measurement too old to be fused (behind the newest IMU sample by more than allowed).
    #[error("measurement at {t_ns} ns is too old (newest IMU {newest_ns} ns)")]
    TooOld {
        /// Its time.
        t_ns: i64,
        /// The newest IMU time.
        newest_ns: i64,
    },
    /// A GNSS fix without a position solution.
    #[error("GNSS fix has no position (fix type None)")]
    NoFix,
    /// A vision measurement for a vehicle configured without a camera.
    #[error("vehicle has no camera configured")]
    NoCamera,
}

fn finite3(v: &nalgebra::Vector3<f64>, what: &'static str) -> Result<(), InputError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(InputError::NonFinite { what })
    }
}

fn finite(x: f64, what: &'static str) -> Result<(), InputError> {
    if x.is_finite() {
        Ok(())
    } else {
        Err(InputError::NonFinite { what })
    }
}

/// Largest magnetic flux density accepted, T: the Earth's field is 22–67 µT; a reading of a
/// millitesla is a saturated or broken sensor, not a field to fuse.
pub const MAX_MAG_FIELD_T: f64 = 1.0e-3;

/// Checks one magnetometer sample against the previous accepted sample time.
pub fn check_mag(s: &MagSample, last_t_ns: Option<i64>) -> Result<(), InputError> {
    finite3(&s.field_t, "magnetic field")?;
    if s.field_t.norm() > MAX_MAG_FIELD_T {
        return Err(InputError::Absurd {
            what: "|magnetic field| T",
            value: s.field_t.norm(),
        });
    }
    if let Some(last) = last_t_ns {
        check_order(s.t_ns, last)?;
    }
    Ok(())
}

/// Accepted static pressure range, Pa: from ~30 km altitude (1.2 kPa) to below the Dead Sea
/// (~107 kPa) with margin.
pub const PRESSURE_RANGE_PA: std::ops::RangeInclusive<f64> = 500.0..=120_000.0;

/// Checks one barometer sample against the previous accepted sample time.
pub fn check_baro(s: &BaroSample, last_t_ns: Option<i64>) -> Result<(), InputError> {
    finite(s.pressure_pa, "pressure")?;
    if let Some(t) = s.temperature_degc {
        finite(t, "baro temperature")?;
        if !(-90.0..=150.0).contains(&t) {
            return Err(InputError::Absurd {
                what: "baro temperature degC",
                value: t,
            });
        }
    }
    if !PRESSURE_RANGE_PA.contains(&s.pressure_pa) {
        return Err(InputError::Absurd {
            what: "pressure Pa",
            value: s.pressure_pa,
        });
    }
    if let Some(last) = last_t_ns {
        check_order(s.t_ns, last)?;
    }
    Ok(())
}

/// Checks one IMU sample against the previous accepted sample time.
pub fn check_imu(
    s: &ImuSample,
    last_t_ns: Option<i64>,
    p: &EstimatorParams,
) -> Result<(), InputError> {
    finite3(&s.gyro_radps, "gyro")?;
    finite3(&s.accel_mps2, "accel")?;
    if s.gyro_radps.norm() > p.max_gyro_radps {
        return Err(InputError::Absurd {
            what: "|gyro| rad/s",
            value: s.gyro_radps.norm(),
        });
    }
    if s.accel_mps2.norm() > p.max_accel_mps2 {
        return Err(InputError::Absurd {
            what: "|accel| m/s²",
            value: s.accel_mps2.norm(),
        });
    }
    if let Some(last) = last_t_ns {
        check_order(s.t_ns, last)?;
        if s.t_ns - last > p.max_imu_gap_ns {
            return Err(InputError::TimeJump {
                gap_ns: s.t_ns - last,
                max_ns: p.max_imu_gap_ns,
            });
        }
    }
    Ok(())
}

fn check_order(t_ns: i64, last_t_ns: i64) -> Result<(), InputError> {
    if t_ns == last_t_ns {
        return Err(InputError::Duplicate { t_ns });
    }
    if t_ns < last_t_ns {
        return Err(InputError::TimeBackwards { t_ns, last_t_ns });
    }
    Ok(())
}

fn check_age(t_ns: i64, newest_imu_ns: Option<i64>, p: &EstimatorParams) -> Result<(), InputError> {
    if let Some(n) = newest_imu_ns
        && n - t_ns > p.max_measurement_age_ns
    {
        return Err(InputError::TooOld { t_ns, newest_ns: n });
    }
    Ok(())
}

/// Checks a GNSS fix.
pub fn check_gnss(
    f: &GnssFix,
    last_t_ns: Option<i64>,
    newest_imu_ns: Option<i64>,
    p: &EstimatorParams,
) -> Result<(), InputError> {
    finite(f.lat_deg, "latitude")?;
    finite(f.lon_deg, "longitude")?;
    finite(f.alt_m, "altitude")?;
    if let Some(v) = &f.velocity {
        finite(v.north_mps, "GNSS velocity north")?;
        finite(v.east_mps, "GNSS velocity east")?;
        if let Some(d) = v.down_mps {
            finite(d, "GNSS velocity down")?;
        }
        finite(v.sigma_mps, "sigma_vel")?;
    }
    finite(f.sigma_h_m, "sigma_h")?;
    finite(f.sigma_v_m, "sigma_v")?;
    if f.fix_type == FixType::None {
        return Err(InputError::NoFix);
    }
    if f.lat_deg.abs() > 90.0 {
        return Err(InputError::Absurd {
            what: "latitude deg",
            value: f.lat_deg,
        });
    }
    if f.lon_deg.abs() > 180.0 {
        return Err(InputError::Absurd {
            what: "longitude deg",
            value: f.lon_deg,
        });
    }
    if !(-1_000.0..=100_000.0).contains(&f.alt_m) {
        return Err(InputError::Absurd {
            what: "altitude m",
            value: f.alt_m,
        });
    }
    if let Some(v) = &f.velocity {
        let speed = v.horizontal_mps().norm().hypot(v.down_mps.unwrap_or(0.0));
        if speed > 600.0 {
            return Err(InputError::Absurd {
                what: "|GNSS velocity| m/s",
                value: speed,
            });
        }
    }
    let sigma_vel = f.velocity.map(|v| ("sigma_vel m/s", v.sigma_mps));
    for (what, s) in [("sigma_h m", f.sigma_h_m), ("sigma_v m", f.sigma_v_m)]
        .into_iter()
        .chain(sigma_vel)
    {
        if s <= 0.0 || s > 1e4 {
            return Err(InputError::Absurd { what, value: s });
        }
    }
    if let Some(last) = last_t_ns {
        check_order(f.t_ns, last)?;
    }
    check_age(f.t_ns, newest_imu_ns, p)
}

/// Checks a vision egomotion.
pub fn check_egomotion(
    m: &Egomotion,
    last_t1_ns: Option<i64>,
    newest_imu_ns: Option<i64>,
    p: &EstimatorParams,
) -> Result<(), InputError> {
    if !m.cam1_from_cam0.coords.iter().all(|x| x.is_finite()) {
        return Err(InputError::NonFinite {
            what: "egomotion rotation",
        });
    }
    if let Some(d) = m.t_dir_cam1 {
        finite3(&d, "egomotion direction")?;
    }
    if let Some(t) = m.t_cam1_m {
        finite3(&t, "egomotion translation")?;
    }
    if let Some(d) = m.scale_distance_m
        && !(d.is_finite() && d > 0.0)
    {
        return Err(InputError::Absurd {
            what: "egomotion scale distance m",
            value: d,
        });
    }
    if !m
        .rot_cov
        .iter()
        .chain(m.t_cov.iter())
        .all(|x| x.is_finite())
    {
        return Err(InputError::NonFinite {
            what: "egomotion covariance",
        });
    }
    if (0..3).any(|k| m.rot_cov[(k, k)] <= 0.0) {
        return Err(InputError::Absurd {
            what: "egomotion rotation variance",
            value: m.rot_cov.diagonal().min(),
        });
    }
    if m.t1_ns <= m.t0_ns || m.t1_ns - m.t0_ns > 2_000_000_000 {
        return Err(InputError::Absurd {
            what: "egomotion frame interval s",
            value: (m.t1_ns - m.t0_ns) as f64 * 1e-9,
        });
    }
    if last_t1_ns == Some(m.t1_ns) {
        return Err(InputError::Duplicate { t_ns: m.t1_ns });
    }
    check_age(m.t1_ns, newest_imu_ns, p)
}
