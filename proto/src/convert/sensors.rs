//! Sensor samples: IMU, GNSS, magnetometer, barometer, camera frames.

use std::sync::Arc;

use nalgebra::Vector3;
use uavnav_core::{
    BaroSample, CameraFrame, FixType, GnssFix, GnssVelocity, ImageFormat, ImuSample, MagSample,
};

use super::{ConvertError, in_range, limits, positive, required};
use crate::v1;

impl TryFrom<&v1::ImuSample> for ImuSample {
    type Error = ConvertError;
    fn try_from(s: &v1::ImuSample) -> Result<Self, ConvertError> {
        let g = limits::MAX_GYRO_RADPS;
        let a = limits::MAX_ACCEL_MPS2;
        Ok(ImuSample {
            t_ns: s.t_ns,
            gyro_radps: Vector3::new(
                in_range("gyro_x_radps", s.gyro_x_radps, -g, g)?,
                in_range("gyro_y_radps", s.gyro_y_radps, -g, g)?,
                in_range("gyro_z_radps", s.gyro_z_radps, -g, g)?,
            ),
            accel_mps2: Vector3::new(
                in_range("accel_x_mps2", s.accel_x_mps2, -a, a)?,
                in_range("accel_y_mps2", s.accel_y_mps2, -a, a)?,
                in_range("accel_z_mps2", s.accel_z_mps2, -a, a)?,
            ),
        })
    }
}

impl From<&ImuSample> for v1::ImuSample {
    fn from(s: &ImuSample) -> Self {
        v1::ImuSample {
            t_ns: s.t_ns,
            gyro_x_radps: s.gyro_radps.x,
            gyro_y_radps: s.gyro_radps.y,
            gyro_z_radps: s.gyro_radps.z,
            accel_x_mps2: s.accel_mps2.x,
            accel_y_mps2: s.accel_mps2.y,
            accel_z_mps2: s.accel_mps2.z,
        }
    }
}

/// Converts a batch, checking every sample and that times strictly increase.
pub fn imu_batch(batch: &v1::ImuBatch) -> Result<Vec<ImuSample>, ConvertError> {
    let mut out: Vec<ImuSample> = Vec::with_capacity(batch.samples.len());
    for (i, wire) in batch.samples.iter().enumerate() {
        let s = ImuSample::try_from(wire).map_err(|e| e.within(format_args!("samples[{i}]")))?;
        let prev_t_ns = out.last().map(|p| p.t_ns);
        if let Some(prev) = prev_t_ns.filter(|&p| s.t_ns <= p) {
            return Err(ConvertError::invalid(
                &format!("samples[{i}].t_ns"),
                format!("{} does not increase (previous sample {prev})", s.t_ns),
            ));
        }
        out.push(s);
    }
    Ok(out)
}

impl TryFrom<&v1::ImuBatch> for Vec<ImuSample> {
    type Error = ConvertError;
    fn try_from(batch: &v1::ImuBatch) -> Result<Self, ConvertError> {
        imu_batch(batch)
    }
}

impl From<&[ImuSample]> for v1::ImuBatch {
    fn from(samples: &[ImuSample]) -> Self {
        v1::ImuBatch {
            samples: samples.iter().map(v1::ImuSample::from).collect(),
        }
    }
}

/// Wire fix type → core; `UNSPECIFIED` and unknown values are errors.
pub fn fix_type(field: &str, raw: i32) -> Result<FixType, ConvertError> {
    use v1::FixType as W;
    match W::try_from(raw) {
        Ok(W::None) => Ok(FixType::None),
        Ok(W::Fix2d) => Ok(FixType::Fix2d),
        Ok(W::Fix3d) => Ok(FixType::Fix3d),
        Ok(W::Dgps) => Ok(FixType::Dgps),
        Ok(W::RtkFloat) => Ok(FixType::RtkFloat),
        Ok(W::RtkFixed) => Ok(FixType::RtkFixed),
        Ok(W::Unspecified) | Err(_) => Err(ConvertError::UnknownEnum {
            field: field.to_owned(),
            value: raw,
        }),
    }
}

impl From<FixType> for v1::FixType {
    fn from(f: FixType) -> Self {
        match f {
            FixType::None => v1::FixType::None,
            FixType::Fix2d => v1::FixType::Fix2d,
            FixType::Fix3d => v1::FixType::Fix3d,
            FixType::Dgps => v1::FixType::Dgps,
            FixType::RtkFloat => v1::FixType::RtkFloat,
            FixType::RtkFixed => v1::FixType::RtkFixed,
        }
    }
}

impl TryFrom<&v1::GnssFix> for GnssFix {
    type Error = ConvertError;
    fn try_from(f: &v1::GnssFix) -> Result<Self, ConvertError> {
        let (alt_lo, alt_hi) = limits::ALT_RANGE_M;
        let v = limits::MAX_VEL_MPS;
        Ok(GnssFix {
            t_ns: f.t_ns,
            lat_deg: in_range("latitude_deg", f.latitude_deg, -90.0, 90.0)?,
            lon_deg: in_range("longitude_deg", f.longitude_deg, -180.0, 180.0)?,
            alt_m: in_range("altitude_m", f.altitude_m, alt_lo, alt_hi)?,
            velocity: match (f.vel_north_mps, f.vel_east_mps, f.sigma_velocity_mps) {
                (Some(n), Some(e), Some(s)) => Some(GnssVelocity {
                    north_mps: in_range("vel_north_mps", n, -v, v)?,
                    east_mps: in_range("vel_east_mps", e, -v, v)?,
                    down_mps: f
                        .vel_down_mps
                        .map(|d| in_range("vel_down_mps", d, -v, v))
                        .transpose()?,
                    sigma_mps: positive("sigma_velocity_mps", s, limits::MAX_SIGMA)?,
                }),
                (None, None, None) if f.vel_down_mps.is_none() => None,
                _ => {
                    return Err(ConvertError::invalid(
                        "vel_north_mps",
                        "vel_north_mps, vel_east_mps and sigma_velocity_mps must be all set or \
                         all unset (vel_down_mps may be unset on its own)",
                    ));
                }
            },
            sigma_h_m: positive(
                "sigma_horizontal_m",
                f.sigma_horizontal_m,
                limits::MAX_SIGMA,
            )?,
            sigma_v_m: positive("sigma_vertical_m", f.sigma_vertical_m, limits::MAX_SIGMA)?,
            fix_type: fix_type("fix_type", f.fix_type)?,
            num_sats: f.num_satellites,
        })
    }
}

impl From<&GnssFix> for v1::GnssFix {
    fn from(f: &GnssFix) -> Self {
        v1::GnssFix {
            t_ns: f.t_ns,
            latitude_deg: f.lat_deg,
            longitude_deg: f.lon_deg,
            altitude_m: f.alt_m,
            vel_north_mps: f.velocity.map(|v| v.north_mps),
            vel_east_mps: f.velocity.map(|v| v.east_mps),
            vel_down_mps: f.velocity.and_then(|v| v.down_mps),
            sigma_horizontal_m: f.sigma_h_m,
            sigma_vertical_m: f.sigma_v_m,
            sigma_velocity_mps: f.velocity.map(|v| v.sigma_mps),
            fix_type: v1::FixType::from(f.fix_type) as i32,
            num_satellites: f.num_sats,
        }
    }
}

impl TryFrom<&v1::MagSample> for MagSample {
    type Error = ConvertError;
    fn try_from(m: &v1::MagSample) -> Result<Self, ConvertError> {
        let b = limits::MAX_MAG_FIELD_T;
        Ok(MagSample {
            t_ns: m.t_ns,
            field_t: Vector3::new(
                in_range("field_x_t", m.field_x_t, -b, b)?,
                in_range("field_y_t", m.field_y_t, -b, b)?,
                in_range("field_z_t", m.field_z_t, -b, b)?,
            ),
        })
    }
}

impl From<&MagSample> for v1::MagSample {
    fn from(m: &MagSample) -> Self {
        v1::MagSample {
            t_ns: m.t_ns,
            field_x_t: m.field_t.x,
            field_y_t: m.field_t.y,
            field_z_t: m.field_t.z,
        }
    }
}

impl TryFrom<&v1::BaroSample> for BaroSample {
    type Error = ConvertError;
    fn try_from(b: &v1::BaroSample) -> Result<Self, ConvertError> {
        let (p_lo, p_hi) = limits::PRESSURE_RANGE_PA;
        let (t_lo, t_hi) = limits::TEMPERATURE_RANGE_DEGC;
        Ok(BaroSample {
            t_ns: b.t_ns,
            pressure_pa: in_range("pressure_pa", b.pressure_pa, p_lo, p_hi)?,
            temperature_degc: b
                .temperature_degc
                .map(|t| in_range("temperature_degc", t, t_lo, t_hi))
                .transpose()?,
        })
    }
}

impl From<&BaroSample> for v1::BaroSample {
    fn from(b: &BaroSample) -> Self {
        v1::BaroSample {
            t_ns: b.t_ns,
            pressure_pa: b.pressure_pa,
            temperature_degc: b.temperature_degc,
        }
    }
}

/// Parses a Foxglove `CompressedImage.format` string ("jpeg", "jpg" or "png", any case).
pub fn image_format(field: &str, format: &str) -> Result<ImageFormat, ConvertError> {
    match format.to_ascii_lowercase().as_str() {
        "jpeg" | "jpg" => Ok(ImageFormat::Jpeg),
        "png" => Ok(ImageFormat::Png),
        other => Err(ConvertError::invalid(
            field,
            format!("unsupported image format '{other}' (expected jpeg or png)"),
        )),
    }
}

impl TryFrom<&v1::CameraFrame> for CameraFrame {
    type Error = ConvertError;
    fn try_from(f: &v1::CameraFrame) -> Result<Self, ConvertError> {
        let image = required("image", &f.image)?;
        let format = image_format("image.format", &image.format)?;
        if image.data.is_empty() {
            return Err(ConvertError::invalid("image.data", "empty image"));
        }
        // Labels lie more often than magic bytes: refuse a mismatch here rather than in the decoder.
        match ImageFormat::sniff(&image.data) {
            Some(sniffed) if sniffed == format => {}
            _ => {
                return Err(ConvertError::invalid(
                    "image.data",
                    format!("not a {} image (magic bytes)", format.as_str()),
                ));
            }
        }
        Ok(CameraFrame {
            t_ns: f.t_ns,
            camera_id: f.camera_id,
            format,
            data: Arc::from(&image.data[..]),
        })
    }
}

impl From<&CameraFrame> for v1::CameraFrame {
    fn from(f: &CameraFrame) -> Self {
        v1::CameraFrame {
            t_ns: f.t_ns,
            camera_id: f.camera_id,
            image: Some(foxglove::messages::CompressedImage {
                timestamp: crate::foxglove_conv::timestamp(f.t_ns),
                frame_id: crate::foxglove_conv::camera_frame_id(f.camera_id),
                data: foxglove::bytes::Bytes::copy_from_slice(&f.data),
                format: f.format.as_str().to_owned(),
            }),
        }
    }
}

impl From<&uavnav_core::SensorEvent> for v1::sensor_envelope::Payload {
    /// One event as an envelope payload (an IMU sample becomes a batch of one).
    fn from(e: &uavnav_core::SensorEvent) -> Self {
        use v1::sensor_envelope::Payload;
        match e {
            uavnav_core::SensorEvent::Imu(s) => Payload::Imu(v1::ImuBatch {
                samples: vec![s.into()],
            }),
            uavnav_core::SensorEvent::Gnss(f) => Payload::Gnss(f.into()),
            uavnav_core::SensorEvent::Mag(m) => Payload::Mag(m.into()),
            uavnav_core::SensorEvent::Baro(b) => Payload::Baro(b.into()),
            uavnav_core::SensorEvent::Camera(c) => Payload::Camera(c.into()),
        }
    }
}
