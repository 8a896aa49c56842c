//! Wire-message builders for service and client tests: plausible samples, envelopes, the tests'
//! camera ([`camera_config`]), a vehicle configuration and a minimal JPEG header (what
//! `server/tests` and the CLI tests used to write as literals each).

use uavnav_core::{CameraConfig, CameraModel, Distortion};

use crate::pb;

/// A level IMU sample at `t_ns`.
pub fn imu(t_ns: i64) -> pb::ImuSample {
    pb::ImuSample {
        t_ns,
        accel_z_mps2: -9.81,
        ..Default::default()
    }
}

/// An IMU envelope.
pub fn imu_env(id: &str, seq: u64, samples: Vec<pb::ImuSample>) -> pb::SensorEnvelope {
    pb::SensorEnvelope {
        vehicle_id: id.into(),
        sequence: seq,
        payload: Some(pb::sensor_envelope::Payload::Imu(pb::ImuBatch { samples })),
    }
}

/// The envelope of one sensor event (an IMU sample as a batch of one).
pub fn event_env(id: &str, seq: u64, e: &uavnav_core::SensorEvent) -> pb::SensorEnvelope {
    use pb::sensor_envelope::Payload as P;
    let payload = match e {
        uavnav_core::SensorEvent::Imu(s) => P::Imu(pb::ImuBatch {
            samples: vec![s.into()],
        }),
        other => P::from(other),
    };
    pb::SensorEnvelope {
        vehicle_id: id.into(),
        sequence: seq,
        payload: Some(payload),
    }
}

/// The IMU samples and GNSS fixes of `events` as envelopes of vehicle `id`, numbered from
/// `first_seq` (the other sensors left out).
pub fn imu_gnss_envs(
    id: &str,
    first_seq: u64,
    events: &[uavnav_core::SensorEvent],
) -> Vec<pb::SensorEnvelope> {
    use uavnav_core::SensorEvent as E;
    events
        .iter()
        .filter(|e| matches!(e, E::Imu(_) | E::Gnss(_)))
        .enumerate()
        .map(|(k, e)| event_env(id, first_seq + k as u64, e))
        .collect()
}

/// A plausible GNSS fix.
pub fn fix(t_ns: i64) -> pb::GnssFix {
    pb::GnssFix {
        t_ns,
        latitude_deg: 45.0,
        longitude_deg: 7.0,
        altitude_m: 300.0,
        sigma_horizontal_m: 1.0,
        sigma_vertical_m: 2.0,
        vel_north_mps: Some(0.0),
        vel_east_mps: Some(0.0),
        vel_down_mps: Some(0.0),
        sigma_velocity_mps: Some(0.1),
        fix_type: pb::FixType::Fix3d as i32,
        num_satellites: 10,
    }
}

/// A GNSS envelope.
pub fn gnss_env(id: &str, seq: u64, f: pb::GnssFix) -> pb::SensorEnvelope {
    pb::SensorEnvelope {
        vehicle_id: id.into(),
        sequence: seq,
        payload: Some(pb::sensor_envelope::Payload::Gnss(f)),
    }
}

/// The tests' camera: 640x480 px, a 500 px focal length, centred principal point, no distortion,
/// 10 Hz, mounted at the body origin with the body's axes. Its wire form is
/// `pb::CameraConfig::from(&camera_config())`.
pub fn camera_config() -> CameraConfig {
    CameraConfig {
        rate_hz: 10.0,
        model: CameraModel {
            width: CAMERA_WIDTH_PX.into(),
            height: CAMERA_HEIGHT_PX.into(),
            fx: 500.0,
            fy: 500.0,
            cx: 320.0,
            cy: 240.0,
            distortion: Distortion::None,
        },
        body_from_cam: nalgebra::Isometry3::identity(),
    }
}

/// The width of [`camera_config`]'s images, px.
pub const CAMERA_WIDTH_PX: u16 = 640;
/// The height of [`camera_config`]'s images, px.
pub const CAMERA_HEIGHT_PX: u16 = 480;

/// A vehicle configuration, with [`camera_config`] when `camera`.
pub fn vehicle_config(camera: bool) -> pb::VehicleConfig {
    pb::VehicleConfig {
        imu: Some(pb::ImuConfig {
            rate_hz: 200.0,
            gyro_noise_density: 1e-4,
            gyro_random_walk: 2e-6,
            accel_noise_density: 1e-3,
            accel_random_walk: 1e-4,
            ..Default::default()
        }),
        gnss: Some(pb::GnssConfig {
            rate_hz: 5.0,
            lever_arm_body_m: Some(pb::Vector3::default()),
            ..Default::default()
        }),
        camera: camera.then(|| pb::CameraConfig::from(&camera_config())),
        terrain_elevation_m: 0.0,
        profile: pb::FilterProfile::Eskf as i32,
        mag: None,
        baro: None,
        // the service tests feed the simulator's fixed-wing flights
        airframe: pb::Airframe::FixedWing as i32,
    }
}

/// A magnetometer sample (a mid-latitude Earth field, tesla).
pub fn mag(t_ns: i64) -> pb::MagSample {
    pb::MagSample {
        t_ns,
        field_x_t: 2.2e-5,
        field_y_t: 0.1e-5,
        field_z_t: 4.1e-5,
    }
}

/// A barometer sample.
pub fn baro(t_ns: i64) -> pb::BaroSample {
    pb::BaroSample {
        t_ns,
        pressure_pa: 97_700.0,
        temperature_degc: Some(21.5),
    }
}

/// A magnetometer envelope.
pub fn mag_env(id: &str, seq: u64, m: pb::MagSample) -> pb::SensorEnvelope {
    pb::SensorEnvelope {
        vehicle_id: id.into(),
        sequence: seq,
        payload: Some(pb::sensor_envelope::Payload::Mag(m)),
    }
}

/// A barometer envelope.
pub fn baro_env(id: &str, seq: u64, b: pb::BaroSample) -> pb::SensorEnvelope {
    pb::SensorEnvelope {
        vehicle_id: id.into(),
        sequence: seq,
        payload: Some(pb::sensor_envelope::Payload::Baro(b)),
    }
}

/// A config envelope.
pub fn config_env(id: &str, seq: u64, camera: bool) -> pb::SensorEnvelope {
    pb::SensorEnvelope {
        vehicle_id: id.into(),
        sequence: seq,
        payload: Some(pb::sensor_envelope::Payload::Config(vehicle_config(camera))),
    }
}

/// A minimal JPEG header (SOI + SOF0 with the given size + EOI): enough for header validation.
pub fn jpeg_header(width: u16, height: u16) -> Vec<u8> {
    let mut d = vec![0xFF, 0xD8, 0xFF, 0xC0, 0x00, 0x0B, 8];
    d.extend(height.to_be_bytes());
    d.extend(width.to_be_bytes());
    d.extend([1, 1, 0x11, 0, 0xFF, 0xD9]);
    d
}

/// A JPEG header of [`camera_config`]'s image size (a frame the camera could have taken).
pub fn camera_jpeg_header() -> Vec<u8> {
    jpeg_header(CAMERA_WIDTH_PX, CAMERA_HEIGHT_PX)
}

/// A camera envelope carrying `data` as JPEG.
pub fn camera_env(id: &str, seq: u64, t_ns: i64, data: Vec<u8>) -> pb::SensorEnvelope {
    pb::SensorEnvelope {
        vehicle_id: id.into(),
        sequence: seq,
        payload: Some(pb::sensor_envelope::Payload::Camera(pb::CameraFrame {
            t_ns,
            camera_id: 0,
            image: Some(foxglove::messages::CompressedImage {
                timestamp: None,
                frame_id: "cam0".into(),
                data: data.into(),
                format: "jpeg".into(),
            }),
        })),
    }
}
