//! Real-flight support: a minimal reader of the shared ASL folders (`../shared/data/real_flights`)
//! and the scoring the estimator issue states (attitude against the autopilot's reference,
//! horizontal position against the raw fixes, yaw consistency, σ sanity). Tests only; the
//! product's reader is `uavnav-dataset`, which this pure crate does not depend on.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use nalgebra::{UnitQuaternion, Vector3};
use uavnav_core::{
    BaroConfig, BaroSample, FilterProfile, FixType, GnssConfig, GnssFix, GnssVelocity, ImuSample,
    Lla, LocalFrame, MagConfig, MagSample, VehicleConfig,
};
use uavnav_estimator::{Estimator, EstimatorParams, Health, PoseOutput};

/// The shared real flight `name`, or `None` (with a message) when `../shared` is absent.
pub fn flight_dir(name: &str) -> Option<PathBuf> {
    uavnav_testdata::shared_data(&format!("real_flights/{name}"))
        .filter(|d| d.join("mav0").is_dir())
}

fn rows(path: &Path) -> Vec<Vec<Option<f64>>> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Vec::new();
    };
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| l.split(',').map(|c| c.trim().parse::<f64>().ok()).collect())
        .collect()
}

fn stamp(path: &Path) -> Vec<i64> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Vec::new();
    };
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .filter_map(|l| l.split(',').next()?.trim().parse::<i64>().ok())
        .collect()
}

fn yaml_number(path: &Path, key: &str) -> Option<f64> {
    let text = std::fs::read_to_string(path).ok()?;
    let line = text.lines().find(|l| l.starts_with(key))?;
    let v = line.split_once(':')?.1.split('#').next()?.trim();
    v.trim_start_matches('[')
        .split(',')
        .next()?
        .trim()
        .trim_end_matches(']')
        .parse()
        .ok()
}

/// One reference sample (the autopilot's estimate).
#[derive(Debug, Clone, Copy)]
pub struct Reference {
    pub t_ns: i64,
    pub q: UnitQuaternion<f64>,
}

/// A real flight, read.
#[derive(Debug, Clone)]
pub struct RealFlight {
    pub config: VehicleConfig,
    pub imu: Vec<ImuSample>,
    pub gnss: Vec<GnssFix>,
    pub mag: Vec<MagSample>,
    pub baro: Vec<BaroSample>,
    pub reference: Vec<Reference>,
}

impl RealFlight {
    /// Reads `mav0/` of a shared flight.
    pub fn read(dir: &Path) -> Self {
        let m = dir.join("mav0");
        let y = |s: &str, k: &str| yaml_number(&m.join(s).join("sensor.yaml"), k);
        let mut config = VehicleConfig::default();
        config.imu.rate_hz = y("imu0", "rate_hz").unwrap_or(50.0);
        config.imu.gyro_noise_density = y("imu0", "gyroscope_noise_density").unwrap_or(1e-3);
        config.imu.gyro_random_walk = y("imu0", "gyroscope_random_walk").unwrap_or(1e-5);
        config.imu.accel_noise_density = y("imu0", "accelerometer_noise_density").unwrap_or(1e-2);
        config.imu.accel_random_walk = y("imu0", "accelerometer_random_walk").unwrap_or(1e-3);
        config.gnss = Some(GnssConfig {
            rate_hz: y("gnss0", "rate_hz").unwrap_or(5.0),
            // `uavnav convert` keeps a log's fix stamps and states the receiver's delay here (the
            // shared flights have theirs taken off the stamps instead): without it, a converted
            // flight's fixes were fused as valid when they arrived.
            delay_ns: y("gnss0", "delay_s").map_or(0, |d| (d * 1e9).round() as i64),
            ..GnssConfig::default()
        });
        config.camera = None;
        let imu_t = stamp(&m.join("imu0/data.csv"));
        let imu: Vec<ImuSample> = rows(&m.join("imu0/data.csv"))
            .into_iter()
            .zip(imu_t)
            .filter_map(|(r, t)| {
                Some(ImuSample {
                    t_ns: t,
                    gyro_radps: Vector3::new(r[1]?, r[2]?, r[3]?),
                    accel_mps2: Vector3::new(r[4]?, r[5]?, r[6]?),
                })
            })
            .collect();
        let gnss_t = stamp(&m.join("gnss0/data.csv"));
        let gnss = rows(&m.join("gnss0/data.csv"))
            .into_iter()
            .zip(gnss_t)
            .filter_map(|(r, t)| {
                let velocity = match (r.get(4).copied().flatten(), r.get(5).copied().flatten()) {
                    (Some(n), Some(e)) => Some(GnssVelocity {
                        north_mps: n,
                        east_mps: e,
                        down_mps: r.get(6).copied().flatten(),
                        sigma_mps: r.get(9).copied().flatten()?,
                    }),
                    _ => None,
                };
                Some(GnssFix {
                    t_ns: t,
                    lat_deg: r[1]?,
                    lon_deg: r[2]?,
                    alt_m: r[3]?,
                    velocity,
                    sigma_h_m: r[7]?,
                    sigma_v_m: r[8]?,
                    fix_type: FixType::Fix3d,
                    num_sats: 0,
                })
            })
            .collect();
        let mag_path = m.join("mag0/data.csv");
        let mag: Vec<MagSample> = rows(&mag_path)
            .into_iter()
            .zip(stamp(&mag_path))
            .filter_map(|(r, t)| {
                Some(MagSample {
                    t_ns: t,
                    field_t: Vector3::new(r[1]?, r[2]?, r[3]?),
                })
            })
            .collect();
        if !mag.is_empty() {
            config.mag = Some(MagConfig {
                rate_hz: y("mag0", "rate_hz").unwrap_or(10.0),
                sigma_t: y("mag0", "sigma").unwrap_or(1e-7),
                ..MagConfig::default()
            });
        }
        let baro_path = m.join("baro0/data.csv");
        let baro: Vec<BaroSample> = rows(&baro_path)
            .into_iter()
            .zip(stamp(&baro_path))
            .filter_map(|(r, t)| {
                Some(BaroSample {
                    t_ns: t,
                    pressure_pa: r[1]?,
                    temperature_degc: r.get(2).copied().flatten(),
                })
            })
            .collect();
        if !baro.is_empty() {
            config.baro = Some(BaroConfig {
                rate_hz: y("baro0", "rate_hz").unwrap_or(10.0),
                sigma_pressure_pa: y("baro0", "sigma_pressure").unwrap_or(1.0),
            });
        }
        let ref_path = m.join("state_groundtruth_estimate0/data.csv");
        let reference = rows(&ref_path)
            .into_iter()
            .zip(stamp(&ref_path))
            .filter_map(|(r, t)| {
                Some(Reference {
                    t_ns: t,
                    q: UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                        r[4]?, r[5]?, r[6]?, r[7]?,
                    )),
                })
            })
            .collect();
        let mut imu = imu;
        // As `uavnav_dataset::asl::conversion` reads it: an ArduPilot conversion keeps the board
        // frame; the autopilot's attitude (the reference) is the vehicle frame's.
        if let Some(r) = vehicle_from_board(dir) {
            for s in &mut imu {
                *s = uavnav_logs::trim::rotate_imu(&r, s);
            }
            if let Some(m) = config.mag.as_mut() {
                uavnav_logs::trim::rotate_mag_config(&r, m);
            }
        }
        Self {
            config,
            imu,
            gnss,
            mag,
            baro,
            reference,
        }
    }
}

/// `conversion.json`'s ArduPilot trim as `vehicle_from_board` (`None` without it).
fn vehicle_from_board(dir: &Path) -> Option<nalgebra::Rotation3<f64>> {
    let text = std::fs::read_to_string(dir.join("conversion.json")).ok()?;
    let json: serde_json::Value = serde_json::from_str(&text).ok()?;
    let trim = |k: &str| json.get("params")?.get(k)?.as_f64();
    uavnav_logs::trim::vehicle_from_board(trim("AHRS_TRIM_X"), trim("AHRS_TRIM_Y"))
}

/// Which sensors a run uses.
#[derive(Debug, Clone, Copy)]
pub struct Use {
    /// GNSS fed at all (without it the vehicle is configured without a receiver).
    pub gnss: bool,
    pub mag: bool,
    pub baro: bool,
    /// GNSS fixes in `[t0, t1)` are withheld (a simulated outage).
    pub outage_ns: Option<(i64, i64)>,
}

/// Runs the estimator over a real flight (events merged by time, IMU first on ties).
pub fn run(
    f: &RealFlight,
    profile: FilterProfile,
    params: EstimatorParams,
    use_: Use,
) -> Vec<PoseOutput> {
    run_with_health(f, profile, params, use_).0
}

/// [`run`], with the estimator's health at the end.
pub fn run_with_health(
    f: &RealFlight,
    profile: FilterProfile,
    params: EstimatorParams,
    use_: Use,
) -> (Vec<PoseOutput>, Health) {
    let mut config = f.config.clone();
    config.profile = profile;
    if !use_.mag {
        config.mag = None;
    }
    if !use_.baro {
        config.baro = None;
    }
    if !use_.gnss {
        config.gnss = None;
    }
    let mut est = Estimator::new(&config, params, None);
    let mut events: Vec<(i64, u8, usize)> = Vec::new();
    events.extend(f.imu.iter().enumerate().map(|(i, s)| (s.t_ns, 0, i)));
    events.extend(
        f.gnss
            .iter()
            .enumerate()
            .filter(|(_, s)| {
                use_.gnss
                    && use_
                        .outage_ns
                        .is_none_or(|(a, b)| s.t_ns < a || s.t_ns >= b)
            })
            .map(|(i, s)| (s.t_ns, 1, i)),
    );
    if config.mag.is_some() {
        events.extend(f.mag.iter().enumerate().map(|(i, s)| (s.t_ns, 2, i)));
    }
    if config.baro.is_some() {
        events.extend(f.baro.iter().enumerate().map(|(i, s)| (s.t_ns, 3, i)));
    }
    events.sort();
    let mut out = Vec::new();
    for (_, kind, i) in events {
        match kind {
            0 => {
                if let Ok(Some(p)) = est.push_imu(&f.imu[i]) {
                    out.push(p);
                }
            }
            1 => {
                let _ = est.push_gnss(&f.gnss[i]);
            }
            2 => {
                let _ = est.push_mag(&f.mag[i]);
            }
            _ => {
                let _ = est.push_baro(&f.baro[i]);
            }
        }
    }
    (out, est.health())
}

/// Scores of one run.
#[derive(Debug, Clone, Default)]
pub struct Score {
    pub rmse_deg: [f64; 3],
    pub max_yaw_err_deg: f64,
    pub yaw_within_3sigma: f64,
    /// Roll and pitch errors within 3σ.
    pub tilt_within_3sigma: [f64; 2],
    pub horizontal_rmse_m: f64,
    pub bad_sigma_rows: usize,
    pub rows: usize,
    pub gnss_rejected: u64,
    pub longest_rejection_s: f64,
}

fn wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::TAU / 2.0) - std::f64::consts::PI
}

/// Scores poses from `start_ns` (to `end_ns`) against the reference attitude and the raw fixes.
pub fn score(f: &RealFlight, poses: &[PoseOutput], start_ns: i64, end_ns: i64) -> Score {
    let mut s = Score::default();
    let mut sq = [0.0; 3];
    let mut n = 0usize;
    let mut within = 0usize;
    let mut tilt_within = [0usize; 2];
    let mut j = 0usize;
    for p in poses {
        let bad = |v: &Vector3<f64>| v.iter().any(|x| !x.is_finite() || *x <= 0.0 || *x > 1e6);
        // Position and velocity σ only where the mode reports them.
        let pv = p.health.mode.has_position();
        if bad(&p.sigma_att_rad) || (pv && (bad(&p.sigma_pos_ned_m) || bad(&p.sigma_vel_mps))) {
            s.bad_sigma_rows += 1;
        }
        s.rows += 1;
        if p.t_ns < start_ns || p.t_ns > end_ns {
            continue;
        }
        while j + 1 < f.reference.len() && f.reference[j + 1].t_ns <= p.t_ns {
            j += 1;
        }
        let Some(r) = f.reference.get(j) else {
            continue;
        };
        if (r.t_ns - p.t_ns).abs() > 200_000_000 {
            continue;
        }
        let (rr, rp, ry) = r.q.euler_angles();
        let e = [
            wrap(p.euler_rad.x - rr),
            wrap(p.euler_rad.y - rp),
            wrap(p.euler_rad.z - ry),
        ];
        for (acc, e) in sq.iter_mut().zip(e) {
            *acc += e * e;
        }
        s.max_yaw_err_deg = s.max_yaw_err_deg.max(e[2].abs().to_degrees());
        if e[2].abs() <= 3.0 * p.sigma_att_rad.z {
            within += 1;
        }
        for k in 0..2 {
            tilt_within[k] += usize::from(e[k].abs() <= 3.0 * p.sigma_att_rad[k]);
        }
        n += 1;
    }
    if n > 0 {
        for (out, sum) in s.rmse_deg.iter_mut().zip(sq) {
            *out = (sum / n as f64).sqrt().to_degrees();
        }
        s.yaw_within_3sigma = within as f64 / n as f64;
        s.tilt_within_3sigma = tilt_within.map(|w| w as f64 / n as f64);
    }
    // Horizontal against the raw fixes, each at its validity time: the stamp less the receiver's
    // delay (0 for the shared flights, whose stamps have it taken off; a converted log states it,
    // and scoring at the stamp counted 0.22 s of a plane's travel, 3–4 m, as error).
    let delay_ns = f.config.gnss.as_ref().map_or(0, |g| g.delay_ns);
    if let Some(first) = f.gnss.first() {
        let frame = LocalFrame::new(Lla::from_deg(first.lat_deg, first.lon_deg, first.alt_m));
        let (mut sum, mut m) = (0.0, 0usize);
        let poses: Vec<&PoseOutput> = poses
            .iter()
            .filter(|p| p.health.mode.has_position())
            .collect();
        let mut k = 0usize;
        for g in f
            .gnss
            .iter()
            .filter(|g| g.t_ns >= start_ns && g.t_ns <= end_ns)
        {
            let t_ns = g.t_ns - delay_ns;
            while k + 1 < poses.len() && poses[k + 1].t_ns <= t_ns {
                k += 1;
            }
            let (Some(p), Some(q)) = (poses.get(k), poses.get(k + 1)) else {
                continue;
            };
            if p.t_ns > t_ns || q.t_ns < t_ns || q.t_ns - p.t_ns > 200_000_000 {
                continue;
            }
            // Interpolated to the fix time (a 10 Hz IMU's poses are 100 ms apart: 1.5 m at 15 m/s).
            let w = (t_ns - p.t_ns) as f64 / (q.t_ns - p.t_ns).max(1) as f64;
            let a = frame.lla_to_ned(&Lla::from_deg(g.lat_deg, g.lon_deg, g.alt_m));
            let b = frame.lla_to_ned(&p.lla) * (1.0 - w) + frame.lla_to_ned(&q.lla) * w;
            sum += (a - b).xy().norm_squared();
            m += 1;
        }
        if m > 0 {
            s.horizontal_rmse_m = (sum / m as f64).sqrt();
        }
    }
    if let Some(last) = poses.last() {
        s.gnss_rejected = last.health.gnss_pos.rejected;
    }
    // The longest stretch without a fused GNSS position while fixes kept coming.
    let mut last_fused: Option<(i64, u64)> = None;
    for p in poses
        .iter()
        .filter(|p| p.t_ns >= start_ns && p.t_ns <= end_ns)
    {
        let fused = p.health.gnss_pos.fused;
        match last_fused {
            Some((t, n)) if n == fused => {
                s.longest_rejection_s = s.longest_rejection_s.max((p.t_ns - t) as f64 * 1e-9)
            }
            _ => last_fused = Some((p.t_ns, fused)),
        }
    }
    s
}

impl std::fmt::Display for Score {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "roll/pitch/yaw RMSE {:.2}/{:.2}/{:.2} deg (max yaw {:.1}), roll/pitch/yaw within 3 \
             sigma {:.1}/{:.1}/{:.1} %, \
             horizontal RMSE vs fixes {:.2} m, GNSS pos rejected {}, longest unfused {:.1} s, \
             bad sigma rows {}/{}",
            self.rmse_deg[0],
            self.rmse_deg[1],
            self.rmse_deg[2],
            self.max_yaw_err_deg,
            100.0 * self.tilt_within_3sigma[0],
            100.0 * self.tilt_within_3sigma[1],
            100.0 * self.yaw_within_3sigma,
            self.horizontal_rmse_m,
            self.gnss_rejected,
            self.longest_rejection_s,
            self.bad_sigma_rows,
            self.rows
        )
    }
}
