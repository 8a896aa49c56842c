//! One actor per vehicle: a cloneable [`VehicleHandle`] and a task that alone owns the vehicle's
//! [`Engine`](crate::vehicle::engine::Engine).
//!
//! One bounded, ordered queue feeds the task (sensor data, configuration, reset, stop); senders
//! wait when it is full, so IMU is never shed. Camera frames are shed instead of waiting when the
//! vehicle already has `vehicles.camera_queue` frames queued, or when the vision pool is saturated
//! at the moment the frame is due. Inputs pass through a [`ReorderBuffer`] and reach the engine in
//! timestamp order; vision jobs run on the [`VisionPool`](crate::vehicle::vision_pool::VisionPool).

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::sync::oneshot;
use tracing::{Span, debug, info_span, warn};
use uavnav_core::{
    BaroSample, CameraFrame, GnssFix, ImuSample, MagSample, SensorEvent, VehicleConfig,
};

use crate::config::VehiclesConfig;
use crate::metrics::Metrics;
use crate::output::health::{HealthReport, HealthWindow, repeats};
use crate::output::hub::{Hub, MAX_BATCH_POSES, Pose, PoseBatch};
use crate::vehicle::budgets::{ByteBudget, CameraBytes, CameraPixels, Reserved};
use crate::vehicle::engine::{
    ActorStep, BoxedEngine, FrameFailureKind, PoolJob, SharedFactory, VisionOutcome,
};
use crate::vehicle::queue;
use crate::vehicle::reorder::{Refused, ReorderBuffer};
use crate::vehicle::ticks::{IDLE_HEALTH_EVERY, Ticks};
use crate::vehicle::vision_pool::VisionPool;
use crate::vehicle::{InputKind, VehicleShared, VehicleStats, mono_now};

/// Most inputs held in one reorder window whatever their timestamps (memory bound).
const REORDER_CAPACITY: usize = 4096;
/// IMU arrivals (one per message) remembered to attribute latency to poses released late.
const LATENCY_MEMORY: usize = 2048;
/// Most queued messages handled after the one that woke the actor, before publishing.
const DRAIN_MAX: usize = 16;
/// Added to a re-armed flush deadline so that a timer firing a hair early does not spin.
const FLUSH_SLACK: Duration = Duration::from_micros(100);

/// Everything an actor needs from the service.
#[derive(Debug)]
pub struct Ctx {
    /// Actor settings.
    pub vehicles: VehiclesConfig,
    /// Health publication period.
    pub health_period: Duration,
    /// Metrics.
    pub metrics: Metrics,
    /// Output fan-out.
    pub hub: Hub,
    /// Vision workers.
    pub pool: Arc<VisionPool>,
    /// Engine factory.
    pub factory: SharedFactory,
    /// Compressed camera bytes queued at all actors, and their limit (`vision.queue_bytes`).
    pub camera_bytes: CameraBytes,
    /// Decoded sensor bytes queued at all actors (`vehicles.input_bytes`).
    pub input_bytes: ByteBudget,
    /// Pixels of all configured cameras (`vision.max_total_camera_pixels`).
    pub camera_pixels: CameraPixels,
}

/// Decoded bytes a queued batch of `n` inputs holds (the queue's slot and the samples).
pub fn batch_bytes(batch: &[Stamped]) -> usize {
    std::mem::size_of::<Msg>() + std::mem::size_of_val(batch)
}

impl Ctx {
    /// The reorder window, ns.
    pub fn window_ns(&self) -> i64 {
        (self.vehicles.reorder_window_ms * 1e6) as i64
    }

    /// The future limit, ns.
    pub fn max_future_ns(&self) -> i64 {
        (self.vehicles.max_future_s * 1e9) as i64
    }

    /// The time gate's limits.
    pub fn gate_limits(&self) -> crate::ingest::gate::GateLimits {
        crate::ingest::gate::GateLimits {
            window_ns: self.window_ns(),
            max_future_ns: self.max_future_ns(),
            resync_samples: self.vehicles.clock_resync_samples,
            resync_wall_ns: (self.vehicles.clock_resync_s * 1e9) as i64,
        }
    }
}

/// One validated sensor input.
#[derive(Debug, Clone)]
pub enum Input {
    /// IMU sample.
    Imu(ImuSample),
    /// GNSS fix.
    Gnss(GnssFix),
    /// Magnetometer sample.
    Mag(MagSample),
    /// Barometer sample.
    Baro(BaroSample),
    /// Camera frame.
    Camera(CameraFrame),
}

impl Input {
    /// The sensor time, ns.
    pub fn t_ns(&self) -> i64 {
        match self {
            Input::Imu(s) => s.t_ns,
            Input::Gnss(g) => g.t_ns,
            Input::Mag(m) => m.t_ns,
            Input::Baro(b) => b.t_ns,
            Input::Camera(c) => c.t_ns,
        }
    }

    /// The estimator's event.
    pub fn into_event(self) -> SensorEvent {
        match self {
            Input::Imu(s) => SensorEvent::Imu(s),
            Input::Gnss(g) => SensorEvent::Gnss(g),
            Input::Mag(m) => SensorEvent::Mag(m),
            Input::Baro(b) => SensorEvent::Baro(b),
            Input::Camera(c) => SensorEvent::Camera(c),
        }
    }

    /// The kind (its value is the tie rank of `SensorEvent::rank`).
    pub fn kind(&self) -> InputKind {
        match self {
            Input::Imu(_) => InputKind::Imu,
            Input::Gnss(_) => InputKind::Gnss,
            Input::Mag(_) => InputKind::Mag,
            Input::Baro(_) => InputKind::Baro,
            Input::Camera(_) => InputKind::Camera,
        }
    }
}

/// An input with its arrival time at the service.
#[derive(Debug, Clone)]
pub struct Stamped {
    /// The input.
    pub input: Input,
    /// Arrival, service wall clock, ns since the UNIX epoch.
    pub wall_ns: i64,
    /// Arrival, monotonic clock.
    pub at: Instant,
}

/// A message on the ordered queue.
#[derive(Debug)]
pub enum Msg {
    /// IMU samples, a GNSS fix or a camera frame, and the queue bytes they hold (none for a
    /// camera frame: its compressed bytes have their own budget).
    Data(Vec<Stamped>, Reserved),
    /// Replace the configuration (and the engine).
    Configure {
        /// The new configuration.
        config: Box<VehicleConfig>,
        /// Told when applied.
        reply: Option<oneshot::Sender<()>>,
    },
    /// Restart the engine.
    Reset {
        /// Told when done.
        reply: Option<oneshot::Sender<()>>,
    },
    /// Fuse what is queued, publish final health and stop.
    Stop,
}

/// Why a message could not be queued.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SendError {
    /// The actor is gone (evicted or stopping).
    Closed,
    /// The vehicle's camera queue is full, in frames or bytes (the frame is shed).
    Full,
    /// The camera queues of all vehicles together hold `vision.queue_bytes` (the frame is shed).
    FullGlobal,
}

/// The compressed size of a camera input (0 for other inputs).
fn frame_bytes(input: &Input) -> usize {
    match input {
        Input::Camera(c) => c.data.len(),
        _ => 0,
    }
}

/// The cloneable handle of a vehicle actor. Its parts are inline: the registry's admission pass
/// reads every vehicle's shared face through the map's values, one pointer away.
#[derive(Debug, Clone)]
pub struct VehicleHandle {
    /// The shared face of the vehicle.
    pub shared: Arc<VehicleShared>,
    tx: queue::Sender<Msg>,
    /// Decoded sensor bytes queued at this vehicle (`vehicles.input_queue_bytes`).
    budget: ByteBudget,
}

impl VehicleHandle {
    /// Waits until the vehicle's queue and all vehicles' queues together have room for `batch`
    /// in bytes (back-pressure, never shedding), and wraps it as a message holding them.
    pub async fn reserve(&self, batch: Vec<Stamped>, ctx: &Ctx) -> Msg {
        let bytes = batch_bytes(&batch);
        // Always the vehicle first, then the global budget: no two senders wait on each other
        // in opposite orders.
        let vehicle = self.budget.reserve(bytes).await;
        let global = ctx.input_bytes.reserve(bytes).await;
        Msg::Data(
            batch,
            Reserved {
                _vehicle: vehicle,
                _global: global,
            },
        )
    }

    /// Bytes of sensor data queued at this vehicle now.
    pub fn queued_bytes(&self) -> usize {
        self.budget.used()
    }

    /// Queues a message, waiting while the queue is full (back-pressure, never shedding).
    pub async fn send(&self, msg: Msg) -> Result<(), SendError> {
        self.tx.send(msg).await.map_err(|_| SendError::Closed)
    }

    /// Like [`VehicleHandle::send`], but hands the message back when the actor is gone, so the
    /// caller can start a fresh actor and resend it.
    pub async fn send_or_return(&self, msg: Msg) -> Result<(), Msg> {
        self.tx.send(msg).await
    }

    /// Queues a camera frame unless the vehicle already has `vehicles.camera_queue` frames or
    /// `vehicles.camera_queue_bytes` bytes queued ([`SendError::Full`]), or all vehicles together
    /// `vision.queue_bytes` ([`SendError::FullGlobal`]): then the frame is shed. Waits for room in
    /// the ordered queue otherwise. The frame counts until the actor takes it off the queue.
    pub async fn send_camera(&self, s: Stamped, ctx: &Ctx) -> Result<(), SendError> {
        use std::sync::atomic::Ordering::AcqRel;
        let (frames, bytes) = (&self.shared.frames_queued, &self.shared.frame_bytes_queued);
        let global = &ctx.camera_bytes;
        let size = frame_bytes(&s.input);
        let undo = || {
            frames.fetch_sub(1, AcqRel);
            bytes.fetch_sub(size, AcqRel);
            global.queued.fetch_sub(size, AcqRel);
        };
        let over_frames = frames.fetch_add(1, AcqRel) >= ctx.vehicles.camera_queue;
        let over_bytes = bytes.fetch_add(size, AcqRel) + size > ctx.vehicles.camera_queue_bytes;
        let over_global = global.queued.fetch_add(size, AcqRel) + size > global.limit;
        if over_frames || over_bytes || over_global {
            undo();
            return Err(if over_frames || over_bytes {
                SendError::Full
            } else {
                SendError::FullGlobal
            });
        }
        let r = self
            .tx
            .send(Msg::Data(vec![s], Reserved::default()))
            .await
            .map_err(|_| SendError::Closed);
        if r.is_err() {
            undo();
        }
        r
    }

    /// Whether the actor has stopped.
    pub fn is_closed(&self) -> bool {
        self.tx.is_closed()
    }

    /// Asks the actor to stop without waiting (admission eviction of an idle vehicle: its queue
    /// is empty). Whether the request was queued.
    pub fn try_stop(&self) -> bool {
        self.tx.try_send(Msg::Stop).is_ok()
    }
}

/// Starts a vehicle actor. `on_exit` runs when the task ends (eviction or shutdown).
pub fn spawn(
    shared: Arc<VehicleShared>,
    config: VehicleConfig,
    ctx: Arc<Ctx>,
    on_exit: Box<dyn FnOnce(bool) + Send>,
) -> VehicleHandle {
    let (tx, rx) = queue::channel(ctx.vehicles.input_queue);
    let ctx_budget = ctx.vehicles.input_queue_bytes;
    let engine = ctx.factory.create(&config);
    // The vehicle's span is the explicit parent of the actor's log events. Entering it on every
    // poll of the task (`Instrument`) cost ~2 % of the service's CPU at fleet scale.
    let span = info_span!("vehicle", id = %shared.id);
    let actor = Actor {
        buffer: ReorderBuffer::new(ctx.window_ns(), REORDER_CAPACITY),
        window: HealthWindow::new(mono_now()),
        shared: Arc::clone(&shared),
        engine,
        outbox: Vec::new(),
        stamped: 0,
        ingest_times: VecDeque::new(),
        last_input: mono_now(),
        ctx,
        span,
        divergence_resets: 0,
        imu_clipped: 0,
        imu_gaps_bridged: 0,
        busy_reports: 2,
        poses_published: 0,
        health_published: 0,
    };
    tokio::spawn(async move {
        let evicted = actor.run(rx).await;
        on_exit(evicted);
    });
    VehicleHandle {
        shared,
        tx,
        budget: ByteBudget::new(ctx_budget),
    }
}

struct Actor {
    shared: Arc<VehicleShared>,
    ctx: Arc<Ctx>,
    /// The engine and its outstanding vision job.
    engine: BoxedEngine,
    buffer: ReorderBuffer<Stamped>,
    /// Poses made since the last publication (published as one batch per wake-up: the message
    /// that woke the actor and those already queued behind it).
    outbox: Vec<Pose>,
    /// How many of the outbox's poses are stamped (the rest are, when published).
    stamped: usize,
    /// (t_ns of the first sample, arrival, arrival wall ns) per fused IMU arrival, oldest first.
    ingest_times: VecDeque<(i64, Instant, i64)>,
    last_input: Instant,
    window: HealthWindow,
    span: Span,
    /// The engine's divergence resets at the last health report (the metric counts the new ones).
    divergence_resets: u64,
    /// The engine's clipped IMU samples at the last health report (likewise).
    imu_clipped: u64,
    /// The engine's bridged IMU gaps at the last health report (likewise).
    imu_gaps_bridged: u64,
    /// Reports still due at every period: a message makes it 2 (the report covering it, and the
    /// next, whose rates show the vehicle went quiet).
    busy_reports: u8,
    /// Poses published so far: the number of the next one (watches decimate by it).
    poses_published: u64,
    /// Health reports published so far: the number of the next one (likewise).
    health_published: u64,
}

/// What an engine counter gained since `last` (its value at the previous report), which it then
/// becomes. A new engine (reset, reconfiguration) counts from 0 again: what it counted since is
/// what it has.
fn counted_since(last: &mut u64, now: u64) -> u64 {
    let gained = if now >= *last { now - *last } else { now };
    *last = now;
    gained
}

impl Actor {
    /// The event loop; returns whether the actor was evicted for idleness.
    async fn run(mut self, mut rx: queue::Receiver<Msg>) -> bool {
        // Health ticks fall on start + k * period. An active vehicle wakes at every one; an idle
        // one only at the tick of its next report or of its eviction, so an idle fleet costs no
        // wake-ups in between. Input brings the next tick back to the coming period.
        let mut ticks = Ticks::new(tokio::time::Instant::now(), self.ctx.health_period);
        let tick = tokio::time::sleep_until(ticks.at(0));
        tokio::pin!(tick);
        let idle = Duration::from_secs_f64(self.ctx.vehicles.idle_evict_s);
        // An idle stream's last window is flushed after this much wall time without input.
        let flush_after =
            Duration::from_secs_f64((self.ctx.vehicles.reorder_window_ms * 1e-3).max(0.005));
        // One timer for the whole life of the actor, re-armed lazily: when it fires early (input
        // came since it was set) it is pushed to the new deadline instead of flushing. A fresh
        // timer per message would register and cancel a timer-wheel entry (a lock shared by the
        // whole runtime) for every input.
        let flush = tokio::time::sleep(flush_after);
        tokio::pin!(flush);
        let evicted = loop {
            tokio::select! {
                biased;
                done = std::future::poll_fn(|cx| self.engine.poll_vision(cx)),
                    if self.engine.vision_pending() => self.on_vision(done),
                // While vision lags, take no input: the queue fills and senders wait (back-
                // pressure) instead of the engine abandoning jobs, so output never depends on timing.
                msg = rx.recv(), if !self.backlogged() => match msg {
                    Some(Msg::Stop) | None => break false,
                    Some(m) => {
                        self.on_msg(m);
                        if self.take_queued(&mut rx) {
                            break false;
                        }
                        // Only an idle actor's timer is far off (the hot path reads no clock).
                        if ticks.idle {
                            ticks.idle = false;
                            let next = ticks.next_after(tokio::time::Instant::now());
                            if next < ticks.scheduled {
                                ticks.scheduled = next;
                                tick.as_mut().reset(ticks.at(next));
                            }
                        }
                    }
                },
                () = &mut tick => {
                    // A late wake-up (a busy runtime) counts as the tick it is in.
                    let k = ticks.scheduled.max(ticks.index_at(tokio::time::Instant::now()));
                    if self.busy() || k >= ticks.reported + u64::from(IDLE_HEALTH_EVERY) {
                        self.busy_reports = self.busy_reports.saturating_sub(1);
                        ticks.reported = k;
                        self.publish_health();
                    }
                    let evict_at = self.last_input + idle;
                    if mono_now() >= evict_at && !self.engine.vision_pending() {
                        break true;
                    }
                    ticks.idle = !self.busy();
                    ticks.scheduled = if !ticks.idle {
                        k + 1
                    } else {
                        let report = ticks.reported + u64::from(IDLE_HEALTH_EVERY);
                        let evict = ticks.index_at_or_after(tokio::time::Instant::from_std(evict_at));
                        report.min(evict).max(k + 1)
                    };
                    tick.as_mut().reset(ticks.at(ticks.scheduled));
                }
                () = &mut flush, if !self.buffer.is_empty() => {
                    let (due, now) = (self.last_input + flush_after, mono_now());
                    if now >= due {
                        self.flush_all();
                    }
                    flush.as_mut().reset(tokio::time::Instant::from_std(due.max(now) + FLUSH_SLACK));
                }
            }
            self.publish();
        };
        self.drain(&mut rx).await;
        evicted
    }

    /// Fuses everything still queued, waits for the outstanding vision jobs, publishes final health.
    async fn drain(&mut self, rx: &mut queue::Receiver<Msg>) {
        rx.close();
        while let Ok(m) = rx.try_recv() {
            if !matches!(m, Msg::Stop) {
                self.on_msg(m);
            }
        }
        loop {
            if self.engine.vision_pending() {
                let done = std::future::poll_fn(|cx| self.engine.poll_vision(cx)).await;
                self.on_vision(done);
                continue;
            }
            match self.buffer.pop_first() {
                Some((_, s)) => self.fuse(s),
                None => break,
            }
        }
        self.publish();
        self.publish_health();
    }

    /// Handles up to [`DRAIN_MAX`] more messages that are already queued, so that one wake-up and
    /// one published batch serve them all: under load, when queues build up, the per-message costs
    /// shrink instead of adding to the backlog. Returns whether a `Stop` was taken.
    fn take_queued(&mut self, rx: &mut queue::Receiver<Msg>) -> bool {
        for _ in 0..DRAIN_MAX {
            if self.backlogged() {
                break;
            }
            match rx.try_recv() {
                Ok(Msg::Stop) => return true,
                Ok(m) => self.on_msg(m),
                Err(_) => break,
            }
        }
        false
    }

    /// Whether the engine holds so many inputs behind the outstanding vision job that the actor
    /// should wait for the job before taking more.
    fn backlogged(&self) -> bool {
        self.engine.vision_pending()
            && self.engine.backlog() >= uavnav_runner::DEFAULT_MAX_HELD_EVENTS
    }

    /// Whether the next tick must report: input came in the last period or the one before
    /// (whose report shows the rates falling to zero), or inputs or a vision job are held.
    fn busy(&self) -> bool {
        self.busy_reports > 0 || !self.buffer.is_empty() || self.engine.vision_pending()
    }

    fn on_msg(&mut self, msg: Msg) {
        self.busy_reports = 2;
        match msg {
            Msg::Data(batch, _reserved) => {
                self.last_input = mono_now();
                for s in batch {
                    self.on_input(s);
                }
            }
            Msg::Configure { config, reply } => {
                self.flush_all();
                // The old engine's outstanding job, if any, goes with it.
                self.engine = self.ctx.factory.create(&config);
                if let Some(r) = reply {
                    let _ = r.send(());
                }
            }
            Msg::Reset { reply } => {
                self.buffer.clear();
                self.engine.reset();
                // The poses made before the reset keep the arrivals they came from.
                self.stamp();
                self.ingest_times.clear();
                if let Some(r) = reply {
                    let _ = r.send(());
                }
            }
            Msg::Stop => {}
        }
    }

    fn on_input(&mut self, s: Stamped) {
        if matches!(s.input, Input::Camera(_)) {
            use std::sync::atomic::Ordering::AcqRel;
            let size = frame_bytes(&s.input);
            self.shared.frames_queued.fetch_sub(1, AcqRel);
            self.shared.frame_bytes_queued.fetch_sub(size, AcqRel);
            self.ctx.camera_bytes.queued.fetch_sub(size, AcqRel);
        }
        let (t, kind) = (s.input.t_ns(), s.input.kind());
        match self.buffer.push(t, kind as u8, s) {
            Ok(()) => {}
            Err(Refused::Late) => {
                VehicleStats::add(&self.shared.stats.late, 1);
                self.ctx.metrics.reorder_dropped.inc();
            }
            Err(Refused::Duplicate) => {
                VehicleStats::add(&self.shared.stats.dropped, 1);
                self.ctx.metrics.reorder_dropped.inc();
            }
        }
        while let Some((_, s)) = self.buffer.pop_ready() {
            self.fuse(s);
        }
    }

    fn flush_all(&mut self) {
        while let Some((_, s)) = self.buffer.pop_first() {
            self.fuse(s);
        }
    }

    fn fuse(&mut self, s: Stamped) {
        match &s.input {
            Input::Imu(imu) => {
                // One entry per arrival (the samples of one message share it): a pose takes the
                // arrival of the newest entry not after it, the same as one entry per sample.
                if self.ingest_times.back().is_none_or(|b| b.1 != s.at) {
                    self.ingest_times.push_back((imu.t_ns, s.at, s.wall_ns));
                    if self.ingest_times.len() > LATENCY_MEMORY {
                        self.ingest_times.pop_front();
                    }
                }
            }
            Input::Camera(_) => {
                // Overload: shed the frame before the engine sees it (never IMU).
                if self.ctx.pool.is_saturated() {
                    VehicleStats::add(&self.shared.stats.shed, 1);
                    self.ctx.metrics.vision_shed.inc();
                    return;
                }
            }
            Input::Gnss(_) | Input::Mag(_) | Input::Baro(_) => {}
        }
        match self
            .engine
            .push_into(s.input.into_event(), &mut self.outbox)
        {
            Ok(work) => self.start(work),
            Err(e) => {
                VehicleStats::add(&self.shared.stats.dropped, 1);
                self.ctx.metrics.engine_errors.inc();
                debug!(parent: &self.span, error = %e, "engine refused an input");
            }
        }
    }

    /// Queues a step's poses for publication, counts a frame the vision job refused and sends
    /// the step's vision job to the pool.
    fn apply(&mut self, step: ActorStep) {
        self.outbox.extend(step.poses);
        if let Some(failure) = step.frame_failure {
            // The frame was acknowledged (its header was good): count it now, as rejected input.
            VehicleStats::add(&self.shared.stats.rejected, 1);
            let cause = match failure.kind {
                FrameFailureKind::Corrupt => crate::metrics::Cause::CorruptImage,
                FrameFailureKind::Size => crate::metrics::Cause::ImageSize,
            };
            self.ctx.metrics.frame_rejected(cause);
            debug!(parent: &self.span, t_ns = failure.t_ns, reason = %failure.reason, "camera frame refused by the vision job");
        }
        self.start(step.job);
    }

    /// Sends a vision job to the pool.
    fn start(&mut self, job: Option<PoolJob>) {
        let Some(job) = job else { return };
        if self.ctx.pool.submit(job) {
            self.ctx
                .metrics
                .vision_in_flight
                .set(self.ctx.pool.stats().in_flight as i64);
        } else {
            // The pool is shutting down: the job is lost, so release what the engine held for it.
            VehicleStats::add(&self.shared.stats.shed, 1);
            self.ctx.metrics.vision_shed.inc();
            let step = self.engine.abandon_job();
            self.apply(step);
        }
    }

    fn on_vision(&mut self, done: VisionOutcome) {
        match done {
            VisionOutcome::Done(step) => {
                self.ctx.metrics.vision_done.inc();
                self.apply(step);
            }
            VisionOutcome::Lost => {
                // The job panicked: the engine still waits for it, so start it afresh.
                self.ctx.metrics.vision_failed.inc();
                warn!(parent: &self.span, "vision job failed; resetting the vehicle's estimator");
                self.engine.reset();
            }
        }
    }

    /// Stamps the outbox's poses not yet stamped with the arrival time of the IMU sample each was
    /// made from and records their latency, up to now (one clock read for all of them).
    fn stamp(&mut self) {
        if self.stamped >= self.outbox.len() {
            return;
        }
        let now = mono_now();
        // The histogram (this thread's shard of it) is locked once per this many poses, not once
        // per pose (at fleet scale, hundreds of thousands of poses a second).
        let mut latencies = [0.0; MAX_BATCH_POSES];
        let mut held = 0;
        for i in self.stamped..self.outbox.len() {
            if let Some((at, wall_ns)) = self.arrival_of(self.outbox[i].t_ns) {
                self.outbox[i].ingest_wall_ns = wall_ns;
                let latency_s = now.saturating_duration_since(at).as_secs_f64();
                self.window.latency(latency_s);
                latencies[held] = latency_s;
                held += 1;
                if held == latencies.len() {
                    self.ctx.metrics.latency.observe_all(&latencies);
                    held = 0;
                }
            }
        }
        self.ctx.metrics.latency.observe_all(&latencies[..held]);
        self.stamped = self.outbox.len();
    }

    /// Publishes the outbox as one batch: the vehicle's latest pose and the fan-out.
    fn publish(&mut self) {
        if self.outbox.is_empty() {
            return;
        }
        self.stamp();
        self.stamped = 0;
        let n = self.outbox.len();
        let mut poses =
            std::mem::replace(&mut self.outbox, Vec::with_capacity(n.min(MAX_BATCH_POSES)));
        // At most MAX_BATCH_POSES a batch, so that the ring's slots, which a lagging watcher
        // keeps, hold a bounded number of bytes (a backlog drained at once, or a message of
        // thousands of samples, would otherwise make one batch of thousands of poses). The usual
        // outbox goes as it is; a larger one is moved out in chunks, each pose once.
        if n > MAX_BATCH_POSES {
            let mut rest = poses.into_iter();
            while rest.len() > MAX_BATCH_POSES {
                self.send_batch(rest.by_ref().take(MAX_BATCH_POSES).collect(), false);
            }
            poses = rest.collect::<Vec<_>>();
        }
        // A vector that grew past its length keeps its capacity: the slot counts that.
        poses.shrink_to(MAX_BATCH_POSES);
        self.send_batch(poses, true);
        self.shared.announce(&self.ctx.hub.lifecycle);
        self.ctx.metrics.poses.inc_by(n as u64);
    }

    /// Puts one batch of this vehicle's poses on the hub, the `latest` one (the vehicle's pose
    /// now) first where `GetPose` reads it.
    fn send_batch(&mut self, poses: Vec<Pose>, latest: bool) {
        let first_seq = self.poses_published;
        self.poses_published += poses.len() as u64;
        let batch = Arc::new(PoseBatch {
            vehicle_id: Arc::clone(&self.shared.id),
            poses,
            first_seq,
        });
        if latest {
            self.shared.set_latest_pose(Arc::clone(&batch));
        }
        let _ = self.ctx.hub.poses.send(batch);
    }

    /// The arrival of the IMU sample a pose at `t_ns` was made from (the newest one not after it).
    fn arrival_of(&mut self, t_ns: i64) -> Option<(Instant, i64)> {
        // Keep the entry a pose matched: the next poses of the same message match it too.
        while self.ingest_times.get(1).is_some_and(|e| e.0 <= t_ns) {
            self.ingest_times.pop_front();
        }
        self.ingest_times
            .front()
            .filter(|e| e.0 <= t_ns)
            .map(|&(_, at, wall)| (at, wall))
    }

    fn publish_health(&mut self) {
        let engine = self.engine.health();
        let resets = counted_since(&mut self.divergence_resets, engine.divergence_resets);
        if resets > 0 {
            self.ctx.metrics.divergence_resets.inc_by(resets);
            warn!(parent: &self.span, resets = engine.divergence_resets,
                "estimator diverged (non-finite state) and was reset");
        }
        let clipped = counted_since(&mut self.imu_clipped, engine.imu_clipped);
        self.ctx.metrics.imu_clipped.inc_by(clipped);
        let bridged = counted_since(&mut self.imu_gaps_bridged, engine.imu_gaps_bridged);
        self.ctx.metrics.imu_gaps_bridged.inc_by(bridged);
        let report =
            Arc::new(
                self.window
                    .report(&self.shared, &engine, self.buffer.len(), mono_now()),
            );
        let previous = self
            .shared
            .latest_health
            .send_replace(Some(Arc::clone(&report)));
        let repeat = previous.is_some_and(|p| repeats(&p, &report));
        let _ = self.ctx.hub.health.send(Arc::new(HealthReport {
            health: report,
            repeat,
            seq: self.health_published,
        }));
        self.health_published += 1;
        self.ctx.metrics.health_reports.inc();
    }
}

#[cfg(test)]
mod tests {
    use super::counted_since;

    #[test]
    fn engine_counters_are_counted_across_engine_restarts() {
        let mut last = 0;
        assert_eq!(counted_since(&mut last, 5), 5);
        assert_eq!(counted_since(&mut last, 5), 0);
        assert_eq!(counted_since(&mut last, 7), 2);
        // A new engine counts from 0: its 3 are new.
        assert_eq!(counted_since(&mut last, 3), 3);
        assert_eq!(counted_since(&mut last, 4), 1);
    }
}
