//! [`VehicleRunner`]: the estimator plus the vision front end under the ordering rule of the
//! crate doc.

use std::collections::VecDeque;

use uavnav_core::{
    CameraFrame, Egomotion, EgomotionSolver, GnssFix, ImuSample, SensorEvent, VehicleConfig,
};
use uavnav_estimator::{Estimator, EstimatorParams, Health, InputError, PoseOutput};
use uavnav_vision::{FrameResult, FrontEnd, NoMeasurement, VisionParams};

/// Parameters of one vehicle's pipeline.
#[derive(Debug, Clone)]
pub struct RunnerParams {
    /// How long after a frame's time its egomotion reaches the estimator, ns (see the crate doc).
    /// Default 50 ms: the vision budget per frame is a few ms, so the pose stream rarely waits.
    pub vision_delay_ns: i64,
    /// Largest number of events held while a vision job is out; beyond it the job is abandoned
    /// (its result discarded when it comes back) so that IMU is never lost.
    pub max_held_events: usize,
    /// Feed GNSS to the estimator (`--no-gnss` turns it off).
    pub use_gnss: bool,
    /// Feed the magnetometer to the estimator (`--no-mag` turns it off).
    pub use_mag: bool,
    /// Feed the barometer to the estimator (`--no-baro` turns it off).
    pub use_baro: bool,
    /// Run vision on camera frames (`--no-vision` turns it off).
    pub use_vision: bool,
    /// Estimator parameters.
    pub estimator: EstimatorParams,
    /// Vision front-end parameters.
    pub vision: VisionParams,
}

/// Default vision delay, ns.
pub const DEFAULT_VISION_DELAY_NS: i64 = 50_000_000;
/// Default bound on held events (2 s of 200 Hz IMU plus GNSS and frames).
pub const DEFAULT_MAX_HELD_EVENTS: usize = 512;

impl Default for RunnerParams {
    fn default() -> Self {
        Self {
            vision_delay_ns: DEFAULT_VISION_DELAY_NS,
            max_held_events: DEFAULT_MAX_HELD_EVENTS,
            use_gnss: true,
            use_mag: true,
            use_baro: true,
            use_vision: true,
            estimator: EstimatorParams::default(),
            vision: VisionParams::default(),
        }
    }
}

/// Why an event was refused. The runner's state is unchanged by a refused event.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RunnerError {
    /// The estimator refused the sample.
    #[error(transparent)]
    Input(#[from] InputError),
    /// A camera frame arrived for a vehicle configured without a camera.
    #[error("camera frame at t_ns={t_ns} but the vehicle has no camera configuration")]
    NoCamera {
        /// Frame time.
        t_ns: i64,
    },
}

/// Counters and the last vision result, for health.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VisionStats {
    /// Frames handed to the front end.
    pub frames: u64,
    /// Frames that produced an egomotion measurement.
    pub measurements: u64,
    /// Frames with no measurement (first frame, decode error, black, …).
    pub no_measurement: u64,
    /// Frames ignored because vision is off.
    pub ignored: u64,
    /// Jobs abandoned because too many events were held behind them.
    pub abandoned: u64,
    /// Egomotion measurements the estimator refused.
    pub refused: u64,
    /// Held events the estimator refused when they were replayed.
    pub replay_rejected: u64,
    /// Tracked features in the last frame pair.
    pub last_tracked: u32,
    /// Inliers in the last measurement.
    pub last_inliers: u32,
    /// Quality of the last measurement, [0, 1].
    pub last_quality: f64,
    /// Solver of the last measurement.
    pub last_solver: Option<EgomotionSolver>,
    /// Reason of the last "no measurement" (for health and logs).
    pub last_reason: Option<String>,
    /// Stage timings of the last frame, µs: decode, track, solve.
    pub last_timings_us: [u64; 3],
}

/// A frame, the front end and the prior, ready to run on any thread.
#[derive(Debug)]
pub struct VisionJob {
    frontend: Box<FrontEnd>,
    frame: CameraFrame,
    prior: uavnav_core::MotionPrior,
    generation: u64,
}

impl VisionJob {
    /// The frame's time.
    pub fn t_ns(&self) -> i64 {
        self.frame.t_ns
    }

    /// Runs the front end on the frame (CPU work: decode, track, solve).
    pub fn run(mut self) -> VisionDone {
        let f = &self.frame;
        let result = self
            .frontend
            .process(f.t_ns, f.format, &f.data, &self.prior);
        VisionDone {
            frontend: self.frontend,
            result,
            generation: self.generation,
        }
    }
}

/// A finished vision job, to be handed back with [`VehicleRunner::finish_frame`].
#[derive(Debug)]
pub struct VisionDone {
    frontend: Box<FrontEnd>,
    /// The front end's output for the frame.
    pub result: FrameResult,
    generation: u64,
}

/// What came out of pushing one event: poses (one per IMU sample fused) and, possibly, a vision
/// job to run.
#[derive(Debug, Default)]
pub struct Step {
    /// Poses, in time order.
    pub poses: Vec<PoseOutput>,
    /// A vision job to run and hand back with [`VehicleRunner::finish_frame`].
    pub job: Option<VisionJob>,
}

/// One vehicle's pipeline. Feed events in time order (ties: IMU, GNSS, camera).
#[derive(Debug)]
pub struct VehicleRunner {
    config: VehicleConfig,
    params: RunnerParams,
    estimator: Estimator,
    /// `None` while a job is out.
    frontend: Option<Box<FrontEnd>>,
    /// Deadline of the job that is out.
    job_deadline_ns: Option<i64>,
    /// Bumped when a job is abandoned or the runner reset, so stale results are discarded.
    generation: u64,
    /// Results waiting for their deadline.
    pending: VecDeque<(i64, Egomotion)>,
    /// Events held behind the job that is out.
    held: VecDeque<SensorEvent>,
    stats: VisionStats,
    /// The front end's last result (read-only, for evaluation against truth).
    last_result: Option<FrameResult>,
}

impl VehicleRunner {
    /// A runner for one vehicle; `origin` fixes the local NED frame (else the first GNSS fix).
    pub fn new(
        config: VehicleConfig,
        params: RunnerParams,
        origin: Option<uavnav_core::Lla>,
    ) -> Self {
        // A run told to leave GNSS out is a vehicle without a receiver to the estimator (which
        // then starts without waiting for a fix).
        let estimator_config = if params.use_gnss {
            config.clone()
        } else {
            VehicleConfig {
                gnss: None,
                ..config.clone()
            }
        };
        let estimator = Estimator::new(&estimator_config, params.estimator.clone(), origin);
        let frontend = config
            .camera
            .as_ref()
            .map(|c| Box::new(FrontEnd::new(&c.model, c.body_from_cam, params.vision)));
        Self {
            config,
            params,
            estimator,
            frontend,
            job_deadline_ns: None,
            generation: 0,
            pending: VecDeque::new(),
            held: VecDeque::new(),
            stats: VisionStats::default(),
            last_result: None,
        }
    }

    /// The vehicle configuration.
    pub fn config(&self) -> &VehicleConfig {
        &self.config
    }

    /// The estimator's current health.
    pub fn health(&self) -> Health {
        self.estimator.health()
    }

    /// Vision counters and the last result.
    pub fn vision_stats(&self) -> &VisionStats {
        &self.stats
    }

    /// The front end's last frame result (measurement or reason), for evaluation against truth.
    pub fn last_frame_result(&self) -> Option<&FrameResult> {
        self.last_result.as_ref()
    }

    /// Events currently held behind a vision job.
    pub fn held_events(&self) -> usize {
        self.held.len()
    }

    /// Restarts the estimator and the front end; counters are kept.
    pub fn reset(&mut self) {
        self.estimator.reset();
        self.generation += 1;
        self.job_deadline_ns = None;
        self.pending.clear();
        self.held.clear();
        self.frontend = self
            .config
            .camera
            .as_ref()
            .map(|c| Box::new(FrontEnd::new(&c.model, c.body_from_cam, self.params.vision)));
    }

    /// Pushes one event. Errors leave the runner unchanged.
    pub fn push(&mut self, event: SensorEvent) -> Result<Step, RunnerError> {
        let mut step = Step::default();
        self.push_into(event, &mut step)?;
        Ok(step)
    }

    /// [`VehicleRunner::push`] appending to `step` (poses added at its end; `step.job` must be
    /// empty), so that a caller pushing at IMU rate reuses one allocation.
    pub fn push_into(&mut self, event: SensorEvent, step: &mut Step) -> Result<(), RunnerError> {
        if let SensorEvent::Camera(f) = &event
            && self.config.camera.is_none()
        {
            return Err(RunnerError::NoCamera { t_ns: f.t_ns });
        }
        if self.must_hold(&event) {
            if self.hold(event) {
                // The job was abandoned: what it held back flows again (never lose IMU).
                self.replay(step);
            }
            return Ok(());
        }
        self.process(event, step)
    }

    /// Hands back a finished job; replays held events (which may start the next job).
    pub fn finish_frame(&mut self, done: VisionDone) -> Step {
        let mut step = Step::default();
        if done.generation != self.generation {
            return step; // abandoned or reset meanwhile
        }
        self.frontend = Some(done.frontend);
        let deadline = self.job_deadline_ns.take().unwrap_or(done.result.t1_ns);
        self.record(&done.result);
        if let Ok(ego) = &done.result.outcome {
            self.pending.push_back((deadline, ego.clone()));
        }
        self.last_result = Some(done.result);
        self.replay(&mut step);
        step
    }

    /// Runs everything inline: pushes `event` and runs any vision job at once (offline use).
    pub fn push_inline(&mut self, event: SensorEvent) -> Result<Vec<PoseOutput>, RunnerError> {
        let mut step = self.push(event)?;
        let mut poses = std::mem::take(&mut step.poses);
        while let Some(job) = step.job.take() {
            step = self.finish_frame(job.run());
            poses.append(&mut step.poses);
        }
        Ok(poses)
    }

    /// Flushes what is pending at the end of a stream (held events are replayed as if the job had
    /// come back empty-handed only when it has; call after the last job finished).
    pub fn pending_events(&self) -> usize {
        self.held.len() + self.pending.len()
    }

    fn must_hold(&self, event: &SensorEvent) -> bool {
        if !self.held.is_empty() {
            return true;
        }
        match self.job_deadline_ns {
            None => false,
            Some(deadline) => {
                event.t_ns() >= deadline
                    || matches!(event, SensorEvent::Camera(_)) && self.params.use_vision
            }
        }
    }

    /// Holds `event`; returns whether the outstanding job was abandoned for holding too much.
    fn hold(&mut self, event: SensorEvent) -> bool {
        self.held.push_back(event);
        let abandon = self.held.len() > self.params.max_held_events;
        if abandon {
            // The job is too slow: give up on it rather than ever lose IMU.
            self.drop_job();
        }
        abandon
    }

    /// Gives up on the vision job that is out (its result will be discarded when it comes back)
    /// and replays the events held behind it. For a caller that lost the job (e.g. its worker
    /// pool shut down); a no-op without a job out.
    pub fn abandon_job(&mut self) -> Step {
        let mut step = Step::default();
        if self.job_deadline_ns.is_some() {
            self.drop_job();
            self.replay(&mut step);
        }
        step
    }

    fn drop_job(&mut self) {
        self.stats.abandoned += 1;
        self.generation += 1;
        self.job_deadline_ns = None;
        self.frontend = self
            .config
            .camera
            .as_ref()
            .map(|c| Box::new(FrontEnd::new(&c.model, c.body_from_cam, self.params.vision)));
    }

    fn replay(&mut self, step: &mut Step) {
        while step.job.is_none() && self.job_deadline_ns.is_none() {
            let Some(event) = self.held.pop_front() else {
                break;
            };
            if self.process(event, step).is_err() {
                self.stats.replay_rejected += 1;
            }
        }
    }

    fn apply_due(&mut self, t_ns: i64) {
        while let Some((deadline, _)) = self.pending.front() {
            if *deadline > t_ns {
                break;
            }
            if let Some((_, ego)) = self.pending.pop_front()
                && self.estimator.push_egomotion(&ego).is_err()
            {
                self.stats.refused += 1;
            }
        }
    }

    fn process(&mut self, event: SensorEvent, step: &mut Step) -> Result<(), RunnerError> {
        self.apply_due(event.t_ns());
        match event {
            SensorEvent::Imu(s) => self.on_imu(&s, step),
            SensorEvent::Gnss(f) => self.on_gnss(&f),
            SensorEvent::Mag(m) => {
                if self.params.use_mag {
                    self.estimator.push_mag(&m)?;
                }
                Ok(())
            }
            SensorEvent::Baro(b) => {
                if self.params.use_baro {
                    self.estimator.push_baro(&b)?;
                }
                Ok(())
            }
            SensorEvent::Camera(frame) => {
                self.on_camera(frame, step);
                Ok(())
            }
        }
    }

    fn on_imu(&mut self, s: &ImuSample, step: &mut Step) -> Result<(), RunnerError> {
        if let Some(p) = self.estimator.push_imu(s)? {
            step.poses.push(p);
        }
        Ok(())
    }

    fn on_gnss(&mut self, f: &GnssFix) -> Result<(), RunnerError> {
        if self.params.use_gnss {
            self.estimator.push_gnss(f)?;
        }
        Ok(())
    }

    fn on_camera(&mut self, frame: CameraFrame, step: &mut Step) {
        if !self.params.use_vision {
            self.stats.ignored += 1;
            return;
        }
        let Some(frontend) = self.frontend.take() else {
            // Unreachable by must_hold; never panic on it.
            self.stats.ignored += 1;
            return;
        };
        let t0 = frontend.reference_t_ns().unwrap_or(frame.t_ns);
        let prior = self.estimator.motion_prior(t0, frame.t_ns);
        self.job_deadline_ns = Some(frame.t_ns.saturating_add(self.params.vision_delay_ns));
        self.stats.frames += 1;
        step.job = Some(VisionJob {
            frontend,
            frame,
            prior,
            generation: self.generation,
        });
    }

    fn record(&mut self, r: &FrameResult) {
        let s = &mut self.stats;
        s.last_tracked = r.tracked;
        s.last_timings_us = [r.timings.decode_us, r.timings.track_us, r.timings.solve_us];
        match &r.outcome {
            Ok(ego) => {
                s.measurements += 1;
                s.last_inliers = ego.inliers;
                s.last_quality = ego.quality;
                s.last_solver = Some(ego.solver);
                s.last_reason = None;
            }
            Err(reason) => {
                s.no_measurement += 1;
                if !matches!(reason, NoMeasurement::NoReference) {
                    s.last_reason = Some(reason.to_string());
                }
            }
        }
    }
}
