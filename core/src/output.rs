//! The estimator's output vocabulary, shared by everything that produces, carries or reads poses:
//! [`PoseOutput`] (one estimate per IMU sample), its [`AidingFlags`], the filter [`Mode`] and the
//! per-pose health summary [`PoseHealth`]. The estimator fills them; `uavnav-proto` converts them to
//! and from the wire (lossless); `uavnav-dataset` writes them as CSV/TUM; `uavnav-report` scores them.

use nalgebra::{UnitQuaternion, Vector3};

use crate::Lla;

/// Which aiding sources contributed recently (within the aid timeout).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct AidingFlags {
    /// GNSS position fused recently.
    pub gnss_pos: bool,
    /// GNSS velocity fused recently.
    pub gnss_vel: bool,
    /// Vision rotation fused recently.
    pub vision_rot: bool,
    /// Vision translation fused recently.
    pub vision_trans: bool,
}

/// One pose estimate, at an IMU sample time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseOutput {
    /// Time, ns (the IMU sample's).
    pub t_ns: i64,
    /// Geodetic position of the body (IMU) origin.
    pub lla: Lla,
    /// Position in the local NED frame, m.
    pub pos_ned_m: Vector3<f64>,
    /// Velocity, NED, m/s.
    pub vel_ned_mps: Vector3<f64>,
    /// Rotation of body vectors into NED.
    pub nav_from_body: UnitQuaternion<f64>,
    /// Roll, pitch, yaw (ZYX), rad.
    pub euler_rad: Vector3<f64>,
    /// 1-σ position, NED, m.
    pub sigma_pos_ned_m: Vector3<f64>,
    /// 1-σ velocity, NED, m/s.
    pub sigma_vel_mps: Vector3<f64>,
    /// 1-σ roll, pitch, yaw, rad.
    pub sigma_att_rad: Vector3<f64>,
    /// Estimated gyro bias, body, rad/s (the paper profile: the bias its GNSS tilt windows learnt,
    /// `paper::gnss_tilt`, zero without them).
    pub gyro_bias_radps: Vector3<f64>,
    /// Estimated accelerometer bias, m/s² (zero for the paper profile).
    pub accel_bias_mps2: Vector3<f64>,
    /// Filter health at this output (the full snapshot: `uavnav_estimator::Estimator::health`).
    pub health: PoseHealth,
    /// Recently fused sources.
    pub aiding: AidingFlags,
}

/// Where the filter's heading came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum HeadingSource {
    /// Not known yet: the yaw σ is that of a uniform heading and the yaw is not corrected.
    #[default]
    Unknown,
    /// The magnetometer (against the world magnetic model's declination).
    Magnetometer,
    /// The yaw estimator (Gaussian sum fed by GNSS velocity and the IMU).
    YawEstimator,
    /// The GNSS course (a vehicle declared a fixed wing, or `course_heading`).
    Course,
}

/// The compass's lifecycle as health reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum MagStatus {
    /// No compass sample yet, or none used (not fitted, or the `paper` profile, which reads none).
    #[default]
    Off,
    /// Aligning or fusing its heading.
    Active,
    /// Stopped for the flight: the sensor reads a dead field.
    StoppedDead,
    /// Stopped for the flight: its heading kept contradicting the converged yaw bank.
    StoppedContradicted,
}

/// The in-flight compass calibration (`eskf`; eq. M2 of `uavnav_estimator::aid_sources::
/// mag_calibration`) as health reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum MagCalibrationStatus {
    /// Not started: no compass, not yet in flight (3 m above the lowest height), or the tilt is
    /// not known yet.
    #[default]
    Off,
    /// Learning the compass's offset; the compass is used as it reads (once the offset is
    /// known, with its heading σ widened by the error the offset makes).
    Learning,
    /// The learnt offset is subtracted from every compass sample.
    Applied,
}

/// Where the heading comes from, and the compass's state: what a user needs to trust the yaw.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HeadingHealth {
    /// The heading's source now (`Unknown` until one aligns it).
    pub source: HeadingSource,
    /// The compass's lifecycle.
    pub mag: MagStatus,
    /// Compass samples judged disturbed (strength or inclination off the model's or the
    /// compass's own typical), never fused.
    pub mag_disturbed: u64,
    /// The in-flight compass calibration's state.
    pub mag_calibration: MagCalibrationStatus,
    /// The compass offset it has learnt, body axes, T (zero while off; subtracted from the
    /// compass only once applied).
    pub mag_offset_t: [f64; 3],
    /// Its last test ratio (NIS over the gate; above 1 the sample was rejected), computed for
    /// every sample it sees.
    pub mag_calibration_test_ratio: f64,
    /// Restarts of the calibration: after a run of rejections, or because what it learnt was
    /// not a compass in the Earth's field (never acted on).
    pub mag_calibration_restarts: u32,
}

/// What the filter is currently running on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Mode {
    /// Waiting for enough data to align.
    #[default]
    Initialising,
    /// GNSS fused recently.
    Nominal,
    /// No recent GNSS; vision carries the solution.
    GnssDeniedVision,
    /// No recent aiding at all: inertial coasting.
    InertialOnly,
    /// Non-finite state or covariance beyond the divergence bounds.
    Diverged,
    /// Started without a GNSS fix and nothing has given a position since: roll and pitch are
    /// held by gravity, the heading by the magnetometer when there is one (`eskf`; the `paper`
    /// profile reads none, and its heading stays unknown); position and
    /// velocity are not estimated (absent on the wire and empty in `poses.csv`; the fields of
    /// [`PoseOutput`] then hold the filter's internal hold point and mean nothing).
    AttitudeOnly,
}

impl Mode {
    /// Every mode, in wire order.
    pub const ALL: [Mode; 6] = [
        Mode::Initialising,
        Mode::Nominal,
        Mode::GnssDeniedVision,
        Mode::InertialOnly,
        Mode::Diverged,
        Mode::AttitudeOnly,
    ];

    /// Whether position and velocity are estimated in this mode (all but
    /// [`Mode::AttitudeOnly`]).
    pub fn has_position(self) -> bool {
        self != Mode::AttitudeOnly
    }

    /// Name for CSV columns and logs.
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Initialising => "initialising",
            Mode::Nominal => "nominal",
            Mode::GnssDeniedVision => "gnss_denied_vision",
            Mode::InertialOnly => "inertial_only",
            Mode::Diverged => "diverged",
            Mode::AttitudeOnly => "attitude_only",
        }
    }
}

/// One aiding source at one output: its latest test ratio and counts (the estimator's innovation
/// diagnostics without the innovation vectors).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SourceSummary {
    /// Latest test ratio (normalised innovation squared over the gate; > 1 = rejected).
    pub test_ratio: f64,
    /// Measurements fused so far.
    pub fused: u64,
    /// Measurements rejected by the gate so far.
    pub rejected: u64,
}

/// Health at one output: the mode, the counters and each source's summary. Every IMU sample gives
/// an output, so this stays small (no innovation vectors, no covariance diagonal); the estimator's
/// full snapshot is `uavnav_estimator::Health`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseHealth {
    /// Current mode.
    pub mode: Mode,
    /// GNSS position.
    pub gnss_pos: SourceSummary,
    /// GNSS velocity.
    pub gnss_vel: SourceSummary,
    /// Vision relative rotation (paper profile: the pseudo-attitude).
    pub vision_rot: SourceSummary,
    /// Vision translation (direction / metric; paper: eq. 35 velocity).
    pub vision_trans: SourceSummary,
    /// Magnetometer heading.
    pub mag: SourceSummary,
    /// Barometric height.
    pub baro: SourceSummary,
    /// Roll and pitch from the GNSS acceleration (`paper` profile, our addition; never fused by
    /// `eskf`, whose GNSS velocity update carries the same information).
    pub gnss_tilt: SourceSummary,
    /// Position hold (`eskf` without position aiding: "within `noaid_pos_sigma_m` of where it
    /// started", our addition; PX4's fake position). Its test ratio tells how far the vehicle
    /// has travelled against what the hold assumes.
    pub position_hold: SourceSummary,
    /// Inputs refused by validation (NaN, time going backwards, …).
    pub inputs_rejected: u64,
    /// Measurements that arrived behind the fusion horizon and were dropped.
    pub late_dropped: u64,
    /// Vision measurements dropped for lack of a clone at their frame-0 time.
    pub vision_no_clone: u64,
    /// GNSS inflate-and-fuse resets.
    pub gnss_resets: u32,
}
