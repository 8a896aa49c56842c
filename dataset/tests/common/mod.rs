//! A small synthetic flight written with `AslWriter`, shared by the dataset tests.

#![allow(dead_code, clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use uavnav_core::rng::Rng;
use uavnav_core::{
    BaroConfig, BaroSample, CameraConfig, CameraFrame, CameraModel, Distortion, FilterProfile,
    FixType, GnssConfig, GnssFix, GnssVelocity, ImageFormat, ImuConfig, ImuSample, Lla, MagConfig,
    MagSample, SensorEvent, TruthSample, VehicleConfig,
};
use uavnav_dataset::AslWriter;

pub fn config() -> VehicleConfig {
    VehicleConfig {
        // Turn-on biases given, so that the optional keys take part in the round trip.
        imu: ImuConfig {
            gyro_bias_sigma_radps: 5e-3,
            accel_bias_sigma_mps2: 0.2,
            ..ImuConfig::TACTICAL_MEMS
        },
        gnss: Some(GnssConfig {
            rate_hz: 5.0,
            lever_arm_body_m: Vector3::new(0.0, 2.0, 0.0),
            delay_ns: 220_000_000,
            altitude_reference: uavnav_core::AltitudeReference::Msl,
        }),
        mag: Some(MagConfig {
            rate_hz: 50.0,
            body_from_mag: UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0),
            sigma_t: 7.0e-8,
        }),
        baro: Some(BaroConfig {
            rate_hz: 20.0,
            sigma_pressure_pa: 0.6,
        }),
        camera: Some(CameraConfig {
            rate_hz: 10.0,
            model: CameraModel {
                width: 640,
                height: 480,
                fx: 500.0,
                fy: 500.0,
                cx: 319.5,
                cy: 239.5,
                distortion: Distortion::RadTan {
                    k1: -0.1,
                    k2: 0.01,
                    p1: 1e-4,
                    p2: -2e-5,
                },
            },
            body_from_cam: Isometry3::from_parts(
                Translation3::new(0.1, 0.0, 0.05),
                UnitQuaternion::from_euler_angles(0.0, -1.2, 0.3),
            ),
        }),
        terrain_elevation_m: 120.5,
        profile: FilterProfile::Paper,
        airframe: uavnav_core::Airframe::FixedWing,
    }
}

pub fn origin() -> Lla {
    Lla::from_deg(40.85, 14.27, 150.0)
}

/// Fake compressed images: the right magic bytes and seeded noise (the dataset layer never decodes).
pub fn image(rng: &mut Rng, format: ImageFormat) -> Arc<[u8]> {
    let mut data: Vec<u8> = match format {
        ImageFormat::Jpeg => vec![0xFF, 0xD8, 0xFF, 0xE0],
        ImageFormat::Png => vec![0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A],
    };
    data.extend((0..200).map(|_| rng.next_u64() as u8));
    Arc::from(data)
}

/// `seconds` of flight: IMU 200 Hz, GNSS 5 Hz, camera 10 Hz (JPEG then PNG alternately), truth 100 Hz.
pub fn events(seconds: i64, seed: u64) -> (Vec<SensorEvent>, Vec<TruthSample>) {
    let mut rng = Rng::new(seed);
    let t0 = 1_000_000_000;
    let mut events = Vec::new();
    let mut truth = Vec::new();
    for k in 0..(200 * seconds) {
        let t_ns = t0 + k * 5_000_000;
        events.push(SensorEvent::Imu(ImuSample {
            t_ns,
            gyro_radps: rng.gaussian3(0.01),
            accel_mps2: Vector3::new(0.0, 0.0, -9.81) + rng.gaussian3(0.1),
        }));
        if k % 40 == 0 {
            events.push(SensorEvent::Gnss(GnssFix {
                t_ns,
                lat_deg: 40.85 + rng.gaussian() * 1e-5,
                lon_deg: 14.27 + rng.gaussian() * 1e-5,
                alt_m: 400.0 + rng.gaussian(),
                // every third fix without velocity, every third without its vertical component
                velocity: match (k / 40) % 3 {
                    0 => Some(GnssVelocity::ned(
                        Vector3::new(30.0, 0.0, 0.0) + rng.gaussian3(0.1),
                        0.1,
                    )),
                    1 => None,
                    _ => Some(GnssVelocity {
                        north_mps: 30.0 + rng.gaussian() * 0.1,
                        east_mps: rng.gaussian() * 0.1,
                        down_mps: None,
                        sigma_mps: 0.2,
                    }),
                },
                sigma_h_m: 1.5,
                sigma_v_m: 3.0,
                fix_type: FixType::Fix3d,
                num_sats: 0,
            }));
        }
        if k % 4 == 1 {
            events.push(SensorEvent::Mag(MagSample {
                t_ns: t_ns + 1_000,
                field_t: Vector3::new(2.2e-5, -1.0e-6, 4.1e-5) + rng.gaussian3(7.0e-8),
            }));
        }
        if k % 10 == 3 {
            events.push(SensorEvent::Baro(BaroSample {
                t_ns: t_ns + 2_000,
                pressure_pa: 96_000.0 + rng.gaussian() * 0.6,
                temperature_degc: (k % 20 == 3).then_some(21.5 + rng.gaussian() * 0.1),
            }));
        }
        if k % 20 == 10 {
            let format = if k % 40 == 10 {
                ImageFormat::Jpeg
            } else {
                ImageFormat::Png
            };
            events.push(SensorEvent::Camera(CameraFrame {
                t_ns,
                camera_id: 0,
                format,
                data: image(&mut rng, format),
            }));
        }
        if k % 2 == 0 {
            truth.push(TruthSample {
                t_ns,
                pos_ned_m: Vector3::new(30.0 * k as f64 * 0.005, 0.0, -250.0) + rng.gaussian3(1e-3),
                nav_from_body: UnitQuaternion::from_euler_angles(
                    rng.gaussian() * 0.1,
                    rng.gaussian() * 0.1,
                    0.5,
                ),
                vel_ned_mps: Vector3::new(30.0, 0.0, 0.0),
                gyro_bias_radps: Vector3::new(1e-4, -2e-4, 3e-5),
                accel_bias_mps2: Vector3::new(0.01, -0.02, 0.005),
            });
        }
    }
    (events, truth)
}

/// Writes the synthetic flight as an ASL folder at `dir`.
pub fn write_asl(dir: &Path, seconds: i64) -> (Vec<SensorEvent>, Vec<TruthSample>) {
    let (events, truth) = events(seconds, 7);
    let mut w = AslWriter::create(dir, "uav-test", &config(), Some(origin())).unwrap();
    for e in &events {
        w.write_event(e).unwrap();
    }
    for s in &truth {
        w.write_truth(s).unwrap();
    }
    w.finish().unwrap();
    (events, truth)
}

/// The real EuRoC subset, if present.
pub fn euroc() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/euroc_v1_01_easy_kimera");
    if p.is_dir() {
        Some(p)
    } else {
        eprintln!("skipping: {} not found", p.display());
        None
    }
}
