//! Prometheus metrics (prometheus-client), shared by every module through [`Metrics`].
//!
//! Labels stay low-cardinality (transport, input kind, outcome): per-vehicle detail lives in the
//! health stream, not in metric labels.

use std::sync::{Arc, OnceLock};

pub mod histogram;

pub use histogram::BatchHistogram;

use prometheus_client::encoding::{EncodeLabelSet, EncodeLabelValue, LabelValueEncoder};
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::exponential_buckets;
use prometheus_client::registry::Registry;

/// Which transport an input came through.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Transport {
    /// gRPC `Ingest`.
    Grpc,
    /// Zenoh subscription.
    Zenoh,
}

/// Kind of input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kind {
    /// IMU sample.
    Imu,
    /// GNSS fix.
    Gnss,
    /// Magnetometer sample.
    Mag,
    /// Barometer sample.
    Baro,
    /// Camera frame.
    Camera,
    /// Vehicle configuration.
    Config,
    /// Undecodable message (kind unknown).
    Malformed,
}

/// What happened to an input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Outcome {
    /// Accepted into the vehicle's window.
    Accepted,
    /// Invalid content.
    Invalid,
    /// Not applicable in the vehicle's state.
    Precondition,
    /// Older than the window or a duplicate.
    Late,
    /// Too far ahead of the vehicle's clock.
    Future,
    /// Shed by the overload policy.
    Shed,
    /// Refused because a limit was reached (too many vehicles, oversize).
    Exhausted,
}

/// Why an input was refused: the `reason` label of `uavnav_inputs_refused_total` (the ack and the
/// debug log carry the full text naming the field).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Cause {
    /// A number is NaN or infinite.
    NotFinite,
    /// A number is outside its plausible range (an absurd magnitude).
    OutOfRange,
    /// A required field is absent.
    Missing,
    /// An unknown or unspecified enum value.
    UnknownEnum,
    /// Any other invalid content (bad id, corrupt image, unordered batch...).
    Invalid,
    /// A sensor's time went backwards.
    Backwards,
    /// Older than the reorder window.
    Late,
    /// The same time as the previous sample of its kind.
    Duplicate,
    /// Too far ahead of the vehicle's clock.
    Future,
    /// Not applicable in the vehicle's state (a frame without a camera configured).
    Precondition,
    /// A limit was reached (queue, vehicles).
    Exhausted,
    /// Above a size limit: message bytes, IMU samples in a batch, image bytes or pixels (checked
    /// before decoding).
    TooLarge,
    /// Undecodable protobuf.
    Malformed,
    /// Compressed data that does not decompress (bad gzip / zstd).
    Compression,
    /// A camera frame whose body does not decode although its header was good (counted when the
    /// vision job finds it, after the frame was acknowledged).
    CorruptImage,
    /// A camera frame whose decoded size is not its header's.
    ImageSize,
    /// The caller has no grant for this vehicle (also in `uavnav_auth_refused_total`).
    PermissionDenied,
    /// A Zenoh put on a key under `uavnav/v1/vehicle/` that names no input.
    UnknownKey,
}

/// Why the recorder dropped a message: the `reason` label of `uavnav_record_dropped_total`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RecordDrop {
    /// The byte-bounded queue to the writer was full (the writer is slower than the input).
    QueueFull,
    /// The output feed (poses, health) lagged behind the hub's ring.
    Lagged,
    /// Writing failed (a full disk, permissions): the file is given up and retried later.
    WriteError,
}

/// Label values are the lowercase variant names (Prometheus convention).
macro_rules! lowercase_label {
    ($t:ty { $($v:ident => $s:literal),* $(,)? }) => {
        impl EncodeLabelValue for $t {
            fn encode(&self, encoder: &mut LabelValueEncoder<'_>) -> Result<(), std::fmt::Error> {
                use std::fmt::Write;
                encoder.write_str(match self { $(Self::$v => $s),* })
            }
        }

        impl $t {
            /// Every variant (the match above is exhaustive, so none is left out).
            #[allow(dead_code)] // used for some label types only
            pub const ALL: &'static [Self] = &[$(Self::$v),*];
        }
    };
}

lowercase_label!(Transport { Grpc => "grpc", Zenoh => "zenoh" });
lowercase_label!(Kind { Imu => "imu", Gnss => "gnss", Mag => "mag", Baro => "baro", Camera => "camera", Config => "config", Malformed => "malformed" });
lowercase_label!(Cause {
    NotFinite => "not_finite",
    OutOfRange => "out_of_range",
    Missing => "missing",
    UnknownEnum => "unknown_enum",
    Invalid => "invalid",
    Backwards => "backwards",
    Late => "late",
    Duplicate => "duplicate",
    Future => "future",
    Precondition => "precondition",
    Exhausted => "exhausted",
    TooLarge => "too_large",
    Malformed => "malformed",
    Compression => "compression",
    CorruptImage => "corrupt_image",
    ImageSize => "image_size",
    PermissionDenied => "permission_denied",
    UnknownKey => "unknown_key",
});
lowercase_label!(RecordDrop { QueueFull => "queue_full", Lagged => "lagged", WriteError => "write_error" });
lowercase_label!(Outcome {
    Accepted => "accepted",
    Invalid => "invalid",
    Precondition => "precondition",
    Late => "late",
    Future => "future",
    Shed => "shed",
    Exhausted => "exhausted",
});

/// Labels of `uavnav_inputs_total`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, EncodeLabelSet)]
pub struct InputLabels {
    /// Transport.
    pub transport: Transport,
    /// Kind.
    pub kind: Kind,
    /// Outcome.
    pub outcome: Outcome,
}

impl InputLabels {
    /// Where these labels' counter is kept in [`Metrics`]'s cache: one slot per combination,
    /// below [`INPUT_LABEL_SETS`] (the variants are numbered from 0, as declared).
    fn index(&self) -> usize {
        (self.transport as usize * Kind::ALL.len() + self.kind as usize) * Outcome::ALL.len()
            + self.outcome as usize
    }
}

/// Combinations of [`InputLabels`].
const INPUT_LABEL_SETS: usize = Transport::ALL.len() * Kind::ALL.len() * Outcome::ALL.len();

/// Labels of `uavnav_inputs_refused_total`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, EncodeLabelSet)]
pub struct RefusedLabels {
    /// Transport.
    pub transport: Transport,
    /// Kind.
    pub kind: Kind,
    /// Why.
    pub reason: Cause,
}

/// Labels of `uavnav_clock_resyncs_total`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, EncodeLabelSet)]
pub struct ResyncLabels {
    /// Which way the vehicle's clock jumped.
    pub direction: Direction,
}

/// Which way a vehicle's clock jumped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Back (a restarted clock: a rebooted drone, a replay started over).
    Back,
    /// Ahead, without the silence that would explain it.
    Ahead,
}

lowercase_label!(Direction { Back => "back", Ahead => "ahead" });

/// Labels of `uavnav_vision_frames_rejected_total`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, EncodeLabelSet)]
pub struct FrameRejectLabels {
    /// Why.
    pub reason: Cause,
}

/// Labels of `uavnav_record_dropped_total`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, EncodeLabelSet)]
pub struct RecordDropLabels {
    /// Why.
    pub reason: RecordDrop,
}

/// Every metric of the service.
#[derive(Debug, Clone)]
pub struct Metrics {
    /// The registry `/metrics` encodes.
    pub registry: Arc<Registry>,
    /// Inputs by transport, kind and outcome (IMU counted per sample).
    pub inputs: Family<InputLabels, Counter>,
    /// The counters of `inputs`, each kept here the first time its labels are used: counting an
    /// input then takes no lock and hashes nothing (every IMU batch counts one).
    input_counters: Arc<[OnceLock<Counter>; INPUT_LABEL_SETS]>,
    /// Refused input messages by transport, kind and reason (a refused IMU batch counts once).
    pub refused: Family<RefusedLabels, Counter>,
    /// Messages the recorder dropped, by reason.
    pub record_dropped: Family<RecordDropLabels, Counter>,
    /// Messages the recorder wrote.
    pub record_written: Counter,
    /// Message bytes the recorder wrote (encoded protobuf, before MCAP compression).
    pub record_bytes: Counter,
    /// Bytes waiting in the recorder's queue.
    pub record_queue_bytes: Gauge,
    /// Recording files closed (rotation or shutdown).
    pub record_files: Counter,
    /// Poses published.
    pub poses: Counter,
    /// Health reports published.
    pub health_reports: Counter,
    /// Live vehicle actors.
    pub vehicles: Gauge,
    /// Actors evicted for idleness.
    pub evictions: Counter,
    /// Idle unconfigured vehicles displaced by a new vehicle at the vehicle limit.
    pub admission_evictions: Counter,
    /// Ingest-to-pose latency, s (observed a published batch at a time).
    pub latency: BatchHistogram,
    /// Vision jobs completed.
    pub vision_done: Counter,
    /// Vision jobs that failed (engine error or panic).
    pub vision_failed: Counter,
    /// Camera frames shed because the vision pool or a vehicle's camera queue was full.
    pub vision_shed: Counter,
    /// Vision jobs queued or running.
    pub vision_in_flight: Gauge,
    /// Late / duplicate inputs dropped inside the actors' reorder windows.
    pub reorder_dropped: Counter,
    /// Engine errors on inputs that passed validation.
    pub engine_errors: Counter,
    /// Outputs the Zenoh publisher could not keep up with (skipped).
    pub zenoh_output_lagged: Counter,
    /// Messages Zenoh dropped on links congested beyond `zenoh.stalled_link_ms` (a subscriber
    /// that stopped reading), all peers together.
    pub zenoh_dropped: Counter,
    /// Health reports that repeat a quiet vehicle's previous one and that Zenoh did not publish
    /// for want of `zenoh.repeat_health_per_s`.
    pub zenoh_health_repeats_skipped: Counter,
    /// Poses put on Zenoh: only those of vehicles some remote subscriber watches.
    pub zenoh_poses_published: Counter,
    /// Output batches (poses) and reports (health) gRPC watch streams skipped because they were
    /// behind.
    pub watch_lagged: Counter,
    /// Samples received on the Zenoh input key expressions (before decoding).
    pub zenoh_samples: Counter,
    /// Messages the Foxglove live view skipped because it was behind.
    pub foxglove_dropped: Counter,
    /// Vehicles taken back at a new time after their clock jumped (a consistent run of samples
    /// far from the stream time), by direction.
    pub clock_resyncs: Family<ResyncLabels, Counter>,
    /// Acknowledged camera frames the vision job could not use because the image itself is bad
    /// (corrupt body, size not the header's), by reason.
    pub frames_rejected: Family<FrameRejectLabels, Counter>,
    /// Estimator resets after a non-finite state (the vehicle reported DIVERGED).
    pub divergence_resets: Counter,
    /// CPU time of the whole process, s (`crate::process`; brought up to date when encoded).
    pub process_cpu: Counter<f64, std::sync::atomic::AtomicU64>,
    /// Resident memory of the process, bytes (brought up to date when encoded).
    pub process_resident: Gauge,
    /// IMU samples the estimators found clipped (at the sensor's range), all vehicles.
    pub imu_clipped: Counter,
    /// IMU gaps the estimators bridged instead of restarting.
    pub imu_gaps_bridged: Counter,
    /// Authentication and authorization refusals, TLS handshake failures.
    pub security: crate::security::SecurityMetrics,
    /// Connections open, refused and closed, by listener.
    pub connections: crate::transport::conn::ConnectionMetrics,
    /// The gRPC arrival budget: bytes held, streams refused.
    pub arrivals: crate::transport::arrivals::ArrivalMetrics,
    /// The gRPC stream limit: streams open, calls refused.
    pub streams: crate::transport::stream_limit::StreamMetrics,
}

impl Metrics {
    /// Creates and registers every metric.
    pub fn new() -> Self {
        let mut registry = Registry::with_prefix("uavnav");
        let inputs = Family::<InputLabels, Counter>::default();
        let refused = Family::<RefusedLabels, Counter>::default();
        let record_dropped = Family::<RecordDropLabels, Counter>::default();
        let record_written = Counter::default();
        let record_bytes = Counter::default();
        let record_queue_bytes = Gauge::default();
        let record_files = Counter::default();
        let poses = Counter::default();
        let health_reports = Counter::default();
        let vehicles = Gauge::default();
        let evictions = Counter::default();
        let latency = BatchHistogram::new(exponential_buckets(0.0005, 2.0, 14));
        let vision_done = Counter::default();
        let vision_failed = Counter::default();
        let vision_shed = Counter::default();
        let vision_in_flight = Gauge::default();
        let reorder_dropped = Counter::default();
        let engine_errors = Counter::default();
        let zenoh_output_lagged = Counter::default();
        let zenoh_dropped = Counter::default();
        let zenoh_health_repeats_skipped = Counter::default();
        let zenoh_poses_published = Counter::default();
        let watch_lagged = Counter::default();
        let zenoh_samples = Counter::default();
        let foxglove_dropped = Counter::default();
        let clock_resyncs = Family::<ResyncLabels, Counter>::default();
        let frames_rejected = Family::<FrameRejectLabels, Counter>::default();
        let divergence_resets = Counter::default();
        let process_cpu = Counter::<f64, std::sync::atomic::AtomicU64>::default();
        let process_resident = Gauge::default();
        registry.register(
            "clock_resyncs",
            "Vehicles taken back at a new time after a consistent jump of their clock",
            clock_resyncs.clone(),
        );
        registry.register(
            "vision_frames_rejected",
            "Acknowledged camera frames whose image turned out bad when decoded, by reason",
            frames_rejected.clone(),
        );
        registry.register(
            "divergence_resets",
            "Estimator resets after a non-finite state (reported as mode DIVERGED)",
            divergence_resets.clone(),
        );
        registry.register(
            "process_cpu_seconds",
            "User and system CPU time of the service process, s (Linux /proc; 0 elsewhere)",
            process_cpu.clone(),
        );
        registry.register(
            "process_resident_memory_bytes",
            "Resident memory of the service process, bytes (Linux /proc; 0 elsewhere)",
            process_resident.clone(),
        );
        registry.register(
            "inputs",
            "Sensor inputs by transport, kind and outcome",
            inputs.clone(),
        );
        registry.register(
            "inputs_refused",
            "Refused input messages by transport, kind and reason",
            refused.clone(),
        );
        registry.register(
            "record_dropped",
            "Messages the recorder dropped (queue full, output lag, write error)",
            record_dropped.clone(),
        );
        registry.register(
            "record_written",
            "Messages the recorder wrote",
            record_written.clone(),
        );
        registry.register(
            "record_bytes",
            "Message bytes the recorder wrote (before compression)",
            record_bytes.clone(),
        );
        registry.register(
            "record_queue_bytes",
            "Bytes waiting in the recorder's queue",
            record_queue_bytes.clone(),
        );
        registry.register(
            "record_files",
            "Recording files closed",
            record_files.clone(),
        );
        registry.register("poses", "Pose estimates published", poses.clone());
        registry.register(
            "health_reports",
            "Vehicle health reports published",
            health_reports.clone(),
        );
        registry.register("vehicles", "Vehicle actors alive", vehicles.clone());
        registry.register(
            "evictions",
            "Vehicle actors evicted after the idle time",
            evictions.clone(),
        );
        registry.register(
            "ingest_to_pose_latency_seconds",
            "Ingest-to-pose latency",
            latency.clone(),
        );
        registry.register(
            "vision_jobs_done",
            "Vision jobs completed",
            vision_done.clone(),
        );
        registry.register(
            "vision_jobs_failed",
            "Vision jobs failed",
            vision_failed.clone(),
        );
        registry.register(
            "vision_frames_shed",
            "Camera frames shed by the overload policy",
            vision_shed.clone(),
        );
        registry.register(
            "vision_in_flight",
            "Vision jobs queued or running",
            vision_in_flight.clone(),
        );
        registry.register(
            "reorder_dropped",
            "Inputs dropped as late or duplicate in reorder windows",
            reorder_dropped.clone(),
        );
        registry.register(
            "engine_errors",
            "Estimator errors on validated inputs",
            engine_errors.clone(),
        );
        registry.register(
            "zenoh_output_lagged",
            "Outputs skipped by a lagging Zenoh publisher",
            zenoh_output_lagged.clone(),
        );
        registry.register(
            "zenoh_dropped",
            "Messages Zenoh dropped on links congested beyond zenoh.stalled_link_ms (subscribers that stopped reading), all peers",
            zenoh_dropped.clone(),
        );
        registry.register(
            "zenoh_health_repeats_skipped",
            "Quiet vehicles' repeated health reports not published on Zenoh (beyond zenoh.repeat_health_per_s)",
            zenoh_health_repeats_skipped.clone(),
        );
        registry.register(
            "zenoh_poses_published",
            "Poses put on Zenoh (only those of vehicles some remote subscriber watches)",
            zenoh_poses_published.clone(),
        );
        registry.register(
            "watch_lagged",
            "Pose batches and health reports gRPC watch streams skipped because they were behind",
            watch_lagged.clone(),
        );
        registry.register(
            "zenoh_samples",
            "Samples received on the Zenoh input key expressions, before decoding",
            zenoh_samples.clone(),
        );
        registry.register(
            "foxglove_dropped",
            "Poses, GNSS fixes and camera frames the Foxglove live view skipped because it was behind",
            foxglove_dropped.clone(),
        );
        let security = crate::security::SecurityMetrics::register(&mut registry);
        let connections = crate::transport::conn::ConnectionMetrics::register(&mut registry);
        let arrivals = crate::transport::arrivals::ArrivalMetrics::register(&mut registry);
        let streams = crate::transport::stream_limit::StreamMetrics::register(&mut registry);
        let imu_clipped = Counter::default();
        registry.register(
            "imu_clipped",
            "IMU samples the estimators found clipped (at the sensor's range; fused with inflated noise)",
            imu_clipped.clone(),
        );
        let imu_gaps_bridged = Counter::default();
        registry.register(
            "imu_gaps_bridged",
            "IMU gaps of 0.5-5 s the estimators integrated across with a widened covariance instead of restarting",
            imu_gaps_bridged.clone(),
        );
        let admission_evictions = Counter::default();
        registry.register(
            "admission_evictions",
            "Idle unconfigured vehicles displaced by a new vehicle at the vehicle limit",
            admission_evictions.clone(),
        );
        Self {
            registry: Arc::new(registry),
            inputs,
            input_counters: Arc::new(std::array::from_fn(|_| OnceLock::new())),
            refused,
            record_dropped,
            record_written,
            record_bytes,
            record_queue_bytes,
            record_files,
            poses,
            health_reports,
            vehicles,
            evictions,
            latency,
            vision_done,
            vision_failed,
            vision_shed,
            vision_in_flight,
            reorder_dropped,
            engine_errors,
            zenoh_output_lagged,
            zenoh_dropped,
            zenoh_health_repeats_skipped,
            zenoh_poses_published,
            watch_lagged,
            zenoh_samples,
            foxglove_dropped,
            clock_resyncs,
            frames_rejected,
            divergence_resets,
            process_cpu,
            process_resident,
            imu_clipped,
            imu_gaps_bridged,
            security,
            connections,
            arrivals,
            streams,
            admission_evictions,
        }
    }

    /// Counts one clock resynchronisation.
    pub fn resync(&self, direction: Direction) {
        self.clock_resyncs
            .get_or_create(&ResyncLabels { direction })
            .inc();
    }

    /// Counts one acknowledged frame the vision job refused.
    pub fn frame_rejected(&self, reason: Cause) {
        self.frames_rejected
            .get_or_create(&FrameRejectLabels { reason })
            .inc();
    }

    /// Counts `n` inputs.
    pub fn input(&self, transport: Transport, kind: Kind, outcome: Outcome, n: u64) {
        let labels = InputLabels {
            transport,
            kind,
            outcome,
        };
        self.input_counters[labels.index()]
            .get_or_init(|| self.inputs.get_or_create(&labels).clone())
            .inc_by(n);
    }

    /// Counts one refused message.
    pub fn refuse(&self, transport: Transport, kind: Kind, reason: Cause) {
        self.refused
            .get_or_create(&RefusedLabels {
                transport,
                kind,
                reason,
            })
            .inc();
    }

    /// Counts `n` messages the recorder dropped.
    pub fn record_dropped(&self, reason: RecordDrop, n: u64) {
        self.record_dropped
            .get_or_create(&RecordDropLabels { reason })
            .inc_by(n);
    }

    /// The text exposition of every metric.
    pub fn encode(&self) -> String {
        self.update_process();
        let mut out = String::new();
        // Writing into a String cannot fail.
        let _ = prometheus_client::encoding::text::encode(&mut out, &self.registry);
        out
    }

    /// Brings the process figures up to date. The CPU counter moves forward by the time used
    /// since it was last brought up to date; one update at a time, or two scrapes at once
    /// would both add the same difference.
    fn update_process(&self) {
        static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());
        let _guard = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
        let Some(now) = crate::process::read() else {
            return;
        };
        let delta = now.cpu_s - self.process_cpu.get();
        if delta > 0.0 {
            self.process_cpu.inc_by(delta);
        }
        self.process_resident
            .set(i64::try_from(now.resident_bytes).unwrap_or(i64::MAX));
    }
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn every_label_set() -> impl Iterator<Item = InputLabels> {
        Transport::ALL.iter().flat_map(|&transport| {
            Kind::ALL.iter().flat_map(move |&kind| {
                Outcome::ALL.iter().map(move |&outcome| InputLabels {
                    transport,
                    kind,
                    outcome,
                })
            })
        })
    }

    #[test]
    fn every_input_label_set_has_its_own_cache_slot() {
        let mut seen = [false; INPUT_LABEL_SETS];
        for labels in every_label_set() {
            let i = labels.index();
            assert!(!seen[i], "{labels:?} shares slot {i}");
            seen[i] = true;
        }
        assert!(seen.iter().all(|s| *s));
    }

    #[test]
    fn cached_input_counters_are_the_familys() {
        let m = Metrics::new();
        // Before any input, no series (the cache creates a series only when used).
        assert!(!m.encode().contains("uavnav_inputs_total{"));
        m.input(Transport::Grpc, Kind::Imu, Outcome::Accepted, 4);
        m.input(Transport::Grpc, Kind::Imu, Outcome::Accepted, 3);
        m.input(Transport::Zenoh, Kind::Gnss, Outcome::Late, 1);
        for labels in every_label_set() {
            let want = match (labels.transport, labels.kind, labels.outcome) {
                (Transport::Grpc, Kind::Imu, Outcome::Accepted) => 7,
                (Transport::Zenoh, Kind::Gnss, Outcome::Late) => 1,
                _ => 0,
            };
            assert_eq!(m.inputs.get_or_create(&labels).get(), want, "{labels:?}");
        }
        let text = m.encode();
        assert!(
            text.contains(
                "uavnav_inputs_total{transport=\"grpc\",kind=\"imu\",outcome=\"accepted\"} 7"
            ),
            "{text}"
        );
        // A clone shares the cache and the family.
        m.clone()
            .input(Transport::Grpc, Kind::Imu, Outcome::Accepted, 1);
        assert!(text.len() <= m.encode().len());
        assert!(m.encode().contains("outcome=\"accepted\"} 8"));
    }
}
