//! The transport-neutral ingest path: gRPC and Zenoh both hand their decoded messages to
//! [`Ingestor`], which validates them, runs the vehicle's time gate, applies the overload policy
//! and routes them to the vehicle's actor. Every outcome is counted (vehicle health + metrics).
//!
//! | file | responsibility |
//! |---|---|
//! | `mod.rs` | the [`Ingestor`]: validate, gate, route, count |
//! | [`validate`] | field-by-field input checks with precise statuses |
//! | [`gate`] | the time gate: late, duplicate, backwards, future, clock resync |

pub mod gate;
pub mod validate;

use std::sync::Arc;
use std::time::Instant;

use uavnav_proto::v1 as pb;

use crate::ingest::gate::{Admitted, GateLimits, GateRefusal};
use crate::ingest::validate::{ImageLimits, Rejection};
use crate::metrics::{Kind, Outcome, Transport};
use crate::vehicle::actor::{Input, Msg, SendError, Stamped, VehicleHandle};
use crate::vehicle::budgets::camera_pixels;
use crate::vehicle::registry::{Registry, RegistryError};
use crate::vehicle::{InputKind, VehicleStats, mono_now, wall_ns};

/// One decoded input message: the wire contract's borrowed input, under the name the transports
/// and the recorder know it by.
pub use uavnav_proto::input::InputRef as Payload;

/// The metric kind of an input message.
fn payload_kind(p: &Payload<'_>) -> Kind {
    match p {
        Payload::Imu(_) => Kind::Imu,
        Payload::Gnss(_) => Kind::Gnss,
        Payload::Mag(_) => Kind::Mag,
        Payload::Baro(_) => Kind::Baro,
        Payload::Camera(_) => Kind::Camera,
        Payload::Config(_) => Kind::Config,
    }
}

/// The outcome of one message: an ack status and a reason.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Verdict {
    /// Status.
    pub status: pb::IngestStatus,
    /// Reason (empty when accepted without remark).
    pub reason: Reason,
    /// The vehicle runs without a client's configuration (sensor data only): the client should
    /// send its configuration again (`IngestAck.needs_config`).
    pub needs_config: bool,
}

/// The reason of a verdict: made for this message, or shared by every message refused alike (a
/// refusal of permission, made once per principal and verb so that refusing allocates nothing).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reason {
    /// This message's own text.
    Own(String),
    /// A text shared by many messages.
    Shared(Arc<str>),
}

impl Reason {
    /// The text.
    pub fn as_str(&self) -> &str {
        match self {
            Reason::Own(s) => s,
            Reason::Shared(s) => s,
        }
    }
}

/// A reason reads as its text (`verdict.reason.contains(..)`).
impl std::ops::Deref for Reason {
    type Target = str;
    fn deref(&self) -> &str {
        self.as_str()
    }
}

impl From<Reason> for String {
    fn from(r: Reason) -> Self {
        match r {
            Reason::Own(s) => s,
            Reason::Shared(s) => s.as_ref().to_owned(),
        }
    }
}

impl std::fmt::Display for Reason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl Verdict {
    fn accepted(reason: String) -> Self {
        Self {
            status: pb::IngestStatus::Accepted,
            reason: Reason::Own(reason),
            needs_config: false,
        }
    }

    /// Accepted sensor data for vehicle `h`, saying whether it lacks a configuration.
    fn accepted_data(h: &VehicleHandle, reason: String) -> Self {
        Self {
            needs_config: !h
                .shared
                .configured
                .load(std::sync::atomic::Ordering::Relaxed),
            ..Self::accepted(reason)
        }
    }

    /// A refusal with a reason shared by many messages.
    pub fn refused_shared(status: pb::IngestStatus, reason: Arc<str>) -> Self {
        Self {
            status,
            reason: Reason::Shared(reason),
            needs_config: false,
        }
    }

    /// A refusal with its own reason.
    pub fn refused(status: pb::IngestStatus, reason: String) -> Self {
        Self {
            status,
            reason: Reason::Own(reason),
            needs_config: false,
        }
    }
}

impl From<Rejection> for Verdict {
    fn from(r: Rejection) -> Self {
        Self::refused(r.status, r.reason)
    }
}

/// The metric kind of an input kind.
fn metric_kind(k: InputKind) -> Kind {
    match k {
        InputKind::Imu => Kind::Imu,
        InputKind::Gnss => Kind::Gnss,
        InputKind::Mag => Kind::Mag,
        InputKind::Baro => Kind::Baro,
        InputKind::Camera => Kind::Camera,
    }
}

/// The ingest front door shared by every transport.
#[derive(Debug, Clone)]
pub struct Ingestor {
    registry: Arc<Registry>,
    limits: ImageLimits,
    max_message_bytes: usize,
    /// The Foxglove live view, shown every accepted GNSS fix and camera frame.
    live: Option<uavnav_liveview::LiveTap>,
    /// The recorder, handed every accepted input.
    record: Option<crate::output::record::RecordTap>,
}

impl Ingestor {
    /// An ingestor over `registry`.
    pub fn new(registry: Arc<Registry>, limits: ImageLimits, max_message_bytes: usize) -> Self {
        Self {
            registry,
            limits,
            max_message_bytes,
            live: None,
            record: None,
        }
    }

    /// Records every accepted input.
    pub fn with_recorder(mut self, tap: crate::output::record::RecordTap) -> Self {
        self.record = Some(tap);
        self
    }

    /// Shows accepted GNSS fixes and camera frames on a live view.
    pub fn with_live_view(mut self, tap: uavnav_liveview::LiveTap) -> Self {
        self.live = Some(tap);
        self
    }

    /// Largest accepted encoded message, bytes.
    pub fn max_message_bytes(&self) -> usize {
        self.max_message_bytes
    }

    /// The registry.
    pub fn registry(&self) -> &Arc<Registry> {
        &self.registry
    }

    /// Validates and routes one message for vehicle `id`.
    pub async fn submit(&self, transport: Transport, id: &str, payload: Payload<'_>) -> Verdict {
        let kind = payload_kind(&payload);
        let verdict = match self.route(transport, id, payload).await {
            Ok(v) => v,
            Err(r) => {
                self.registry.ctx().metrics.refuse(transport, kind, r.cause);
                tracing::debug!(vehicle = ?id, ?kind, reason = ?r.reason, "input refused");
                if let Some(h) = self.registry.get(id) {
                    let st = &h.shared.stats;
                    let counter = match r.status {
                        pb::IngestStatus::Late | pb::IngestStatus::OutOfRange => &st.late,
                        pb::IngestStatus::ResourceExhausted => &st.shed,
                        _ => &st.rejected,
                    };
                    VehicleStats::add(counter, 1);
                }
                Verdict::from(r)
            }
        };
        let outcome = match verdict.status {
            pb::IngestStatus::Accepted => None, // counted per sample in `route`
            pb::IngestStatus::InvalidArgument => Some(Outcome::Invalid),
            pb::IngestStatus::FailedPrecondition => Some(Outcome::Precondition),
            pb::IngestStatus::Late => Some(Outcome::Late),
            pb::IngestStatus::OutOfRange => Some(Outcome::Future),
            pb::IngestStatus::ResourceExhausted => Some(Outcome::Exhausted),
            pb::IngestStatus::Unspecified | pb::IngestStatus::PermissionDenied => {
                Some(Outcome::Invalid)
            }
        };
        if let Some(o) = outcome {
            self.registry.ctx().metrics.input(transport, kind, o, 1);
        }
        verdict
    }

    async fn route(
        &self,
        transport: Transport,
        id: &str,
        payload: Payload<'_>,
    ) -> Result<Verdict, Rejection> {
        validate::vehicle_id(id)?;
        match payload {
            Payload::Imu(b) => self.imu(transport, id, b).await,
            Payload::Gnss(g) => {
                let fix = validate::gnss_fix(g)?;
                self.single(transport, id, Input::Gnss(fix), payload, |live| {
                    live.gnss(id, g)
                })
                .await
            }
            Payload::Mag(m) => {
                let sample = validate::mag_sample(m)?;
                self.single(transport, id, Input::Mag(sample), payload, |live| {
                    live.mag(id, m)
                })
                .await
            }
            Payload::Baro(b) => {
                let sample = validate::baro_sample(b)?;
                self.single(transport, id, Input::Baro(sample), payload, |_| {})
                    .await
            }
            Payload::Camera(c) => self.camera(transport, id, c).await,
            Payload::Config(c) => self
                .configure(id, c, false)
                .await
                .map(|_| Verdict::accepted(String::new())),
        }
    }

    fn vehicle(&self, id: &str) -> Result<VehicleHandle, Rejection> {
        self.registry
            .get_or_create(id, None)
            .map(|(h, _)| h)
            .map_err(registry_rejection)
    }

    async fn imu(
        &self,
        transport: Transport,
        id: &str,
        b: &pb::ImuBatch,
    ) -> Result<Verdict, Rejection> {
        let samples = validate::imu_batch(b)?;
        let h = self.vehicle(id)?;
        let ctx = self.registry.ctx();
        let (at, wall) = (mono_now(), wall_ns());
        let n = samples.len();
        let GateOutcome {
            batch,
            late,
            future,
            first_refusal,
            resync,
        } = admit_imu(&h.shared, samples, at, wall, ctx.gate_limits());
        let accepted = batch.len() as u64;
        if let Some(direction) = resync {
            self.resync(&h, id, direction).await?;
        }
        if accepted == 0 {
            // Counted once, as a refused message, by `submit`.
            return Err(gate_rejection(first_refusal));
        }
        VehicleStats::add(&h.shared.stats.late, late + future);
        ctx.metrics.input(transport, Kind::Imu, Outcome::Late, late);
        ctx.metrics
            .input(transport, Kind::Imu, Outcome::Future, future);
        // The accepted samples as received, made before the batch moves to the actor.
        let recorded = self.record.as_ref().map(|r| (r, accepted_wire(b, &batch)));
        self.send_data(&h, id, batch).await?;
        if let Some((record, wire)) = recorded {
            record.imu(id, wire);
        }
        VehicleStats::add(&h.shared.stats.imu, accepted);
        ctx.metrics
            .input(transport, Kind::Imu, Outcome::Accepted, accepted);
        h.shared
            .last_input_wall_ns
            .store(wall, std::sync::atomic::Ordering::Relaxed);
        let remark = match first_refusal {
            Some(r) => format!(
                "{} of {n} samples dropped: {}",
                n as u64 - accepted,
                refusal_text(&r)
            ),
            None => String::new(),
        };
        Ok(Verdict::accepted_data(&h, remark))
    }

    /// Gates and routes one validated single-sample input (GNSS fix, magnetometer or barometer
    /// sample) and shows it on the live view when accepted.
    async fn single(
        &self,
        transport: Transport,
        id: &str,
        input: Input,
        payload: Payload<'_>,
        show: impl FnOnce(&uavnav_liveview::LiveTap),
    ) -> Result<Verdict, Rejection> {
        let kind = input.kind();
        let h = self.vehicle(id)?;
        let ctx = self.registry.ctx();
        let wall = wall_ns();
        // Only IMU runs resynchronise a stream: other kinds are admitted or refused.
        h.shared
            .admit(kind, input.t_ns(), wall, ctx.gate_limits(), || {
                kind.field().into()
            })
            .map_err(|r| gate_rejection(Some(r)))?;
        self.send_data(
            &h,
            id,
            vec![Stamped {
                input,
                wall_ns: wall,
                at: mono_now(),
            }],
        )
        .await?;
        VehicleStats::add(h.shared.stats.of(kind), 1);
        if let Some(live) = &self.live {
            show(live);
        }
        if let Some(record) = &self.record {
            record.input(id, payload);
        }
        ctx.metrics
            .input(transport, metric_kind(kind), Outcome::Accepted, 1);
        h.shared
            .last_input_wall_ns
            .store(wall, std::sync::atomic::Ordering::Relaxed);
        Ok(Verdict::accepted_data(&h, String::new()))
    }

    async fn camera(
        &self,
        transport: Transport,
        id: &str,
        c: &pb::CameraFrame,
    ) -> Result<Verdict, Rejection> {
        // A frame never creates a vehicle: without a configuration there is no camera to check.
        let Some(h) = self.registry.get(id) else {
            return Err(Rejection::precondition(format!(
                "camera: vehicle {id:?} has no camera configuration (send a VehicleConfig with `camera` first)"
            )));
        };
        let frame = validate::camera_frame(c, h.shared.camera(), self.limits)?;
        let ctx = self.registry.ctx();
        h.shared
            .admit(
                InputKind::Camera,
                frame.t_ns,
                wall_ns(),
                ctx.gate_limits(),
                || "camera".into(),
            )
            .map_err(|r| gate_rejection(Some(r)))?;
        let wall = wall_ns();
        let stamped = Stamped {
            input: Input::Camera(frame),
            wall_ns: wall,
            at: mono_now(),
        };
        match h.send_camera(stamped, ctx).await {
            Ok(()) => {}
            Err(SendError::Full) => {
                ctx.metrics.vision_shed.inc();
                return Err(Rejection::exhausted(format!(
                    "camera: the vehicle's camera queue is full ({} frames or {} bytes); frame shed",
                    ctx.vehicles.camera_queue, ctx.vehicles.camera_queue_bytes
                )));
            }
            Err(SendError::FullGlobal) => {
                ctx.metrics.vision_shed.inc();
                return Err(Rejection::exhausted(format!(
                    "camera: the service's camera queues hold their {} bytes (vision.queue_bytes); frame shed",
                    ctx.camera_bytes.limit
                )));
            }
            Err(SendError::Closed) => {
                return Err(Rejection::exhausted(
                    "camera: the vehicle is restarting; frame shed",
                ));
            }
        }
        VehicleStats::add(&h.shared.stats.camera, 1);
        if let Some(live) = &self.live {
            live.camera(id, c);
        }
        if let Some(record) = &self.record {
            record.input(id, Payload::Camera(c));
        }
        ctx.metrics
            .input(transport, Kind::Camera, Outcome::Accepted, 1);
        h.shared
            .last_input_wall_ns
            .store(wall, std::sync::atomic::Ordering::Relaxed);
        Ok(Verdict::accepted_data(&h, String::new()))
    }

    /// The vehicle's clock jumped (the gate saw a consistent run of samples far from its stream
    /// time and started a new stream): the actor forgets the old stream (reorder window,
    /// estimator) before the new stream's samples, which follow on the same queue.
    async fn resync(
        &self,
        h: &VehicleHandle,
        id: &str,
        direction: crate::metrics::Direction,
    ) -> Result<(), Rejection> {
        VehicleStats::add(&h.shared.stats.resyncs, 1);
        self.registry.ctx().metrics.resync(direction);
        tracing::info!(vehicle = ?id, ?direction, "vehicle clock jumped; stream taken back at its new time (estimator reset)");
        self.send(h, id, Msg::Reset { reply: None }).await
    }

    /// Sends on the ordered queue, starting a fresh actor once if this one was evicted meanwhile.
    /// Queues sensor data at vehicle `h` once its byte budgets have room (waiting meanwhile).
    async fn send_data(
        &self,
        h: &VehicleHandle,
        id: &str,
        batch: Vec<Stamped>,
    ) -> Result<(), Rejection> {
        let msg = h.reserve(batch, self.registry.ctx()).await;
        self.send(h, id, msg).await
    }

    async fn send(&self, h: &VehicleHandle, id: &str, msg: Msg) -> Result<(), Rejection> {
        let Err(msg) = h.send_or_return(msg).await else {
            return Ok(());
        };
        let fresh = self.vehicle(id)?;
        fresh
            .send(msg)
            .await
            .map_err(|_| Rejection::exhausted(format!("vehicle {id:?} is restarting; resend")))
    }

    /// Creates or reconfigures a vehicle. `wait` waits until the actor applied it.
    /// Returns whether the vehicle was created.
    pub async fn configure(
        &self,
        id: &str,
        c: &pb::VehicleConfig,
        wait: bool,
    ) -> Result<bool, Rejection> {
        validate::vehicle_id(id)?;
        let (config, spec) = validate::vehicle_config(c, self.limits)?;
        // The global pixel budget: this vehicle's camera replaces what it had.
        let old_px = self
            .registry
            .get(id)
            .map_or(0, |h| camera_pixels(h.shared.camera()));
        let new_px = camera_pixels(spec);
        let budget = &self.registry.ctx().camera_pixels;
        if !budget.swap(old_px, new_px) {
            return Err(Rejection::exhausted(format!(
                "camera: {new_px} pixels would exceed the service's {} for all cameras (vision.max_total_camera_pixels; {} configured)",
                budget.limit,
                budget.used()
            )));
        }
        let (h, created) = match self.registry.get_or_create(id, Some(&config)) {
            Ok(created) => created,
            Err(e) => {
                budget.swap(new_px, old_px);
                return Err(registry_rejection(e));
            }
        };
        let same = {
            let mut current = h.shared.config.lock().unwrap_or_else(|p| p.into_inner());
            let same = !created && current.as_deref() == Some(&config);
            if !same {
                *current = Some(Arc::new(config.clone()));
            }
            same
        };
        h.shared.set_camera(spec);
        h.shared
            .configured
            .store(true, std::sync::atomic::Ordering::Relaxed);
        h.shared.announce(&self.registry().ctx().hub.lifecycle);
        if !created && !same {
            let (tx, rx) = tokio::sync::oneshot::channel();
            self.send(
                &h,
                id,
                Msg::Configure {
                    config: Box::new(config),
                    reply: Some(tx),
                },
            )
            .await?;
            if wait {
                let _ = rx.await;
            }
        }
        if let Some(record) = &self.record {
            record.input(id, Payload::Config(c));
        }
        Ok(created)
    }

    /// Restarts a vehicle's estimator; `None` when the vehicle is unknown.
    pub async fn reset(&self, id: &str) -> Result<Option<()>, Rejection> {
        validate::vehicle_id(id)?;
        let Some(h) = self.registry.get(id) else {
            return Ok(None);
        };
        h.shared
            .gate
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clear();
        let (tx, rx) = tokio::sync::oneshot::channel();
        self.send(&h, id, Msg::Reset { reply: Some(tx) }).await?;
        let _ = rx.await;
        Ok(Some(()))
    }
}

/// The IMU samples of one message that passed the vehicle's time gate.
struct GateOutcome {
    batch: Vec<Stamped>,
    late: u64,
    future: u64,
    first_refusal: Option<GateRefusal>,
    /// The gate started a new stream within this batch: `batch` holds the new stream's samples
    /// only, and the actor must be reset before them.
    resync: Option<crate::metrics::Direction>,
}

/// Runs a batch of IMU samples through the time gate under one lock (a plain function: the guard
/// must not live across an await).
fn admit_imu(
    shared: &crate::vehicle::VehicleShared,
    samples: Vec<uavnav_core::ImuSample>,
    at: Instant,
    wall: i64,
    limits: GateLimits,
) -> GateOutcome {
    let mut out = GateOutcome {
        batch: Vec::with_capacity(samples.len()),
        late: 0,
        future: 0,
        first_refusal: None,
        resync: None,
    };
    let mut gate = shared.gate();
    for (i, s) in samples.into_iter().enumerate() {
        let field = || format!("imu.samples[{i}]");
        match gate.admit(InputKind::Imu, s.t_ns, wall, limits, field) {
            Ok(admitted) => {
                if let Admitted::Resync(direction) = admitted {
                    // Samples of the old stream earlier in this batch go with it.
                    out.late += out.batch.len() as u64;
                    out.batch.clear();
                    out.resync = Some(direction);
                }
                out.batch.push(Stamped {
                    input: Input::Imu(s),
                    wall_ns: wall,
                    at,
                });
            }
            Err(r) => {
                match &r {
                    GateRefusal::Future(_) => out.future += 1,
                    _ => out.late += 1,
                }
                out.first_refusal.get_or_insert(r);
            }
        }
    }
    out
}

/// The wire samples of `b` the time gate admitted (`admitted`, in batch order): the whole batch
/// when all were, else those whose times were admitted (a batch's times strictly increase).
fn accepted_wire(b: &pb::ImuBatch, admitted: &[Stamped]) -> pb::ImuBatch {
    if admitted.len() == b.samples.len() {
        return b.clone();
    }
    let mut times = admitted.iter().map(|s| s.input.t_ns()).peekable();
    let samples = b
        .samples
        .iter()
        .filter(|s| {
            if times.peek() == Some(&s.t_ns) {
                times.next();
                true
            } else {
                false
            }
        })
        .copied()
        .collect();
    pb::ImuBatch { samples }
}

fn registry_rejection(e: RegistryError) -> Rejection {
    match e {
        RegistryError::Full(_) => Rejection::exhausted(format!("vehicle_id: {e}")),
        RegistryError::Stopping => Rejection::precondition(e.to_string()),
    }
}

fn refusal_text(r: &GateRefusal) -> &str {
    r.text()
}

fn gate_rejection(r: Option<GateRefusal>) -> Rejection {
    use crate::metrics::Cause;
    let (status, cause, reason) = match r {
        Some(GateRefusal::Late(reason)) => (pb::IngestStatus::Late, Cause::Late, reason),
        Some(GateRefusal::Duplicate(reason)) => (pb::IngestStatus::Late, Cause::Duplicate, reason),
        // A sensor whose clock runs backwards is sending bad data, not late data.
        Some(GateRefusal::Backwards(reason)) => {
            (pb::IngestStatus::InvalidArgument, Cause::Backwards, reason)
        }
        Some(GateRefusal::Future(reason)) => (pb::IngestStatus::OutOfRange, Cause::Future, reason),
        None => return Rejection::invalid("no sample accepted"),
    };
    Rejection::new(status, cause, reason)
}
