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

/// The antenna velocity of a GNSS solution in local NED. The vertical component is optional on its
/// own: MAVLink `GPS_RAW_INT`-style sources give ground speed and course only.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssVelocity {
    /// North velocity, m/s.
    pub north_mps: f64,
    /// East velocity, m/s.
    pub east_mps: f64,
    /// Down velocity, m/s, when the receiver gives it.
    pub down_mps: Option<f64>,
    /// 1-σ error per axis, m/s.
    pub sigma_mps: f64,
}

impl GnssVelocity {
    /// A full 3-D velocity.
    pub fn ned(v_ned_mps: Vector3<f64>, sigma_mps: f64) -> Self {
        Self {
            north_mps: v_ned_mps.x,
            east_mps: v_ned_mps.y,
            down_mps: Some(v_ned_mps.z),
            sigma_mps,
        }
    }

    /// The 3-D velocity when all three components are known.
    pub fn ned_mps(&self) -> Option<Vector3<f64>> {
        self.down_mps
            .map(|d| Vector3::new(self.north_mps, self.east_mps, d))
    }

    /// The horizontal velocity (north, east), m/s.
    pub fn horizontal_mps(&self) -> nalgebra::Vector2<f64> {
        nalgebra::Vector2::new(self.north_mps, self.east_mps)
    }
}

/// One GNSS receiver solution at the antenna phase centre. `t_ns` is the stamp as the source gives
/// it; the solution was valid at `t_ns − GnssConfig::delay_ns` (the estimator applies the delay, so
/// every transport and file format is treated alike).
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
    /// Antenna velocity, when the receiver gives one (a ROS `NavSatFix` or a position-only
    /// receiver does not).
    pub velocity: Option<GnssVelocity>,
    /// 1-σ horizontal position error, m.
    pub sigma_h_m: f64,
    /// 1-σ vertical position error, m.
    pub sigma_v_m: f64,
    /// Fix quality.
    pub fix_type: FixType,
    /// Satellites used (0 when unknown).
    pub num_sats: u32,
}

/// One magnetometer sample: the calibrated (hard- and soft-iron corrected) flux density in the
/// magnetometer frame (`MagConfig::body_from_mag` rotates it into the body frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MagSample {
    /// Sample time, ns.
    pub t_ns: i64,
    /// Magnetic flux density, magnetometer frame, tesla.
    pub field_t: Vector3<f64>,
}

/// One barometer sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaroSample {
    /// Sample time, ns.
    pub t_ns: i64,
    /// Static pressure, Pa.
    pub pressure_pa: f64,
    /// The sensor's own temperature, °C, when given (not the air's: it warms during a flight).
    pub temperature_degc: Option<f64>,
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
    /// A magnetometer sample.
    Mag(MagSample),
    /// A barometer sample.
    Baro(BaroSample),
    /// A camera frame.
    Camera(CameraFrame),
}

impl SensorEvent {
    /// The event's time of validity, ns.
    pub fn t_ns(&self) -> i64 {
        match self {
            SensorEvent::Imu(s) => s.t_ns,
            SensorEvent::Gnss(g) => g.t_ns,
            SensorEvent::Mag(m) => m.t_ns,
            SensorEvent::Baro(b) => b.t_ns,
            SensorEvent::Camera(c) => c.t_ns,
        }
    }

    /// The tie-break rank among events with the same time: IMU, GNSS, magnetometer, barometer,
    /// camera (the dataset reader and the service's reorder window both order by `(t_ns, rank)`).
    pub fn rank(&self) -> u8 {
        match self {
            SensorEvent::Imu(_) => 0,
            SensorEvent::Gnss(_) => 1,
            SensorEvent::Mag(_) => 2,
            SensorEvent::Baro(_) => 3,
            SensorEvent::Camera(_) => 4,
        }
    }
}
