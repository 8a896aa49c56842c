//! What the outside sees of one vehicle without asking its actor: counters, the ingest time gate,
//! and the latest pose and health. The estimator itself is owned by the actor alone.

use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, RwLock};

use tokio::sync::watch;
use uavnav_proto::v1 as pb;

use crate::validate::CameraSpec;

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

/// Why the time gate refused a sample.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GateRefusal {
    /// Older than the reorder window allows.
    Late(String),
    /// The same time as the previous sample of its kind.
    Duplicate(String),
    /// A magnetometer or barometer sample older than the previous one of its kind: the sensor's
    /// clock went backwards.
    Backwards(String),
    /// Too far ahead of the vehicle's newest sample.
    Future(String),
}

impl GateRefusal {
    /// The reason text.
    pub fn text(&self) -> &str {
        match self {
            GateRefusal::Late(s)
            | GateRefusal::Duplicate(s)
            | GateRefusal::Backwards(s)
            | GateRefusal::Future(s) => s,
        }
    }
}

/// Whether a kind's samples must come in increasing time order. Magnetometer and barometer samples
/// arrive one per message from one sensor, so an older sample means the sensor's clock jumped back
/// (the estimator would refuse it silently behind the window); IMU batches, fixes and frames may
/// arrive out of order within the reorder window (several links, retransmissions).
fn strictly_ordered(kind: InputKind) -> bool {
    matches!(kind, InputKind::Mag | InputKind::Baro)
}

/// Per-vehicle timestamp bookkeeping done at ingest, so a sender learns at once (in its ack)
/// that a sample is late, duplicated or from the far future.
#[derive(Debug, Default)]
pub struct TimeGate {
    newest_ns: Option<i64>,
    /// Service wall clock when `newest_ns` was admitted.
    newest_wall_ns: i64,
    last_ns: [Option<i64>; INPUT_KINDS],
}

impl TimeGate {
    /// Checks `t_ns` for `kind`, arriving at service wall time `wall_ns`, and records it when
    /// accepted.
    ///
    /// "Too far ahead" is judged against the newest sample *plus the wall time elapsed since it
    /// arrived*: a vehicle whose link dropped for a minute resumes a minute later in its own time,
    /// and must be taken back, while a timestamp from the far future in a running stream is not.
    pub fn admit(
        &mut self,
        kind: InputKind,
        t_ns: i64,
        wall_ns: i64,
        window_ns: i64,
        max_future_ns: i64,
        field: impl Fn() -> String,
    ) -> Result<(), GateRefusal> {
        if let Some(newest) = self.newest_ns {
            let silent_ns = wall_ns.saturating_sub(self.newest_wall_ns).max(0);
            let limit_ns = max_future_ns.saturating_add(silent_ns);
            if t_ns > newest.saturating_add(limit_ns) {
                return Err(GateRefusal::Future(format!(
                    "{}: t_ns {t_ns} is {:.3} s ahead of the vehicle's newest sample (limit {:.3} s: {:.3} s + {:.3} s without input)",
                    field(),
                    (t_ns - newest) as f64 * 1e-9,
                    limit_ns as f64 * 1e-9,
                    max_future_ns as f64 * 1e-9,
                    silent_ns as f64 * 1e-9
                )));
            }
            if t_ns < newest.saturating_sub(window_ns) {
                return Err(GateRefusal::Late(format!(
                    "{}: t_ns {t_ns} is {:.3} s older than the vehicle's newest sample (reorder window {:.3} s)",
                    field(),
                    (newest - t_ns) as f64 * 1e-9,
                    window_ns as f64 * 1e-9
                )));
            }
        }
        let last = self.last_ns[kind as usize];
        if last == Some(t_ns) {
            return Err(GateRefusal::Duplicate(format!(
                "{}: duplicate t_ns {t_ns}",
                field()
            )));
        }
        if let Some(last) = last.filter(|&l| strictly_ordered(kind) && t_ns < l) {
            return Err(GateRefusal::Backwards(format!(
                "{}: time went backwards: t_ns {t_ns} is {:.6} s before the previous {} sample ({last})",
                field(),
                (last - t_ns) as f64 * 1e-9,
                kind.field()
            )));
        }
        self.last_ns[kind as usize] = Some(t_ns);
        if self.newest_ns.is_none_or(|n| t_ns > n) {
            self.newest_ns = Some(t_ns);
            self.newest_wall_ns = wall_ns;
        }
        Ok(())
    }

    /// Forgets the stream (after a reset).
    pub fn clear(&mut self) {
        *self = Self::default();
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
    /// Camera frames in the actor's queue (bounded by `vehicles.camera_queue`; beyond, shed).
    pub frames_queued: AtomicUsize,
    /// Service wall time of the latest input, ns since the UNIX epoch.
    pub last_input_wall_ns: AtomicI64,
    /// Latest pose batch (a plain slot: nobody waits for changes, and a watch channel's sender
    /// would notify its waiter lists on every message).
    pub latest_pose: Mutex<Option<Arc<crate::hub::PoseBatch>>>,
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
            frames_queued: AtomicUsize::new(0),
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
        limits: (i64, i64),
        field: impl Fn() -> String,
    ) -> Result<(), GateRefusal> {
        self.gate()
            .admit(kind, t_ns, wall_ns, limits.0, limits.1, field)
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
    pub fn latest_pose_batch(&self) -> Option<Arc<crate::hub::PoseBatch>> {
        self.latest_pose
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Records the latest pose batch.
    pub fn set_latest_pose(&self, batch: Arc<crate::hub::PoseBatch>) {
        *self.latest_pose.lock().unwrap_or_else(|p| p.into_inner()) = Some(batch);
    }

    /// The latest health report, if any.
    pub fn health(&self) -> Option<Arc<pb::VehicleHealth>> {
        self.latest_health.borrow().clone()
    }
}

/// Nanoseconds since the UNIX epoch on the service's wall clock.
pub fn wall_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as i64)
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gate_refuses_late_duplicate_and_future() {
        let mut g = TimeGate::default();
        let (w, f) = (100, 1_000);
        assert!(
            g.admit(InputKind::Imu, 1_000, 0, w, f, || "imu".into())
                .is_ok()
        );
        assert!(matches!(
            g.admit(InputKind::Imu, 1_000, 0, w, f, || "imu".into()),
            Err(GateRefusal::Duplicate(_))
        ));
        assert!(
            g.admit(InputKind::Gnss, 950, 0, w, f, || "gnss".into())
                .is_ok(),
            "within the window"
        );
        assert!(matches!(
            g.admit(InputKind::Gnss, 800, 0, w, f, || "gnss".into()),
            Err(GateRefusal::Late(_))
        ));
        assert!(matches!(
            g.admit(InputKind::Imu, 3_000, 0, w, f, || "imu".into()),
            Err(GateRefusal::Future(_))
        ));
        assert!(
            g.admit(InputKind::Imu, 1_900, 0, w, f, || "imu".into())
                .is_ok()
        );
    }

    #[test]
    fn gate_refuses_mag_and_baro_going_backwards_but_not_imu() {
        let mut g = TimeGate::default();
        let (w, f) = (100, 1_000);
        for kind in [InputKind::Mag, InputKind::Baro, InputKind::Imu] {
            assert!(g.admit(kind, 1_000, 0, w, f, || "x".into()).is_ok());
        }
        let e = g.admit(InputKind::Mag, 990, 0, w, f, || "mag".into());
        assert!(
            matches!(e, Err(GateRefusal::Backwards(ref m)) if m.starts_with("mag: time went backwards")),
            "{e:?}"
        );
        assert!(matches!(
            g.admit(InputKind::Baro, 999, 0, w, f, || "baro".into()),
            Err(GateRefusal::Backwards(_))
        ));
        assert!(
            g.admit(InputKind::Imu, 990, 0, w, f, || "imu".into())
                .is_ok(),
            "IMU may be reordered within the window"
        );
        assert!(
            g.admit(InputKind::Mag, 1_010, 0, w, f, || "mag".into())
                .is_ok()
        );
    }

    #[test]
    fn gate_takes_a_stream_back_after_a_silence_as_long_as_the_jump() {
        let mut g = TimeGate::default();
        let (w, f) = (20_000_000, 10_000_000_000); // 20 ms window, 10 s ahead at most
        let s = 1_000_000_000i64;
        assert!(
            g.admit(InputKind::Imu, 100 * s, 0, w, f, || "imu".into())
                .is_ok()
        );
        // 60 s later in the vehicle's time, but only 1 s later on the wall clock: refused...
        let err = g.admit(InputKind::Imu, 160 * s, s, w, f, || "imu".into());
        assert!(
            matches!(err, Err(GateRefusal::Future(ref m)) if m.contains("without input")),
            "{err:?}"
        );
        // ...after 55 s of silence it is a link that came back: taken.
        assert!(
            g.admit(InputKind::Imu, 160 * s, 55 * s, w, f, || "imu".into())
                .is_ok()
        );
        // A running stream still cannot jump ahead.
        let err = g.admit(InputKind::Imu, 200 * s, 55 * s + 5_000_000, w, f, || {
            "imu".into()
        });
        assert!(matches!(err, Err(GateRefusal::Future(_))), "{err:?}");
    }
}
