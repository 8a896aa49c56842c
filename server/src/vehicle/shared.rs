//! What the outside sees of one vehicle without asking its actor: counters, the ingest time gate
//! (its state; the gate itself is [`crate::ingest::gate`]), and the latest pose and health. The
//! estimator itself is owned by the actor alone.

use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, RwLock};

use tokio::sync::watch;
use uavnav_core::VehicleConfig;
use uavnav_proto::v1 as pb;

use crate::ingest::gate::{Admitted, GateLimits, GateRefusal, TimeGate};
use crate::ingest::validate::CameraSpec;

/// Input kinds, in the order that breaks timestamp ties in the reorder window: the values are
/// `SensorEvent::rank()` (IMU, GNSS, magnetometer, barometer, camera), the rule the dataset
/// reader's merge follows too, so a recording and the service fuse ties alike.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum InputKind {
    /// IMU sample.
    Imu = 0,
    /// GNSS fix.
    Gnss = 1,
    /// Magnetometer sample.
    Mag = 2,
    /// Barometer sample.
    Baro = 3,
    /// Camera frame.
    Camera = 4,
}

/// How many input kinds there are.
pub const INPUT_KINDS: usize = 5;

impl InputKind {
    /// Field name used in rejection reasons.
    pub fn field(self) -> &'static str {
        match self {
            InputKind::Imu => "imu",
            InputKind::Gnss => "gnss",
            InputKind::Mag => "mag",
            InputKind::Baro => "baro",
            InputKind::Camera => "camera",
        }
    }
}

/// Monotonic counters of one vehicle (since the actor was created).
#[derive(Debug, Default)]
pub struct VehicleStats {
    /// Accepted IMU samples.
    pub imu: AtomicU64,
    /// Accepted GNSS fixes.
    pub gnss: AtomicU64,
    /// Accepted magnetometer samples.
    pub mag: AtomicU64,
    /// Accepted barometer samples.
    pub baro: AtomicU64,
    /// Accepted camera frames.
    pub camera: AtomicU64,
    /// Rejected as invalid (any transport).
    pub rejected: AtomicU64,
    /// Late (older than the window) or duplicate time.
    pub late: AtomicU64,
    /// Times the vehicle's clock jumped and its stream was taken back at the new time.
    pub resyncs: AtomicU64,
    /// Shed by the overload policy.
    pub shed: AtomicU64,
    /// Dropped for other reasons (duplicates in the window, engine errors).
    pub dropped: AtomicU64,
}

impl VehicleStats {
    /// Adds `n` to a counter.
    pub fn add(counter: &AtomicU64, n: u64) {
        counter.fetch_add(n, Ordering::Relaxed);
    }

    /// Reads a counter.
    pub fn get(counter: &AtomicU64) -> u64 {
        counter.load(Ordering::Relaxed)
    }

    /// Accepted inputs of every kind.
    pub fn accepted(&self) -> u64 {
        Self::get(&self.imu)
            + Self::get(&self.gnss)
            + Self::get(&self.mag)
            + Self::get(&self.baro)
            + Self::get(&self.camera)
    }

    /// The accepted counter of one input kind.
    pub fn of(&self, kind: InputKind) -> &AtomicU64 {
        match kind {
            InputKind::Imu => &self.imu,
            InputKind::Gnss => &self.gnss,
            InputKind::Mag => &self.mag,
            InputKind::Baro => &self.baro,
            InputKind::Camera => &self.camera,
        }
    }
}

/// The shared face of one vehicle.
#[derive(Debug)]
pub struct VehicleShared {
    /// Vehicle identifier.
    pub id: Arc<str>,
    /// Counters.
    pub stats: VehicleStats,
    /// Ingest time gate.
    pub gate: Mutex<TimeGate>,
    /// The vehicle's camera, if configured (frames are refused otherwise).
    pub camera: RwLock<Option<CameraSpec>>,
    /// Whether a configuration was given.
    pub configured: AtomicBool,
    /// Whether the vehicle was announced alive (its Zenoh liveliness token): once configured or
    /// once it has a pose, never for a mere id that sent data ([`VehicleShared::announce`]).
    pub announced: AtomicBool,
    /// The configuration the engine runs with, when one was given: the same one again changes
    /// nothing (a client re-sends it when its stream reopens, which must not reset the filter).
    pub config: Mutex<Option<Arc<VehicleConfig>>>,
    /// Camera frames in the actor's queue (bounded by `vehicles.camera_queue`; beyond, shed).
    pub frames_queued: AtomicUsize,
    /// Their compressed bytes (bounded by `vehicles.camera_queue_bytes`).
    pub frame_bytes_queued: AtomicUsize,
    /// Service wall time of the latest input, ns since the UNIX epoch.
    pub last_input_wall_ns: AtomicI64,
    /// Latest pose batch (a plain slot: nobody waits for changes, and a watch channel's sender
    /// would notify its waiter lists on every message).
    pub latest_pose: Mutex<Option<Arc<crate::output::hub::PoseBatch>>>,
    /// Latest health report.
    pub latest_health: watch::Sender<Option<Arc<pb::VehicleHealth>>>,
}

impl VehicleShared {
    /// A fresh vehicle.
    pub fn new(id: Arc<str>) -> Self {
        Self {
            id,
            stats: VehicleStats::default(),
            gate: Mutex::new(TimeGate::default()),
            camera: RwLock::new(None),
            configured: AtomicBool::new(false),
            announced: AtomicBool::new(false),
            config: Mutex::new(None),
            frames_queued: AtomicUsize::new(0),
            frame_bytes_queued: AtomicUsize::new(0),
            last_input_wall_ns: AtomicI64::new(0),
            latest_pose: Mutex::new(None),
            latest_health: watch::channel(None).0,
        }
    }

    /// Runs the time gate at the service wall time `wall_ns` (a poisoned lock only means another
    /// thread panicked mid-check: the gate's state is still consistent, so it is used as is).
    pub fn admit(
        &self,
        kind: InputKind,
        t_ns: i64,
        wall_ns: i64,
        limits: GateLimits,
        field: impl Fn() -> String,
    ) -> Result<Admitted, GateRefusal> {
        self.gate().admit(kind, t_ns, wall_ns, limits, field)
    }

    /// The time gate, locked (to run a whole batch through it with one lock).
    pub fn gate(&self) -> std::sync::MutexGuard<'_, TimeGate> {
        self.gate.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The configured camera, if any.
    pub fn camera(&self) -> Option<CameraSpec> {
        *self.camera.read().unwrap_or_else(|p| p.into_inner())
    }

    /// Records the configured camera.
    pub fn set_camera(&self, spec: Option<CameraSpec>) {
        *self.camera.write().unwrap_or_else(|p| p.into_inner()) = spec;
    }

    /// The latest pose, if any.
    pub fn pose(&self) -> Option<pb::PoseEstimate> {
        self.latest_pose_batch()?.last()
    }

    /// The latest pose batch, if any.
    pub fn latest_pose_batch(&self) -> Option<Arc<crate::output::hub::PoseBatch>> {
        self.latest_pose
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Records the latest pose batch.
    pub fn set_latest_pose(&self, batch: Arc<crate::output::hub::PoseBatch>) {
        *self.latest_pose.lock().unwrap_or_else(|p| p.into_inner()) = Some(batch);
    }

    /// Announces the vehicle alive on `lifecycle` (its Zenoh liveliness token), the first time
    /// only. Called when it is configured and when it publishes poses.
    ///
    /// Why not when it is created: an id that merely sent data is not yet a vehicle the service
    /// estimates, and a flood of new ids (issue 19, row 1: 20,000 ids of one IMU sample each)
    /// made the service declare a token for every one of them, which Zenoh sends to every peer:
    /// each ground station saw thousands of vehicles come alive and go, and the service held
    /// about 4.5 kB per token.
    pub fn announce(&self, lifecycle: &tokio::sync::broadcast::Sender<(Arc<str>, bool)>) {
        if !self.announced.load(Ordering::Relaxed) && !self.announced.swap(true, Ordering::Relaxed)
        {
            let _ = lifecycle.send((Arc::clone(&self.id), true));
        }
    }

    /// The latest health report, if any.
    pub fn health(&self) -> Option<Arc<pb::VehicleHealth>> {
        self.latest_health.borrow().clone()
    }
}

/// The service's monotonic clock. Tokio's rather than `Instant::now()`: in the service they are
/// the same clock, and a test that pauses tokio's time (`uavnav_tests::paused`) then moves idle
/// eviction, the reorder flush, health periods and latencies with the runtime's timers, without
/// real sleeps.
pub fn mono_now() -> std::time::Instant {
    tokio::time::Instant::now().into_std()
}

/// Nanoseconds since the UNIX epoch on the service's wall clock.
pub fn wall_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as i64)
        .unwrap_or(0)
}
