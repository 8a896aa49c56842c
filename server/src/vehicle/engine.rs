//! The seam between the service and the estimation code: one [`Engine`] per vehicle.
//!
//! Actors only talk to this trait, so the fusion implementation behind it is swapped in one file.
//! The product implementation ([`crate::vehicle::runner_engine`]) wraps
//! `uavnav_runner::VehicleRunner` (vision front end + estimator); tests may plug a scripted engine
//! through [`EngineFactory`].
//!
//! An [`Engine`] names the type its vision jobs return ([`Engine::Vision`]); [`boxed`] pairs it
//! with its outstanding job ([`VehicleEngine`], what the actor drives), so a job's result goes
//! back to its engine typed, with no downcast that could silently fail.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

use tokio::sync::oneshot;

use uavnav_core::{SensorEvent, VehicleConfig};
use uavnav_proto::v1 as pb;

use crate::output::hub::Pose;

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
    /// IMU gaps the estimator bridged instead of restarting so far.
    pub imu_gaps_bridged: u64,
    /// The GNSS velocity's delay in use, s (`eskf`: learnt from the data).
    pub gnss_velocity_delay_s: Option<f64>,
    /// Where the heading comes from and the compass's state (None from an engine that cannot
    /// tell).
    pub heading: Option<pb::HeadingStatus>,
    /// The IMU noise measured over the configured (None from an engine that does not measure it).
    pub imu_noise: Option<pb::ImuNoise>,
}

/// CPU work for one camera frame, run on the vision pool; its result `V` goes back to the engine
/// that made it ([`Engine::finish_frame`]).
pub type VisionWork<V> = Box<dyn FnOnce() -> V + Send>;

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
pub struct EngineStep<V> {
    /// Poses in time order.
    pub poses: Vec<Pose>,
    /// Vision work to run; its result goes back through [`Engine::finish_frame`].
    pub work: Option<VisionWork<V>>,
    /// The finished frame's image was bad (counted by the actor in health and metrics).
    pub frame_failure: Option<FrameFailure>,
}

impl<V> Default for EngineStep<V> {
    fn default() -> Self {
        Self {
            poses: Vec::new(),
            work: None,
            frame_failure: None,
        }
    }
}

impl<V> std::fmt::Debug for EngineStep<V> {
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
    /// What this engine's vision jobs hand back: typed end to end, so a job's result can only
    /// ever reach an engine of the kind that made it.
    type Vision: Send + 'static;
    /// Fuses one input.
    fn push(&mut self, event: SensorEvent) -> Result<EngineStep<Self::Vision>, EngineError>;
    /// [`Engine::push`] appending the poses to `poses` (the actor's outbox) and returning the
    /// vision work: no allocation per input for engines that override it.
    fn push_into(
        &mut self,
        event: SensorEvent,
        poses: &mut Vec<Pose>,
    ) -> Result<Option<VisionWork<Self::Vision>>, EngineError> {
        let step = self.push(event)?;
        poses.extend(step.poses);
        Ok(step.work)
    }
    /// Hands back the result of the vision job the engine produced last.
    fn finish_frame(&mut self, done: Self::Vision) -> EngineStep<Self::Vision>;
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
    fn abandon_job(&mut self) -> EngineStep<Self::Vision> {
        EngineStep::default()
    }
}

/// A vision job ready for the pool: it runs the engine's work and hands the result back to
/// that engine ([`VehicleEngine::poll_vision`]).
pub type PoolJob = Box<dyn FnOnce() + Send>;

/// An [`EngineStep`] as the actor sees it: the vision work already wired to its engine.
#[derive(Default)]
pub struct ActorStep {
    /// Poses in time order.
    pub poses: Vec<Pose>,
    /// The job to send to the pool.
    pub job: Option<PoolJob>,
    /// The finished frame's image was bad.
    pub frame_failure: Option<FrameFailure>,
}

impl std::fmt::Debug for ActorStep {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ActorStep")
            .field("poses", &self.poses.len())
            .field("job", &self.job.is_some())
            .field("frame_failure", &self.frame_failure)
            .finish()
    }
}

/// How the outstanding vision job ended.
#[derive(Debug)]
pub enum VisionOutcome {
    /// Its result went back to the engine, which made this step.
    Done(ActorStep),
    /// It never came back (it panicked): the engine still waits for it.
    Lost,
}

/// What the actor drives: any [`Engine`] together with its outstanding vision job. Object-safe,
/// so that the factory can hand out any engine; the job's result type stays the engine's own.
pub trait VehicleEngine: Send {
    /// [`Engine::push_into`]; the vision work comes back wired as a pool job.
    fn push_into(
        &mut self,
        event: SensorEvent,
        poses: &mut Vec<Pose>,
    ) -> Result<Option<PoolJob>, EngineError>;
    /// Whether a vision job is out.
    fn vision_pending(&self) -> bool;
    /// Waits for the outstanding job and hands its result to the engine (pending forever when no
    /// job is out).
    fn poll_vision(&mut self, cx: &mut Context<'_>) -> Poll<VisionOutcome>;
    /// The job that is out will never run (the pool refused it): [`Engine::abandon_job`].
    fn abandon_job(&mut self) -> ActorStep;
    /// [`Engine::health`].
    fn health(&self) -> EngineHealth;
    /// [`Engine::reset`], forgetting the outstanding job.
    fn reset(&mut self);
    /// [`Engine::backlog`].
    fn backlog(&self) -> usize;
}

/// An engine and the receiving end of its outstanding vision job.
struct Driven<E: Engine> {
    engine: E,
    pending: Option<oneshot::Receiver<E::Vision>>,
}

impl<E: Engine> Driven<E> {
    /// Wires `work` to hand its result back here. The engine contract is one job at a time: a
    /// second one is dropped with a warning rather than blocking on a broken engine.
    fn wire(&mut self, work: Option<VisionWork<E::Vision>>) -> Option<PoolJob> {
        let work = work?;
        if self.pending.is_some() {
            tracing::warn!("engine started a second vision job while one was out; dropping it");
            return None;
        }
        let (tx, rx) = oneshot::channel();
        self.pending = Some(rx);
        Some(Box::new(move || {
            // The receiver is gone when the vehicle was reconfigured or reset meanwhile.
            let _ = tx.send(work());
        }))
    }

    fn step(&mut self, step: EngineStep<E::Vision>) -> ActorStep {
        let EngineStep {
            poses,
            work,
            frame_failure,
        } = step;
        ActorStep {
            poses,
            job: self.wire(work),
            frame_failure,
        }
    }
}

impl<E: Engine> VehicleEngine for Driven<E> {
    fn push_into(
        &mut self,
        event: SensorEvent,
        poses: &mut Vec<Pose>,
    ) -> Result<Option<PoolJob>, EngineError> {
        let work = self.engine.push_into(event, poses)?;
        Ok(self.wire(work))
    }

    fn vision_pending(&self) -> bool {
        self.pending.is_some()
    }

    fn poll_vision(&mut self, cx: &mut Context<'_>) -> Poll<VisionOutcome> {
        let Some(rx) = self.pending.as_mut() else {
            return Poll::Pending;
        };
        let result = std::task::ready!(Pin::new(rx).poll(cx));
        self.pending = None;
        Poll::Ready(match result {
            Ok(done) => {
                let step = self.engine.finish_frame(done);
                VisionOutcome::Done(self.step(step))
            }
            Err(_) => VisionOutcome::Lost,
        })
    }

    fn abandon_job(&mut self) -> ActorStep {
        self.pending = None;
        let step = self.engine.abandon_job();
        self.step(step)
    }

    fn health(&self) -> EngineHealth {
        self.engine.health()
    }

    fn reset(&mut self) {
        self.pending = None;
        self.engine.reset();
    }

    fn backlog(&self) -> usize {
        self.engine.backlog()
    }
}

/// A boxed engine, as factories make them.
pub type BoxedEngine = Box<dyn VehicleEngine>;

/// Boxes `engine` for the actor.
pub fn boxed<E: Engine>(engine: E) -> BoxedEngine {
    Box::new(Driven {
        engine,
        pending: None,
    })
}

/// Builds engines for new vehicles and for reconfigured ones.
pub trait EngineFactory: Send + Sync + 'static {
    /// A fresh engine for a vehicle with this configuration.
    fn create(&self, config: &VehicleConfig) -> BoxedEngine;
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
    Arc::new(crate::vehicle::runner_engine::RunnerFactory::default())
}
