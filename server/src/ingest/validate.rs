//! Input validation: every wire message is checked field by field before it can reach an actor,
//! so bad input never crashes the process or touches another vehicle. A refusal carries the exact
//! [`pb::IngestStatus`] and a reason naming the field.
//!
//! Field-level conversion and plausibility limits are the wire contract's (`uavnav_proto::convert`);
//! this module adds what only the service knows: vehicle ids, batch and image size limits, image
//! headers against the vehicle's configured camera, and the status of each refusal.

use uavnav_core::{
    BaroSample, CameraFrame, GnssFix, ImageFormat, ImuSample, MagSample, VehicleConfig,
};
use uavnav_proto::convert::{self, ConvertError};
use uavnav_proto::v1 as pb;

use crate::metrics::Cause;

/// Most IMU samples in one batch (the gRPC codec and the Zenoh input count them on the wire,
/// before decoding, and keep at most one more than this).
pub const MAX_IMU_BATCH: usize = uavnav_proto::convert::limits::MAX_IMU_BATCH_SAMPLES;
/// Longest vehicle id.
pub const MAX_ID_LEN: usize = 128;

/// A refused input: the ack status and a reason naming the field.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{reason}")]
pub struct Rejection {
    /// Ack status.
    pub status: pb::IngestStatus,
    /// Reason, starting with the field path.
    pub reason: String,
    /// The reason's class (the `reason` label of `uavnav_inputs_refused_total`).
    pub cause: Cause,
}

impl Rejection {
    /// A refusal with an explicit status and cause.
    pub fn new(status: pb::IngestStatus, cause: Cause, reason: impl Into<String>) -> Self {
        Self {
            status,
            reason: reason.into(),
            cause,
        }
    }

    /// INVALID_ARGUMENT.
    pub fn invalid(reason: impl Into<String>) -> Self {
        Self::new(pb::IngestStatus::InvalidArgument, Cause::Invalid, reason)
    }

    /// FAILED_PRECONDITION.
    pub fn precondition(reason: impl Into<String>) -> Self {
        Self::new(
            pb::IngestStatus::FailedPrecondition,
            Cause::Precondition,
            reason,
        )
    }

    /// RESOURCE_EXHAUSTED.
    pub fn exhausted(reason: impl Into<String>) -> Self {
        Self::new(
            pb::IngestStatus::ResourceExhausted,
            Cause::Exhausted,
            reason,
        )
    }

    /// RESOURCE_EXHAUSTED for an input above a size limit (bytes, samples, pixels).
    pub fn too_large(reason: impl Into<String>) -> Self {
        Self::new(pb::IngestStatus::ResourceExhausted, Cause::TooLarge, reason)
    }

    /// The matching gRPC status (for unary calls).
    pub fn to_status(&self) -> tonic::Status {
        let code = match self.status {
            pb::IngestStatus::InvalidArgument => tonic::Code::InvalidArgument,
            pb::IngestStatus::FailedPrecondition => tonic::Code::FailedPrecondition,
            pb::IngestStatus::ResourceExhausted => tonic::Code::ResourceExhausted,
            pb::IngestStatus::OutOfRange => tonic::Code::OutOfRange,
            pb::IngestStatus::Late => tonic::Code::OutOfRange,
            pb::IngestStatus::PermissionDenied => tonic::Code::PermissionDenied,
            _ => tonic::Code::Unknown,
        };
        tonic::Status::new(code, self.reason.clone())
    }
}

type Check<T> = Result<T, Rejection>;

/// Checks a vehicle id: 1–128 characters of `[A-Za-z0-9_.-]` (also a Zenoh key chunk).
pub fn vehicle_id(id: &str) -> Check<()> {
    if id.is_empty() {
        return Err(Rejection::invalid("vehicle_id: must not be empty"));
    }
    if id.len() > MAX_ID_LEN {
        return Err(Rejection::invalid(format!(
            "vehicle_id: longer than {MAX_ID_LEN} characters"
        )));
    }
    if let Some(c) = id
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-')))
    {
        return Err(Rejection::invalid(format!(
            "vehicle_id: character {c:?} not allowed (use [A-Za-z0-9_.-])"
        )));
    }
    Ok(())
}

/// A conversion error from the wire contract, with the enclosing field's name in front.
fn invalid_in(parent: &str, e: ConvertError) -> Rejection {
    let cause = match &e {
        ConvertError::Missing { .. } => Cause::Missing,
        ConvertError::NotFinite { .. } => Cause::NotFinite,
        ConvertError::OutOfRange { .. } => Cause::OutOfRange,
        ConvertError::UnknownEnum { .. } => Cause::UnknownEnum,
        ConvertError::Invalid { .. } => Cause::Invalid,
    };
    Rejection::new(
        pb::IngestStatus::InvalidArgument,
        cause,
        e.within(parent).to_string(),
    )
}

/// A negative sensor time (MCAP recordings and the estimator's clocks are unsigned from 0).
fn negative_time(field: &str, t_ns: i64) -> Check<()> {
    if t_ns < 0 {
        return Err(Rejection::new(
            pb::IngestStatus::InvalidArgument,
            Cause::OutOfRange,
            format!("{field}.t_ns: {t_ns} is negative"),
        ));
    }
    Ok(())
}

/// Validates an IMU batch (finite, plausible, strictly increasing times) and converts it.
pub fn imu_batch(b: &pb::ImuBatch) -> Check<Vec<ImuSample>> {
    if b.samples.is_empty() {
        return Err(Rejection::invalid("imu.samples: empty batch"));
    }
    if b.samples.len() > MAX_IMU_BATCH {
        // The transports decode at most one sample more than the limit: the true count is larger.
        return Err(Rejection::too_large(format!(
            "imu.samples: more than {MAX_IMU_BATCH} samples in one batch (limit {MAX_IMU_BATCH})"
        )));
    }
    let samples = convert::sensors::imu_batch(b).map_err(|e| invalid_in("imu", e))?;
    if let Some((i, s)) = samples.iter().enumerate().find(|(_, s)| s.t_ns < 0) {
        return Err(Rejection::invalid(format!(
            "imu.samples[{i}].t_ns: {} is negative",
            s.t_ns
        )));
    }
    Ok(samples)
}

/// Validates a GNSS fix and converts it.
pub fn gnss_fix(g: &pb::GnssFix) -> Check<GnssFix> {
    let fix = GnssFix::try_from(g).map_err(|e| invalid_in("gnss", e))?;
    negative_time("gnss", fix.t_ns)?;
    Ok(fix)
}

/// Validates a magnetometer sample (finite, each axis within the contract's plausible bound: a
/// value in gauss or µT sent as tesla is refused) and converts it.
pub fn mag_sample(m: &pb::MagSample) -> Check<MagSample> {
    let s = MagSample::try_from(m).map_err(|e| invalid_in("mag", e))?;
    negative_time("mag", s.t_ns)?;
    Ok(s)
}

/// Validates a barometer sample (finite, pressure and temperature within the contract's plausible
/// ranges: a value in hPa sent as Pa is refused) and converts it.
pub fn baro_sample(b: &pb::BaroSample) -> Check<BaroSample> {
    let s = BaroSample::try_from(b).map_err(|e| invalid_in("baro", e))?;
    negative_time("baro", s.t_ns)?;
    Ok(s)
}

/// What the service knows of a vehicle's camera, to check frames against.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CameraSpec {
    /// Camera index.
    pub camera_id: u32,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
}

/// Image limits (the service's `[vision]` configuration).
#[derive(Debug, Clone, Copy)]
pub struct ImageLimits {
    /// Largest compressed size, bytes.
    pub max_bytes: usize,
    /// Largest camera width, px.
    pub max_width_px: u32,
    /// Largest camera height, px.
    pub max_height_px: u32,
    /// Largest camera resolution, pixels (width × height).
    pub max_pixels: u64,
}

impl ImageLimits {
    /// Checks a resolution against the limits; the error names `field` and the limit's key.
    pub fn check(&self, field: &str, w: u32, h: u32) -> Check<()> {
        let pixels = u64::from(w) * u64::from(h);
        let over = if w > self.max_width_px {
            Some(format!(
                "width {w} px above the service's maximum {} px (vision.max_camera_width_px)",
                self.max_width_px
            ))
        } else if h > self.max_height_px {
            Some(format!(
                "height {h} px above the service's maximum {} px (vision.max_camera_height_px)",
                self.max_height_px
            ))
        } else if pixels > self.max_pixels {
            Some(format!(
                "{w}x{h} = {pixels} pixels above the service's maximum {} (vision.max_camera_pixels)",
                self.max_pixels
            ))
        } else {
            None
        };
        match over {
            Some(why) => Err(Rejection::too_large(format!("{field}: {why}"))),
            None => Ok(()),
        }
    }
}

/// Validates a camera frame against the vehicle's camera (if any) and converts it.
pub fn camera_frame(
    c: &pb::CameraFrame,
    camera: Option<CameraSpec>,
    limits: ImageLimits,
) -> Check<CameraFrame> {
    let Some(spec) = camera else {
        return Err(Rejection::precondition(
            "camera: the vehicle has no camera configuration (send a VehicleConfig with `camera` first)",
        ));
    };
    if c.camera_id != spec.camera_id {
        return Err(Rejection::precondition(format!(
            "camera.camera_id: {} is not configured (configured: {})",
            c.camera_id, spec.camera_id
        )));
    }
    // Size first: the conversion copies the bytes.
    let size = c.image.as_ref().map_or(0, |i| i.data.len());
    if size > limits.max_bytes {
        return Err(Rejection::too_large(format!(
            "camera.image.data: {size} bytes, limit {}",
            limits.max_bytes
        )));
    }
    let frame = CameraFrame::try_from(c).map_err(|e| invalid_in("camera", e))?;
    if frame.t_ns < 0 {
        return Err(Rejection::invalid(format!(
            "camera.t_ns: {} is negative",
            frame.t_ns
        )));
    }
    // The header's size, before anything is decoded: an image bomb (a small file announcing a
    // huge image) is refused here, never handed to a decoder.
    let (w, h) = match frame.format {
        ImageFormat::Jpeg => jpeg_dimensions(&frame.data),
        ImageFormat::Png => png_dimensions(&frame.data),
    }
    .ok_or_else(|| {
        Rejection::invalid(format!(
            "camera.image.data: corrupt {} header",
            frame.format.as_str()
        ))
    })?;
    limits.check("camera.image", w, h)?;
    if (w, h) != (spec.width, spec.height) {
        return Err(Rejection::invalid(format!(
            "camera.image: {w}x{h} px does not match the configured {}x{}",
            spec.width, spec.height
        )));
    }
    Ok(frame)
}

/// Width and height from a JPEG's SOF segment, walking the marker segments; `None` when the
/// header is truncated or malformed.
pub fn jpeg_dimensions(d: &[u8]) -> Option<(u32, u32)> {
    if d.get(0..2)? != [0xFF, 0xD8] {
        return None;
    }
    let mut i = 2;
    loop {
        // Fill bytes (0xFF) may precede a marker.
        while *d.get(i)? == 0xFF && *d.get(i + 1)? == 0xFF {
            i += 1;
        }
        if *d.get(i)? != 0xFF {
            return None;
        }
        let marker = *d.get(i + 1)?;
        let len = u16::from_be_bytes([*d.get(i + 2)?, *d.get(i + 3)?]) as usize;
        if len < 2 {
            return None;
        }
        let is_sof = matches!(marker, 0xC0..=0xCF) && !matches!(marker, 0xC4 | 0xC8 | 0xCC);
        if is_sof {
            let seg = d.get(i + 4..i + 2 + len)?;
            let h = u16::from_be_bytes([*seg.get(1)?, *seg.get(2)?]) as u32;
            let w = u16::from_be_bytes([*seg.get(3)?, *seg.get(4)?]) as u32;
            return (w > 0 && h > 0).then_some((w, h));
        }
        if marker == 0xD9 || marker == 0xDA {
            return None; // end of image or scan data before any frame header
        }
        i += 2 + len;
    }
}

/// The PNG signature.
const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1A, b'\n'];

/// Width and height from a PNG's IHDR chunk (the first chunk, 13 bytes), which must be
/// well-formed: a known bit depth and colour type (decoders refuse others, after allocating).
pub fn png_dimensions(d: &[u8]) -> Option<(u32, u32)> {
    if d.get(0..8)? != PNG_SIGNATURE || d.get(8..12)? != [0, 0, 0, 13] {
        return None;
    }
    if d.get(12..16)? != b"IHDR" {
        return None;
    }
    let w = u32::from_be_bytes(d.get(16..20)?.try_into().ok()?);
    let h = u32::from_be_bytes(d.get(20..24)?.try_into().ok()?);
    let (depth, colour) = (*d.get(24)?, *d.get(25)?);
    let valid = match colour {
        0 => matches!(depth, 1 | 2 | 4 | 8 | 16),
        3 => matches!(depth, 1 | 2 | 4 | 8),
        2 | 4 | 6 => matches!(depth, 8 | 16),
        _ => false,
    };
    (valid && w > 0 && h > 0).then_some((w, h))
}

/// Validates a vehicle configuration (the contract's plausibility bounds, and a camera within the
/// service's maximum resolution) and converts it; also returns the camera spec for frames.
pub fn vehicle_config(
    c: &pb::VehicleConfig,
    limits: ImageLimits,
) -> Check<(VehicleConfig, Option<CameraSpec>)> {
    let config = VehicleConfig::try_from(c).map_err(|e| invalid_in("config", e))?;
    let spec = match (&c.camera, &config.camera) {
        (Some(wire), Some(cam)) => {
            let (width, height) = (cam.model.width, cam.model.height);
            // A configuration is refused as invalid (the camera cannot be served), not shed.
            limits
                .check("config.camera", width, height)
                .map_err(|r| Rejection {
                    status: pb::IngestStatus::InvalidArgument,
                    ..r
                })?;
            Some(CameraSpec {
                camera_id: wire.camera_id,
                width,
                height,
            })
        }
        _ => None,
    };
    Ok((config, spec))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids() {
        assert!(vehicle_id("uav-01.a_b").is_ok());
        assert!(vehicle_id("").is_err());
        assert!(vehicle_id("a/b").unwrap_err().reason.contains("'/'"));
        assert!(vehicle_id(&"x".repeat(129)).is_err());
    }

    #[test]
    fn imu_backwards_and_nan_name_the_field() {
        let s = |t, gx| pb::ImuSample {
            t_ns: t,
            gyro_x_radps: gx,
            accel_z_mps2: -9.8,
            ..Default::default()
        };
        let e = imu_batch(&pb::ImuBatch {
            samples: vec![s(10, 0.0), s(5, 0.0)],
        })
        .unwrap_err();
        assert!(e.reason.starts_with("imu.samples[1].t_ns"), "{}", e.reason);
        let e = imu_batch(&pb::ImuBatch {
            samples: vec![s(10, f64::NAN)],
        })
        .unwrap_err();
        assert!(
            e.reason.starts_with("imu.samples[0].gyro_x_radps"),
            "{}",
            e.reason
        );
        assert_eq!(e.status, pb::IngestStatus::InvalidArgument);
    }

    #[test]
    fn mag_and_baro_nan_and_absurd_values_name_the_field() {
        let e = mag_sample(&pb::MagSample {
            t_ns: 1,
            field_x_t: f64::NAN,
            ..Default::default()
        })
        .unwrap_err();
        assert!(e.reason.starts_with("mag.field_x_t"), "{}", e.reason);
        assert_eq!(e.cause, Cause::NotFinite);
        // 45 µT sent in gauss-like units: absurd as tesla.
        let e = mag_sample(&pb::MagSample {
            t_ns: 1,
            field_z_t: 0.45,
            ..Default::default()
        })
        .unwrap_err();
        assert_eq!(
            (e.cause, e.status),
            (Cause::OutOfRange, pb::IngestStatus::InvalidArgument)
        );
        assert!(
            mag_sample(&pb::MagSample {
                t_ns: 1,
                field_x_t: 2.2e-5,
                field_z_t: 4.1e-5,
                ..Default::default()
            })
            .is_ok()
        );
        // 1013 hPa sent as Pa.
        let e = baro_sample(&pb::BaroSample {
            t_ns: 1,
            pressure_pa: 1013.0 * 1e-2,
            temperature_degc: None,
        })
        .unwrap_err();
        assert!(e.reason.starts_with("baro.pressure_pa"), "{}", e.reason);
        let e = baro_sample(&pb::BaroSample {
            t_ns: -5,
            pressure_pa: 101_325.0,
            temperature_degc: Some(20.0),
        })
        .unwrap_err();
        assert!(e.reason.starts_with("baro.t_ns"), "{}", e.reason);
        assert!(
            baro_sample(&pb::BaroSample {
                t_ns: 5,
                pressure_pa: 101_325.0,
                temperature_degc: Some(20.0),
            })
            .is_ok()
        );
    }

    #[test]
    fn jpeg_header_parsing() {
        // SOI, APP0 (len 4, 2 payload bytes), SOF0 with 480x640.
        let mut d = vec![0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0x04, 0, 0];
        d.extend([
            0xFF, 0xC0, 0x00, 0x0B, 8, 0x01, 0xE0, 0x02, 0x80, 1, 1, 0x11, 0,
        ]);
        assert_eq!(jpeg_dimensions(&d), Some((640, 480)));
        assert_eq!(jpeg_dimensions(&d[..12]), None, "truncated");
        assert_eq!(jpeg_dimensions(&[0xFF, 0xD8, 0x00, 0x01]), None, "garbage");
    }
}
