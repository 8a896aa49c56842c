//! The seam between the service and the estimation code: one [`Engine`] per vehicle.
//!
//! Actors only talk to this trait, so the fusion implementation behind it is swapped in one file.
//! The product implementation ([`crate::runner_engine`]) wraps `uavnav_runner::VehicleRunner`
//! (vision front end + estimator); tests may plug a scripted engine through [`EngineFactory`].

use std::any::Any;
use std::sync::Arc;

use uavnav_core::{SensorEvent, VehicleConfig};
use uavnav_proto::v1 as pb;

use crate::hub::Pose;

/// An error reported by an engine for one input; the actor counts it and goes on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct EngineError(pub String);

/// What an engine says about itself; the actor adds the input statistics to make the health report.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EngineHealth {
    /// Operating mode.
    pub mode: pb::EstimatorMode,
    /// Sensor time of the newest estimate, ns (0 = none yet).
    pub t_ns: i64,
    /// Latest innovation test ratios.
    pub innovation: pb::InnovationRatios,
    /// Latest vision quality (None without camera or before the first frame).
    pub vision: Option<pb::VisionQuality>,
    /// GNSS measurements rejected by the innovation gate so far.
    pub gnss_gate_rejections: u64,
    /// Vision measurements rejected by the innovation gate so far.
    pub vision_gate_rejections: u64,
    /// Inputs the engine refused or dropped (estimator validation, behind its horizon).
    pub engine_dropped: u64,
    /// Estimator restarts after a divergence (a non-finite state, or the paper profile's tilt
    /// check) so far.
    pub divergence_resets: u64,
    /// IMU samples the estimator found clipped (at the sensor's range) so far.
    pub imu_clipped: u64,
}

/// The result of a vision job, handed back to the engine that created it.
pub type VisionResult = Box<dyn Any + Send>;

/// CPU work for one camera frame, run on the vision pool.
pub type VisionWork = Box<dyn FnOnce() -> VisionResult + Send>;

/// What is wrong with a camera frame that passed ingest (its header was good) but whose image
/// the vision job could not use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameFailureKind {
    /// The compressed body does not decode.
    Corrupt,
    /// The decoded size is not the configured camera's.
    Size,
}

/// A camera frame the vision job refused for a fault of the image itself (not of the scene).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameFailure {
    /// The frame's time, ns.
    pub t_ns: i64,
    /// What is wrong.
    pub kind: FrameFailureKind,
    /// The decoder's words.
    pub reason: String,
}

/// What one call produced: poses (`ingest_wall_ns` unset: the actor fills it in), possibly a
/// vision job to run on the pool, and, from [`Engine::finish_frame`], a frame refused as bad.
#[derive(Default)]
pub struct EngineStep {
    /// Poses in time order.
    pub poses: Vec<Pose>,
    /// Vision work to run; its result goes back through [`Engine::finish_frame`].
    pub work: Option<VisionWork>,
    /// The finished frame's image was bad (counted by the actor in health and metrics).
    pub frame_failure: Option<FrameFailure>,
}

impl std::fmt::Debug for EngineStep {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EngineStep")
            .field("poses", &self.poses.len())
            .field("work", &self.work.is_some())
            .field("frame_failure", &self.frame_failure)
            .finish()
    }
}

/// One vehicle's estimator, driven by its actor in timestamp order (ties: IMU, GNSS, camera).
/// Deterministic. At most one vision job is out at a time; the engine holds later inputs itself.
pub trait Engine: Send + 'static {
    /// Fuses one input.
    fn push(&mut self, event: SensorEvent) -> Result<EngineStep, EngineError>;
    /// [`Engine::push`] appending the poses to `poses` (the actor's outbox) and returning the
    /// vision work: no allocation per input for engines that override it.
    fn push_into(
        &mut self,
        event: SensorEvent,
        poses: &mut Vec<Pose>,
    ) -> Result<Option<VisionWork>, EngineError> {
        let step = self.push(event)?;
        poses.extend(step.poses);
        Ok(step.work)
    }
    /// Hands back the result of the vision job the engine produced last.
    fn finish_frame(&mut self, done: VisionResult) -> EngineStep;
    /// Current self-assessment.
    fn health(&self) -> EngineHealth;
    /// Forgets all state (the configuration is kept).
    fn reset(&mut self);
    /// Inputs held behind the vision job that is out (the actor stops taking input while this is
    /// large, so that a fast feed waits for vision instead of outrunning it).
    fn backlog(&self) -> usize {
        0
    }
    /// The vision job that is out will never come back (e.g. the pool shut down): give up on it
    /// and release what it held.
    fn abandon_job(&mut self) -> EngineStep {
        EngineStep::default()
    }
}

/// Builds engines for new vehicles and for reconfigured ones.
pub trait EngineFactory: Send + Sync + 'static {
    /// A fresh engine for a vehicle with this configuration.
    fn create(&self, config: &VehicleConfig) -> Box<dyn Engine>;
}

impl std::fmt::Debug for dyn EngineFactory {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("EngineFactory")
    }
}

/// A shared factory.
pub type SharedFactory = Arc<dyn EngineFactory>;

/// The product factory (the estimator runner with default parameters).
pub fn default_factory() -> SharedFactory {
    Arc::new(crate::runner_engine::RunnerFactory::default())
}
