//! The product [`Engine`]: `uavnav_runner::VehicleRunner` (vision front end + estimator) behind the
//! engine seam, and the conversion of its outputs to the wire messages.

use uavnav_core::{SensorEvent, VehicleConfig};
use uavnav_proto::compact::compact_pose;
use uavnav_proto::convert::output::{heading_to_wire, mode_to_wire};
use uavnav_proto::v1 as pb;
use uavnav_runner::{
    Health, NoMeasurement, PoseOutput, RunnerParams, Step, VehicleRunner, VisionDone,
};

use crate::output::hub::Pose;
use crate::vehicle::engine::{
    BoxedEngine, Engine, EngineError, EngineFactory, EngineHealth, EngineStep, FrameFailure,
    FrameFailureKind, VisionWork,
};

/// Builds [`RunnerEngine`]s with the same parameters for every vehicle.
#[derive(Debug, Clone)]
pub struct RunnerFactory {
    /// Runner parameters (those of `uavnav estimate`, except `max_held_events`, see
    /// [`SERVICE_MAX_HELD_EVENTS`]).
    pub params: RunnerParams,
}

/// The runner's own bound on held events in the service. Far above the actor's intake limit
/// ([`uavnav_runner::DEFAULT_MAX_HELD_EVENTS`]): the actor stops taking input at that limit and
/// waits for the vision job instead, so the runner never abandons a job on its own and the poses
/// are those of `uavnav estimate` whatever the feed rate. This bound only caps memory.
pub const SERVICE_MAX_HELD_EVENTS: usize = 1 << 16;

impl Default for RunnerFactory {
    fn default() -> Self {
        Self {
            params: RunnerParams {
                max_held_events: SERVICE_MAX_HELD_EVENTS,
                ..RunnerParams::default()
            },
        }
    }
}

impl EngineFactory for RunnerFactory {
    fn create(&self, config: &VehicleConfig) -> BoxedEngine {
        crate::vehicle::engine::boxed(RunnerEngine {
            runner: VehicleRunner::new(config.clone(), self.params.clone(), None),
            last_t_ns: 0,
            scratch: Step::default(),
        })
    }
}

/// One vehicle's runner.
#[derive(Debug)]
pub struct RunnerEngine {
    runner: VehicleRunner,
    last_t_ns: i64,
    /// Reused for every input (one pose per IMU sample: no allocation per sample).
    scratch: Step,
}

/// Appends `step`'s poses to `out`, notes the last one's time and hands back the vision work.
/// A free function over the fields, so that [`RunnerEngine::push_into`] can lend its scratch step
/// in place (taking it out and back moved the whole `Step`, vision job slot included, twice per
/// IMU sample).
fn emit(
    last_t_ns: &mut i64,
    step: &mut Step,
    out: &mut Vec<Pose>,
) -> Option<VisionWork<VisionDone>> {
    if let Some(p) = step.poses.last() {
        *last_t_ns = p.t_ns;
    }
    out.extend(step.poses.iter().map(compact_pose));
    step.job.take().map(vision_work)
}

impl RunnerEngine {
    fn step(&mut self, mut step: Step) -> EngineStep<VisionDone> {
        let mut poses = Vec::with_capacity(step.poses.len());
        let work = emit(&mut self.last_t_ns, &mut step, &mut poses);
        EngineStep {
            poses,
            work,
            frame_failure: None,
        }
    }
}

impl Engine for RunnerEngine {
    type Vision = VisionDone;

    fn push(&mut self, event: SensorEvent) -> Result<EngineStep<VisionDone>, EngineError> {
        let mut poses = Vec::new();
        let work = self.push_into(event, &mut poses)?;
        Ok(EngineStep {
            poses,
            work,
            frame_failure: None,
        })
    }

    fn push_into(
        &mut self,
        event: SensorEvent,
        poses: &mut Vec<Pose>,
    ) -> Result<Option<VisionWork<VisionDone>>, EngineError> {
        self.scratch.poses.clear();
        let r = self.runner.push_into(event, &mut self.scratch);
        let work = emit(&mut self.last_t_ns, &mut self.scratch, poses);
        r.map_err(|e| EngineError(e.to_string()))?;
        Ok(work)
    }

    fn finish_frame(&mut self, done: VisionDone) -> EngineStep<VisionDone> {
        let failure = frame_failure(&done);
        let step = self.runner.finish_frame(done);
        let mut step = self.step(step);
        step.frame_failure = failure;
        step
    }

    fn health(&self) -> EngineHealth {
        let h = self.runner.health();
        let v = self.runner.vision_stats();
        let vision = (v.frames > 0).then_some(pb::VisionQuality {
            tracked: v.last_tracked,
            inliers: v.last_inliers,
            quality: v.last_quality,
            solver: match v.last_solver {
                Some(uavnav_core::EgomotionSolver::Plane) => pb::VisionSolver::Homography as i32,
                Some(_) => pb::VisionSolver::Essential as i32,
                None => pb::VisionSolver::Unspecified as i32,
            },
            t_ns: self.last_t_ns,
        });
        EngineHealth {
            mode: mode_to_wire(h.mode),
            t_ns: self.last_t_ns,
            innovation: innovation(&h),
            vision,
            gnss_gate_rejections: h.gnss_pos.rejected + h.gnss_vel.rejected,
            vision_gate_rejections: h.vision_rot.rejected + h.vision_trans.rejected,
            engine_dropped: h.inputs_rejected + h.late_dropped + v.abandoned,
            divergence_resets: u64::from(h.divergence_resets),
            imu_clipped: h.imu_clipped,
            imu_gaps_bridged: h.imu_gaps_bridged,
            gnss_velocity_delay_s: h.gnss_velocity_delay_s,
            heading: Some(heading_to_wire(&h.heading, h.yaw_resets)),
            imu_noise: h
                .imu_noise_ratio
                .map(|[gyro_ratio, accel_ratio]| pb::ImuNoise {
                    gyro_ratio,
                    accel_ratio,
                }),
        }
    }

    fn reset(&mut self) {
        self.runner.reset();
        self.last_t_ns = 0;
    }

    fn backlog(&self) -> usize {
        self.runner.held_events()
    }

    fn abandon_job(&mut self) -> EngineStep<VisionDone> {
        let step = self.runner.abandon_job();
        self.step(step)
    }
}

/// The fault of the frame itself, when the front end could not use it because of its image (a
/// corrupt body behind a good header, a decoded size not the camera's); scene conditions (dark,
/// blurred, textureless) are not faults of the input.
fn frame_failure(done: &VisionDone) -> Option<FrameFailure> {
    let kind = match &done.result.outcome {
        Err(NoMeasurement::Decode(_)) => FrameFailureKind::Corrupt,
        Err(NoMeasurement::SizeMismatch { .. }) => FrameFailureKind::Size,
        _ => return None,
    };
    let reason = match &done.result.outcome {
        Err(e) => e.to_string(),
        Ok(_) => String::new(),
    };
    Some(FrameFailure {
        t_ns: done.result.t1_ns,
        kind,
        reason,
    })
}

/// A runner job as pool work.
fn vision_work(job: uavnav_runner::VisionJob) -> VisionWork<VisionDone> {
    Box::new(move || job.run())
}

fn innovation(h: &Health) -> pb::InnovationRatios {
    pb::InnovationRatios {
        gnss_position: h.gnss_pos.test_ratio,
        gnss_velocity: h.gnss_vel.test_ratio,
        vision: h.vision_rot.test_ratio.max(h.vision_trans.test_ratio),
        magnetometer: h.mag.test_ratio,
        barometer: h.baro.test_ratio,
        gnss_tilt: h.gnss_tilt.test_ratio,
        position_hold: h.position_hold.test_ratio,
    }
}

/// Estimator pose → the service's wire pose (its compact form; without `vehicle_id` and
/// `ingest_wall_ns`).
pub fn pose_to_wire(p: &PoseOutput) -> pb::PoseEstimate {
    compact_pose(p).to_wire("")
}
