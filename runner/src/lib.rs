//! # uavnav-runner
//!
//! One vehicle's pipeline — the vision front end feeding the estimator — with one ordering rule
//! that makes the output identical whether vision runs inline (`uavnav estimate`) or on a worker
//! pool in the service (`uavnavd`). Pure and synchronous.
//!
//! | item | role |
//! |---|---|
//! | [`VehicleRunner`] | owns the [`Estimator`] and the vision [`FrontEnd`]; `push` events in time order |
//! | [`VisionJob`] | a frame plus the front end and its prior, `Send`: run it anywhere, hand back [`VisionDone`] |
//! | [`RunnerParams`] | the vision delay, the estimator and vision parameters, sensor switches |
//! | [`VisionStats`] | what the last vision result looked like, for health |
//!
//! ## The ordering rule
//! A camera frame at `t1` starts a vision job with the estimator's [`MotionPrior`] at that point of
//! the stream. Its result is handed to the estimator exactly before the first event with
//! `t ≥ t1 + vision_delay_ns`. While a job is out, events at or after its deadline — and any camera
//! frame, since the front end is busy — are held, in order, and replayed when the job comes back.
//! The estimator fuses the egomotion at its own time behind its fusion horizon, so the delay only
//! sets when the pose stream learns of it; `vision_delay_ns` must stay below the estimator's
//! `fusion_delay_ns`.

mod runner;

pub use runner::{
    DEFAULT_MAX_HELD_EVENTS, DEFAULT_VISION_DELAY_NS, RunnerError, RunnerParams, Step,
    VehicleRunner, VisionDone, VisionJob, VisionStats,
};
#[doc(no_inline)]
pub use uavnav_core::MotionPrior;
pub use uavnav_estimator::{Estimator, EstimatorParams, Health, Mode, PoseHealth, PoseOutput};
pub use uavnav_vision::{FrontEnd, NoMeasurement, VisionParams};
