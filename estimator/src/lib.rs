//! # uavnav-estimator
//!
//! Pure, synchronous, deterministic fusion of IMU, GNSS and camera egomotion (no I/O, no clock:
//! time comes with the data). Two profiles behind one [`Estimator`]:
//! - `eskf` (default): error-state EKF at a delayed fusion horizon with an output predictor;
//! - `paper`: the paper's three EKFs (section V, Fig. 1) as the baseline.
//!
//! | module | what it holds |
//! |---|---|
//! | [`estimator`] | [`Estimator`]: validation, profile dispatch, `push_*`, `motion_prior`, `reset` |
//! | [`validate`] | [`InputError`] and the input checks (rejected inputs never touch the filter) |
//! | [`params`] | [`EstimatorParams`] with documented defaults |
//! | [`eskf`] | the error-state EKF orchestration (horizon stepping, events, outputs) |
//! | [`state`] | nominal state, error-state layout, injection, stochastic clones |
//! | [`prediction`] | strapdown mechanization (eqs. 29–31) and block-sparse covariance prediction |
//! | [`aid_sources`] | GNSS position (eq. 32), GNSS velocity (eq. 33), magnetometer heading (eq. M1) and in-flight compass calibration (eq. M2), vision; gated updates |
//! | [`buffer`] | the delayed-measurement buffer |
//! | [`gnss_delay`] | the GNSS velocity's own delay learnt from the data (eq. L1) |
//! | [`output_predictor`] | a pose for every IMU sample from the delayed filter |
//! | [`init`] | alignment without operator input |
//! | [`yaw_estimator`] | heading without a magnetometer: a Gaussian sum of yaw hypotheses fed by GNSS velocity |
//! | [`motion_prior`] | the prior handed to the vision front end |
//! | [`health`] | [`Health`] (full snapshot) and its summary [`PoseHealth`] (with every output; defined in `uavnav_core::output` with [`Mode`]) |
//! | [`output`] | Euler σ and eq. (31)'s `J`, the geodetic linearizer ([`PoseOutput`] and [`AidingFlags`] are `uavnav_core::output`'s) |
//! | [`paper`] | the paper's GPS-IMU, VIDEO-IMU(1) and VIDEO-IMU(2) filters |

pub mod aid_sources;
pub mod buffer;
pub mod eskf;
pub mod estimator;
pub mod gnss_delay;
pub mod health;
pub mod init;
pub mod motion_prior;
pub mod output;
pub mod output_predictor;
pub mod paper;
pub mod params;
pub mod prediction;
pub mod state;
pub mod validate;
pub mod yaw_estimator;

pub use estimator::Estimator;
pub use health::{Health, Mode, PoseHealth, SourceSummary};
pub use output::{AidingFlags, PoseOutput};
pub use params::EstimatorParams;
pub use validate::InputError;
