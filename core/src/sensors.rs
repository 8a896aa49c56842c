//! Raw sensor samples as they enter the estimator, whatever transport or file they came from.

use nalgebra::Vector3;

/// One IMU sample in the body (FRD = IMU) frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    /// Sample time, ns.
    pub t_ns: i64,
    /// Angular rate of body w.r.t. inertial space, body frame, rad/s.
    pub gyro_radps: Vector3<f64>,
    /// Specific force (non-gravitational acceleration), body frame, m/s². At rest, level: (0, 0, -g).
    pub accel_mps2: Vector3<f64>,
}

/// GNSS fix quality.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum FixType {
    /// No position.
    #[default]
    None,
    /// 2-D fix (altitude not trusted).
    Fix2d,
    /// 3-D single-point fix.
    Fix3d,
    /// Differential / SBAS.
    Dgps,
    /// RTK float.
    RtkFloat,
    /// RTK fixed.
    RtkFixed,
}

/// One GNSS receiver solution at the antenna phase centre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssFix {
    /// Time of validity, ns.
    pub t_ns: i64,
    /// Geodetic latitude, degrees (WGS84).
    pub lat_deg: f64,
    /// Longitude, degrees (WGS84).
    pub lon_deg: f64,
    /// Height above the WGS84 ellipsoid, m.
    pub alt_m: f64,
    /// Antenna velocity in local NED, m/s.
    pub vel_ned_mps: Vector3<f64>,
    /// 1-σ horizontal position error, m.
    pub sigma_h_m: f64,
    /// 1-σ vertical position error, m.
    pub sigma_v_m: f64,
    /// 1-σ velocity error per axis, m/s.
    pub sigma_vel_mps: f64,
    /// Fix quality.
    pub fix_type: FixType,
    /// Satellites used (0 when unknown).
    pub num_sats: u32,
}

/// Compressed image encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ImageFormat {
    /// JPEG (baseline or progressive).
    Jpeg,
    /// PNG.
    Png,
}

impl ImageFormat {
    /// The lowercase name used in file extensions and Foxglove `CompressedImage.format`.
    pub fn as_str(self) -> &'static str {
        match self {
            ImageFormat::Jpeg => "jpeg",
            ImageFormat::Png => "png",
        }
    }

    /// Guesses the format from magic bytes.
    pub fn sniff(data: &[u8]) -> Option<Self> {
        if data.starts_with(&[0xFF, 0xD8]) {
            Some(ImageFormat::Jpeg)
        } else if data.starts_with(&[0x89, b'P', b'N', b'G']) {
            Some(ImageFormat::Png)
        } else {
            None
        }
    }
}

/// One compressed camera frame. The pixels are decoded by the vision crate, not here.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraFrame {
    /// Exposure mid-point time, ns.
    pub t_ns: i64,
    /// Camera index on the vehicle (0 = `cam0`).
    pub camera_id: u32,
    /// Encoding of `data`.
    pub format: ImageFormat,
    /// The compressed bytes, shared cheaply between stages.
    pub data: std::sync::Arc<[u8]>,
}

/// One item of a vehicle's time-ordered sensor stream.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorEvent {
    /// An IMU sample.
    Imu(ImuSample),
    /// A GNSS fix.
    Gnss(GnssFix),
    /// A camera frame.
    Camera(CameraFrame),
}

impl SensorEvent {
    /// The event's time of validity, ns.
    pub fn t_ns(&self) -> i64 {
        match self {
            SensorEvent::Imu(s) => s.t_ns,
            SensorEvent::Gnss(g) => g.t_ns,
            SensorEvent::Camera(c) => c.t_ns,
        }
    }
}
