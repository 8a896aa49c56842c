//! Vehicle configuration: IMU noise, GNSS lever arm, camera model and mount, profile.

use uavnav_core::{
    Airframe, AltitudeReference, BaroConfig, CameraConfig, CameraModel, Distortion, FilterProfile,
    GnssConfig, ImuConfig, MagConfig, VehicleConfig,
};

use nalgebra::Vector3;

use super::geometry::{isometry, required_quaternion, required_vector3};
use super::limits::{
    AIDING_RATE_HZ, FOCAL_RANGE_PX, IMU_RATE_HZ, MAX_ACCEL_BIAS_SIGMA_MPS2,
    MAX_ACCEL_NOISE_DENSITY, MAX_ACCEL_RANDOM_WALK, MAX_DISTORTION_COEFF,
    MAX_GYRO_BIAS_SIGMA_RADPS, MAX_GYRO_NOISE_DENSITY, MAX_GYRO_RANDOM_WALK, MAX_OFFSET_M,
};
use super::{ConvertError, in_range, positive, required};
use crate::v1;

/// An aiding sensor's rate, Hz.
fn aiding_rate(field: &str, hz: f64) -> Result<f64, ConvertError> {
    in_range(field, hz, AIDING_RATE_HZ.0, AIDING_RATE_HZ.1)
}

/// A noise density or random walk: finite, in `[0, hi]` (0 lets the estimator use its floor).
fn noise(field: &str, value: f64, hi: f64) -> Result<f64, ConvertError> {
    in_range(field, value, 0.0, hi)
}

/// A sensor offset from the IMU, each component within [`MAX_OFFSET_M`].
fn offset(field: &str, v: Vector3<f64>) -> Result<Vector3<f64>, ConvertError> {
    for (axis, c) in ["x", "y", "z"].into_iter().zip(v.iter()) {
        in_range(axis, *c, -MAX_OFFSET_M, MAX_OFFSET_M).map_err(|e| e.within(field))?;
    }
    Ok(v)
}

/// Largest accepted image side, px.
const MAX_IMAGE_SIDE_PX: u32 = 16_384;
/// Accepted terrain elevation range, m (ellipsoidal).
const TERRAIN_RANGE_M: (f64, f64) = (-1_000.0, 10_000.0);

impl TryFrom<&v1::ImuConfig> for ImuConfig {
    type Error = ConvertError;
    fn try_from(c: &v1::ImuConfig) -> Result<Self, ConvertError> {
        Ok(ImuConfig {
            rate_hz: in_range("rate_hz", c.rate_hz, IMU_RATE_HZ.0, IMU_RATE_HZ.1)?,
            gyro_noise_density: noise(
                "gyro_noise_density",
                c.gyro_noise_density,
                MAX_GYRO_NOISE_DENSITY,
            )?,
            gyro_random_walk: noise("gyro_random_walk", c.gyro_random_walk, MAX_GYRO_RANDOM_WALK)?,
            accel_noise_density: noise(
                "accel_noise_density",
                c.accel_noise_density,
                MAX_ACCEL_NOISE_DENSITY,
            )?,
            accel_random_walk: noise(
                "accel_random_walk",
                c.accel_random_walk,
                MAX_ACCEL_RANDOM_WALK,
            )?,
            gyro_bias_sigma_radps: noise(
                "gyro_bias_sigma_radps",
                c.gyro_bias_sigma_radps,
                MAX_GYRO_BIAS_SIGMA_RADPS,
            )?,
            accel_bias_sigma_mps2: noise(
                "accel_bias_sigma_mps2",
                c.accel_bias_sigma_mps2,
                MAX_ACCEL_BIAS_SIGMA_MPS2,
            )?,
        })
    }
}

impl From<&ImuConfig> for v1::ImuConfig {
    fn from(c: &ImuConfig) -> Self {
        v1::ImuConfig {
            rate_hz: c.rate_hz,
            gyro_noise_density: c.gyro_noise_density,
            gyro_random_walk: c.gyro_random_walk,
            accel_noise_density: c.accel_noise_density,
            accel_random_walk: c.accel_random_walk,
            gyro_bias_sigma_radps: c.gyro_bias_sigma_radps,
            accel_bias_sigma_mps2: c.accel_bias_sigma_mps2,
        }
    }
}

impl TryFrom<&v1::GnssConfig> for GnssConfig {
    type Error = ConvertError;
    fn try_from(c: &v1::GnssConfig) -> Result<Self, ConvertError> {
        Ok(GnssConfig {
            rate_hz: aiding_rate("rate_hz", c.rate_hz)?,
            lever_arm_body_m: offset(
                "lever_arm_body_m",
                required_vector3("lever_arm_body_m", &c.lever_arm_body_m)?,
            )?,
            delay_ns: uavnav_core::s_to_ns(in_range(
                "delay_s",
                c.delay_s,
                0.0,
                super::limits::MAX_GNSS_DELAY_S,
            )?),
            altitude_reference: {
                use v1::AltitudeReference as W;
                match W::try_from(c.altitude_reference) {
                    Ok(W::Unspecified | W::Ellipsoid) => AltitudeReference::Ellipsoid,
                    Ok(W::Msl) => AltitudeReference::Msl,
                    Err(_) => {
                        return Err(ConvertError::UnknownEnum {
                            field: "altitude_reference".to_owned(),
                            value: c.altitude_reference,
                        });
                    }
                }
            },
        })
    }
}

impl TryFrom<&v1::MagConfig> for MagConfig {
    type Error = ConvertError;
    fn try_from(c: &v1::MagConfig) -> Result<Self, ConvertError> {
        Ok(MagConfig {
            rate_hz: aiding_rate("rate_hz", c.rate_hz)?,
            body_from_mag: required_quaternion("body_from_mag", &c.body_from_mag)?,
            sigma_t: positive("sigma_t", c.sigma_t, super::limits::MAX_MAG_FIELD_T)?,
        })
    }
}

impl From<&MagConfig> for v1::MagConfig {
    fn from(c: &MagConfig) -> Self {
        v1::MagConfig {
            rate_hz: c.rate_hz,
            body_from_mag: Some((&c.body_from_mag).into()),
            sigma_t: c.sigma_t,
        }
    }
}

impl TryFrom<&v1::BaroConfig> for BaroConfig {
    type Error = ConvertError;
    fn try_from(c: &v1::BaroConfig) -> Result<Self, ConvertError> {
        Ok(BaroConfig {
            rate_hz: aiding_rate("rate_hz", c.rate_hz)?,
            sigma_pressure_pa: positive("sigma_pressure_pa", c.sigma_pressure_pa, 1.0e4)?,
        })
    }
}

impl From<&BaroConfig> for v1::BaroConfig {
    fn from(c: &BaroConfig) -> Self {
        v1::BaroConfig {
            rate_hz: c.rate_hz,
            sigma_pressure_pa: c.sigma_pressure_pa,
        }
    }
}

impl From<&GnssConfig> for v1::GnssConfig {
    fn from(c: &GnssConfig) -> Self {
        v1::GnssConfig {
            rate_hz: c.rate_hz,
            lever_arm_body_m: Some((&c.lever_arm_body_m).into()),
            delay_s: uavnav_core::ns_to_s(c.delay_ns),
            altitude_reference: match c.altitude_reference {
                AltitudeReference::Ellipsoid => v1::AltitudeReference::Ellipsoid,
                AltitudeReference::Msl => v1::AltitudeReference::Msl,
            } as i32,
        }
    }
}

fn image_side(field: &str, px: u32) -> Result<u32, ConvertError> {
    if (1..=MAX_IMAGE_SIDE_PX).contains(&px) {
        Ok(px)
    } else {
        Err(ConvertError::OutOfRange {
            field: field.to_owned(),
            value: f64::from(px),
            range: format!("[1, {MAX_IMAGE_SIDE_PX}]"),
        })
    }
}

fn distortion(c: &v1::CameraConfig) -> Result<Distortion, ConvertError> {
    use v1::DistortionModel as M;
    let coeff = |name: &str, k: f64| in_range(name, k, -MAX_DISTORTION_COEFF, MAX_DISTORTION_COEFF);
    let k1 = coeff("k1", c.k1)?;
    let k2 = coeff("k2", c.k2)?;
    let p1 = coeff("p1", c.p1)?;
    let p2 = coeff("p2", c.p2)?;
    let all_zero = [k1, k2, p1, p2].iter().all(|&k| k == 0.0);
    match M::try_from(c.distortion_model) {
        Ok(M::None) => Ok(Distortion::None),
        Ok(M::RadialTangential) => Ok(Distortion::RadTan { k1, k2, p1, p2 }),
        // Unset with no coefficients unambiguously means an ideal pinhole.
        Ok(M::Unspecified) if all_zero => Ok(Distortion::None),
        _ => Err(ConvertError::UnknownEnum {
            field: "distortion_model".to_owned(),
            value: c.distortion_model,
        }),
    }
}

impl TryFrom<&v1::CameraConfig> for CameraModel {
    type Error = ConvertError;
    fn try_from(c: &v1::CameraConfig) -> Result<Self, ConvertError> {
        let width = image_side("width_px", c.width_px)?;
        let height = image_side("height_px", c.height_px)?;
        let (f_lo, f_hi) = FOCAL_RANGE_PX;
        // The principal point lies on the image, or within one image size of it.
        let (w, h) = (f64::from(width), f64::from(height));
        Ok(CameraModel {
            width,
            height,
            fx: in_range("fx_px", c.fx_px, f_lo, f_hi)?,
            fy: in_range("fy_px", c.fy_px, f_lo, f_hi)?,
            cx: in_range("cx_px", c.cx_px, -w, 2.0 * w)?,
            cy: in_range("cy_px", c.cy_px, -h, 2.0 * h)?,
            distortion: distortion(c)?,
        })
    }
}

impl TryFrom<&v1::CameraConfig> for CameraConfig {
    type Error = ConvertError;
    fn try_from(c: &v1::CameraConfig) -> Result<Self, ConvertError> {
        // The core configuration holds camera 0 only; refusing others beats silently mislabelling.
        if c.camera_id != 0 {
            return Err(ConvertError::invalid(
                "camera_id",
                format!("{} unsupported (only camera 0)", c.camera_id),
            ));
        }
        let body_from_cam = isometry(
            "body_from_cam",
            required("body_from_cam", &c.body_from_cam)?,
        )?;
        offset(
            "body_from_cam.translation_m",
            body_from_cam.translation.vector,
        )?;
        Ok(CameraConfig {
            rate_hz: aiding_rate("rate_hz", c.rate_hz)?,
            model: CameraModel::try_from(c)?,
            body_from_cam,
        })
    }
}

impl From<&CameraConfig> for v1::CameraConfig {
    fn from(c: &CameraConfig) -> Self {
        let m = &c.model;
        let (model, [k1, k2, p1, p2]) = match m.distortion {
            Distortion::None => (v1::DistortionModel::None, [0.0; 4]),
            Distortion::RadTan { k1, k2, p1, p2 } => {
                (v1::DistortionModel::RadialTangential, [k1, k2, p1, p2])
            }
        };
        v1::CameraConfig {
            camera_id: 0,
            rate_hz: c.rate_hz,
            width_px: m.width,
            height_px: m.height,
            fx_px: m.fx,
            fy_px: m.fy,
            cx_px: m.cx,
            cy_px: m.cy,
            distortion_model: model as i32,
            k1,
            k2,
            p1,
            p2,
            body_from_cam: Some((&c.body_from_cam).into()),
        }
    }
}

/// Wire profile → core; `UNSPECIFIED` means the default (ESKF).
pub fn filter_profile(field: &str, raw: i32) -> Result<FilterProfile, ConvertError> {
    use v1::FilterProfile as W;
    match W::try_from(raw) {
        Ok(W::Unspecified) => Ok(FilterProfile::default()),
        Ok(W::Eskf) => Ok(FilterProfile::Eskf),
        Ok(W::Paper) => Ok(FilterProfile::Paper),
        Err(_) => Err(ConvertError::UnknownEnum {
            field: field.to_owned(),
            value: raw,
        }),
    }
}

/// Wire airframe → core; `UNSPECIFIED` is `Airframe::Unknown`.
pub fn airframe(field: &str, raw: i32) -> Result<Airframe, ConvertError> {
    use v1::Airframe as W;
    match W::try_from(raw) {
        Ok(W::Unspecified) => Ok(Airframe::Unknown),
        Ok(W::FixedWing) => Ok(Airframe::FixedWing),
        Ok(W::Multirotor) => Ok(Airframe::Multirotor),
        Err(_) => Err(ConvertError::UnknownEnum {
            field: field.to_owned(),
            value: raw,
        }),
    }
}

impl From<Airframe> for v1::Airframe {
    fn from(a: Airframe) -> Self {
        match a {
            Airframe::Unknown => v1::Airframe::Unspecified,
            Airframe::FixedWing => v1::Airframe::FixedWing,
            Airframe::Multirotor => v1::Airframe::Multirotor,
        }
    }
}

impl From<FilterProfile> for v1::FilterProfile {
    fn from(p: FilterProfile) -> Self {
        match p {
            FilterProfile::Eskf => v1::FilterProfile::Eskf,
            FilterProfile::Paper => v1::FilterProfile::Paper,
        }
    }
}

impl TryFrom<&v1::VehicleConfig> for VehicleConfig {
    type Error = ConvertError;
    fn try_from(c: &v1::VehicleConfig) -> Result<Self, ConvertError> {
        let imu = ImuConfig::try_from(required("imu", &c.imu)?).map_err(|e| e.within("imu"))?;
        let gnss = c
            .gnss
            .as_ref()
            .map(GnssConfig::try_from)
            .transpose()
            .map_err(|e| e.within("gnss"))?;
        let camera = c
            .camera
            .as_ref()
            .map(CameraConfig::try_from)
            .transpose()
            .map_err(|e| e.within("camera"))?;
        let mag = c
            .mag
            .as_ref()
            .map(MagConfig::try_from)
            .transpose()
            .map_err(|e| e.within("mag"))?;
        let baro = c
            .baro
            .as_ref()
            .map(BaroConfig::try_from)
            .transpose()
            .map_err(|e| e.within("baro"))?;
        let (lo, hi) = TERRAIN_RANGE_M;
        Ok(VehicleConfig {
            imu,
            gnss,
            mag,
            baro,
            camera,
            terrain_elevation_m: in_range("terrain_elevation_m", c.terrain_elevation_m, lo, hi)?,
            profile: filter_profile("profile", c.profile)?,
            airframe: airframe("airframe", c.airframe)?,
        })
    }
}

impl From<&VehicleConfig> for v1::VehicleConfig {
    fn from(c: &VehicleConfig) -> Self {
        v1::VehicleConfig {
            imu: Some((&c.imu).into()),
            gnss: c.gnss.as_ref().map(Into::into),
            camera: c.camera.as_ref().map(Into::into),
            mag: c.mag.as_ref().map(Into::into),
            baro: c.baro.as_ref().map(Into::into),
            terrain_elevation_m: c.terrain_elevation_m,
            profile: v1::FilterProfile::from(c.profile) as i32,
            airframe: v1::Airframe::from(c.airframe) as i32,
        }
    }
}
