//! Filter health: [`Health`], the full snapshot (mode, per-source innovation diagnostics with test
//! ratios, rejection counts, the covariance diagonal) that `Estimator::health` returns, and
//! [`PoseHealth`], its summary carried by every output (never logged; defined in
//! `uavnav_core::output` with [`Mode`], as are the conversions from the snapshot here).

pub use uavnav_core::output::{
    HeadingHealth, HeadingSource, MagCalibrationStatus, MagStatus, Mode, PoseHealth, SourceSummary,
};

use crate::aid_sources::InnovDiag;

/// Health of the estimator: the full snapshot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Health {
    /// Current mode.
    pub mode: Mode,
    /// GNSS position diagnostics.
    pub gnss_pos: InnovDiag,
    /// GNSS velocity diagnostics.
    pub gnss_vel: InnovDiag,
    /// Vision relative-rotation diagnostics (paper profile: the pseudo-attitude).
    pub vision_rot: InnovDiag,
    /// Vision translation diagnostics (direction / metric; paper: eq. 35 velocity).
    pub vision_trans: InnovDiag,
    /// Magnetometer heading diagnostics (computed even when not fused).
    pub mag: InnovDiag,
    /// Barometric height diagnostics (fused only without GNSS height).
    pub baro: InnovDiag,
    /// GNSS-acceleration tilt diagnostics (`paper` profile, our addition: computed at every
    /// window, fused or not).
    pub gnss_tilt: InnovDiag,
    /// Position hold (`eskf` without position aiding).
    pub position_hold: InnovDiag,
    /// Heading resets from the yaw estimator after alignment.
    pub yaw_resets: u32,
    /// The heading's source and the compass's state.
    pub heading: HeadingHealth,
    /// Filter restarts after a detected divergence (paper profile: roll or pitch far from the
    /// accelerometer's tilt).
    pub divergence_resets: u32,
    /// Inputs refused by validation (NaN, time going backwards, …).
    pub inputs_rejected: u64,
    /// IMU gaps longer than `EstimatorParams::max_imu_gap_ns` that the estimator bridged instead of
    /// restarting (`EstimatorParams::max_bridge_gap_ns`).
    pub imu_gaps_bridged: u64,
    /// Measurements that arrived behind the fusion horizon and were dropped.
    pub late_dropped: u64,
    /// Vision measurements dropped for lack of a clone at their frame-0 time.
    pub vision_no_clone: u64,
    /// GNSS inflate-and-fuse resets.
    pub gnss_resets: u32,
    /// IMU intervals with a clipped (saturated) accelerometer or gyro axis (`eskf`; handled by
    /// extra process noise).
    pub imu_clipped: u64,
    /// The IMU noise the `eskf` measured over about the last second (from the change between
    /// consecutive samples; `eskf::imu_noise`), over the configured noise density, as a σ ratio:
    /// gyro, accelerometer. 1 is as configured: with datasheet densities a multirotor's
    /// vibration shows as 3–20 (the shared ArduPilot copters vibrate 10–20× their datasheet;
    /// their folders state in-flight densities instead, and read 0.3–2.6 as medians), and a
    /// 10 Hz log of a manoeuvring aircraft likewise (the shared plane_E: gyro 9.4, accelerometer
    /// 3.9). The filter's process noise follows the larger of the two
    /// (`Eskf::observed_imu_noise`). `None` for `paper` or before the first interval.
    pub imu_noise_ratio: Option<[f64; 2]>,
    /// The GNSS velocity's delay in use, s (`eskf`: the configured one until eq. L1 learns
    /// another, `crate::gnss_delay`; `None` for `paper`, which uses the configured one).
    pub gnss_velocity_delay_s: Option<f64>,
    /// Covariance diagonal of the error state (layout: [`crate::state::STATE_LABELS`] for `eskf`;
    /// the paper profile fills p, v, attitude and leaves the rest 0).
    pub cov_diag: [f64; crate::state::N],
}

impl Default for Health {
    fn default() -> Self {
        Self {
            mode: Mode::Initialising,
            gnss_pos: InnovDiag::new(),
            gnss_vel: InnovDiag::new(),
            vision_rot: InnovDiag::new(),
            vision_trans: InnovDiag::new(),
            mag: InnovDiag::new(),
            baro: InnovDiag::new(),
            gnss_tilt: InnovDiag::new(),
            position_hold: InnovDiag::new(),
            yaw_resets: 0,
            heading: HeadingHealth::default(),
            divergence_resets: 0,
            inputs_rejected: 0,
            imu_gaps_bridged: 0,
            late_dropped: 0,
            vision_no_clone: 0,
            gnss_resets: 0,
            imu_clipped: 0,
            imu_noise_ratio: None,
            gnss_velocity_delay_s: None,
            cov_diag: [0.0; crate::state::N],
        }
    }
}

impl From<&InnovDiag> for SourceSummary {
    fn from(d: &InnovDiag) -> Self {
        Self {
            test_ratio: d.test_ratio,
            fused: d.fused,
            rejected: d.rejected,
        }
    }
}

impl From<&Health> for PoseHealth {
    fn from(h: &Health) -> Self {
        Self {
            mode: h.mode,
            gnss_pos: (&h.gnss_pos).into(),
            gnss_vel: (&h.gnss_vel).into(),
            vision_rot: (&h.vision_rot).into(),
            vision_trans: (&h.vision_trans).into(),
            mag: (&h.mag).into(),
            baro: (&h.baro).into(),
            gnss_tilt: (&h.gnss_tilt).into(),
            position_hold: (&h.position_hold).into(),
            inputs_rejected: h.inputs_rejected,
            late_dropped: h.late_dropped,
            vision_no_clone: h.vision_no_clone,
            gnss_resets: h.gnss_resets,
        }
    }
}
