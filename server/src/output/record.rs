//! Recording: every accepted input and every pose, of every vehicle, to rotating MCAP files in
//! the layout of `uavnav record` (the dataset crate's [`McapWriter`]), so that `uavnav replay
//! FILE.mcap` through a fresh service gives the same poses.
//!
//! The ingest path and the pose feed hand records to [`RecordTap`], which never waits: the queue
//! to the writer thread is bounded in bytes, and a record that does not fit is dropped and counted
//! (`uavnav_record_dropped_total{reason="queue_full"}`). The writer is an OS thread (MCAP writing
//! is blocking file I/O and compression, kept off the async runtime). A failed write (a full disk)
//! gives the file up, drops the record (`reason="write_error"`) and opens a new file at most once
//! per [`RETRY_AFTER`].
//!
//! Files are `uavnavd-NNNNNN.mcap` in the configured directory, one per rotation holding every
//! vehicle; the index continues after the highest one found at start, so a restart never
//! overwrites. A file is finished (summary and index written) on rotation and at shutdown; then
//! the oldest files are deleted until the directory's recordings fit `retain_bytes`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use prost::Message;
use tokio::sync::{broadcast, oneshot};
use tracing::{info, warn};
use uavnav_core::{Lla, LocalFrame};
use uavnav_dataset::{McapOptions, McapWriter};
use uavnav_proto::input::InputRef;
use uavnav_proto::v1 as pb;

use crate::config::RecordConfig;
use crate::ingest::Payload;
use crate::metrics::{Metrics, RecordDrop};
use crate::output::hub::{Hub, PoseBatch};
use crate::vehicle::wall_ns;

/// After a failed open or write, the writer waits this long before opening a new file (records
/// meanwhile are dropped as write errors): a full disk is not retried per message.
pub const RETRY_AFTER: Duration = Duration::from_secs(1);
/// File name prefix; the full name is `uavnavd-NNNNNN.mcap`.
pub const FILE_PREFIX: &str = "uavnavd-";
/// What a queued record costs beyond its message bytes (the queue entry, the vehicle id).
const ITEM_OVERHEAD: u64 = 64;
/// Bytes one queued pose costs (poses are queued as plain data, encoded by the writer).
const POSE_BYTES: u64 = std::mem::size_of::<crate::output::hub::Pose>() as u64;

/// Why the recorder could not start.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The directory could not be created or listed.
    #[error("recording directory {path}: {source}")]
    Directory {
        /// The directory.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The writer thread did not start.
    #[error("starting the recording writer thread: {0}")]
    Thread(std::io::Error),
}

/// One record's content.
#[derive(Debug)]
enum Body {
    Imu(pb::ImuBatch),
    Gnss(pb::GnssFix),
    Mag(pb::MagSample),
    Baro(pb::BaroSample),
    Camera(pb::CameraFrame),
    /// Boxed: a configuration is far larger than the other records, and rare.
    Config(Box<pb::VehicleConfig>),
    Poses(Arc<PoseBatch>),
}

impl Body {
    /// Bytes the record holds while queued.
    fn queued_bytes(&self) -> u64 {
        ITEM_OVERHEAD
            + match self {
                Body::Imu(m) => m.encoded_len() as u64,
                Body::Gnss(m) => m.encoded_len() as u64,
                Body::Mag(m) => m.encoded_len() as u64,
                Body::Baro(m) => m.encoded_len() as u64,
                Body::Camera(m) => m.encoded_len() as u64,
                Body::Config(m) => m.encoded_len() as u64,
                Body::Poses(b) => b.poses.len() as u64 * POSE_BYTES,
            }
    }

    /// Messages the record becomes in the file.
    fn messages(&self) -> u64 {
        match self {
            Body::Poses(b) => b.poses.len() as u64,
            _ => 1,
        }
    }
}

enum Item {
    Record {
        vehicle: Arc<str>,
        body: Body,
        log_ns: i64,
        bytes: u64,
    },
    Stop,
}

/// The cloneable, never-blocking handle the ingest path and the pose feed record through.
#[derive(Debug, Clone)]
pub struct RecordTap {
    tx: mpsc::Sender<Item>,
    queued: Arc<AtomicU64>,
    budget: u64,
    metrics: Metrics,
}

impl std::fmt::Debug for Item {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Item::Record { vehicle, bytes, .. } => f
                .debug_struct("Record")
                .field("vehicle", vehicle)
                .field("bytes", bytes)
                .finish_non_exhaustive(),
            Item::Stop => f.write_str("Stop"),
        }
    }
}

impl RecordTap {
    fn push(&self, vehicle: Arc<str>, body: Body) {
        let bytes = body.queued_bytes();
        let before = self.queued.fetch_add(bytes, Ordering::AcqRel);
        if before + bytes > self.budget {
            self.queued.fetch_sub(bytes, Ordering::AcqRel);
            self.metrics
                .record_dropped(RecordDrop::QueueFull, body.messages());
            return;
        }
        let item = Item::Record {
            vehicle,
            body,
            log_ns: wall_ns(),
            bytes,
        };
        if self.tx.send(item).is_err() {
            // The writer has stopped (shutdown): nothing more is recorded.
            self.queued.fetch_sub(bytes, Ordering::AcqRel);
        }
    }

    /// Records an accepted input of `vehicle_id` as received (an IMU batch: see [`Self::imu`]).
    pub fn input(&self, vehicle_id: &str, payload: Payload<'_>) {
        let body = match payload {
            Payload::Imu(b) => Body::Imu(b.clone()),
            Payload::Gnss(g) => Body::Gnss(*g),
            Payload::Mag(m) => Body::Mag(*m),
            Payload::Baro(b) => Body::Baro(*b),
            Payload::Camera(c) => Body::Camera(c.clone()),
            Payload::Config(c) => Body::Config(Box::new(*c)),
        };
        self.push(vehicle_id.into(), body);
    }

    /// Records the accepted samples of an IMU batch.
    pub fn imu(&self, vehicle_id: &str, batch: pb::ImuBatch) {
        self.push(vehicle_id.into(), Body::Imu(batch));
    }

    /// Records a batch of poses.
    pub fn poses(&self, batch: Arc<PoseBatch>) {
        self.push(Arc::clone(&batch.vehicle_id), Body::Poses(batch));
    }
}

/// A running recorder: the writer thread and the task feeding it the hub's poses.
#[derive(Debug)]
pub struct Recorder {
    tap: RecordTap,
    writer: std::thread::JoinHandle<()>,
    poses: (tokio::task::JoinHandle<()>, oneshot::Sender<()>),
}

impl Recorder {
    /// Starts recording into `config.directory` (which must be set), poses from `hub`.
    pub fn start(
        dir: &Path,
        config: &RecordConfig,
        metrics: &Metrics,
        hub: &Hub,
    ) -> Result<Self, RecordError> {
        let dir_err = |source| RecordError::Directory {
            path: dir.to_owned(),
            source,
        };
        std::fs::create_dir_all(dir).map_err(dir_err)?;
        let next_index = recordings(dir)
            .map_err(dir_err)?
            .last()
            .map_or(0, |f| f.index + 1);
        let (tx, rx) = mpsc::channel();
        let queued = Arc::new(AtomicU64::new(0));
        let mut writer = Writer {
            dir: dir.to_owned(),
            config: config.clone(),
            metrics: metrics.clone(),
            queued: Arc::clone(&queued),
            file: None,
            next_index,
            retry_at: None,
            frames: HashMap::new(),
        };
        let thread = std::thread::Builder::new()
            .name("uavnavd-record".into())
            .spawn(move || writer.run(&rx))
            .map_err(RecordError::Thread)?;
        let tap = RecordTap {
            tx,
            queued,
            budget: config.queue_bytes,
            metrics: metrics.clone(),
        };
        // Subscribed here, before any input is taken, so that no pose is missed.
        let rx_poses = hub.poses.subscribe();
        let (stop_tx, stop_rx) = oneshot::channel();
        let task = tokio::spawn(feed_poses(rx_poses, tap.clone(), stop_rx));
        info!(directory = %dir.display(), next_index, "recording");
        Ok(Self {
            tap,
            writer: thread,
            poses: (task, stop_tx),
        })
    }

    /// The handle for the ingest path.
    pub fn tap(&self) -> RecordTap {
        self.tap.clone()
    }

    /// Takes the poses already published, then finishes the open file. Call after the vehicles
    /// are drained, so that the recording ends with their last poses.
    pub async fn stop(self) {
        let (task, stop) = self.poses;
        let _ = stop.send(());
        let _ = task.await;
        let _ = self.tap.tx.send(Item::Stop);
        let writer = self.writer;
        if tokio::task::spawn_blocking(move || writer.join())
            .await
            .is_err()
        {
            warn!("the recording writer thread panicked");
        }
    }
}

/// Hands every published pose batch to the recorder until told to stop, then the ones left in
/// the ring. A lag (the ring overwrote batches this task had not read) is counted.
async fn feed_poses(
    mut rx: broadcast::Receiver<Arc<PoseBatch>>,
    tap: RecordTap,
    mut stop: oneshot::Receiver<()>,
) {
    use broadcast::error::{RecvError, TryRecvError};
    loop {
        tokio::select! {
            biased;
            p = rx.recv() => match p {
                Ok(b) => tap.poses(b),
                Err(RecvError::Lagged(n)) => tap.metrics.record_dropped(RecordDrop::Lagged, n),
                Err(RecvError::Closed) => return,
            },
            _ = &mut stop => break,
        }
    }
    loop {
        match rx.try_recv() {
            Ok(b) => tap.poses(b),
            Err(TryRecvError::Lagged(n)) => tap.metrics.record_dropped(RecordDrop::Lagged, n),
            Err(TryRecvError::Empty | TryRecvError::Closed) => return,
        }
    }
}

/// A recording file in the directory.
#[derive(Debug, Clone)]
struct Recording {
    index: u64,
    path: PathBuf,
    bytes: u64,
}

/// The directory's recordings (`uavnavd-NNNNNN.mcap`), oldest (lowest index) first.
fn recordings(dir: &Path) -> std::io::Result<Vec<Recording>> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name();
        let Some(index) = name
            .to_str()
            .and_then(|n| n.strip_prefix(FILE_PREFIX))
            .and_then(|n| n.strip_suffix(".mcap"))
            .and_then(|n| n.parse::<u64>().ok())
        else {
            continue;
        };
        let bytes = entry.metadata().map(|m| m.len()).unwrap_or(0);
        out.push(Recording {
            index,
            path: entry.path(),
            bytes,
        });
    }
    out.sort_by_key(|r| r.index);
    Ok(out)
}

/// The path of recording `index`.
pub fn file_path(dir: &Path, index: u64) -> PathBuf {
    dir.join(format!("{FILE_PREFIX}{index:06}.mcap"))
}

struct OpenFile {
    out: McapWriter,
    path: PathBuf,
    bytes: u64,
    /// Messages handed to the file: lost (and counted) if it cannot be finished.
    messages: u64,
    opened: Instant,
}

/// The writer thread's state.
struct Writer {
    dir: PathBuf,
    config: RecordConfig,
    metrics: Metrics,
    queued: Arc<AtomicU64>,
    file: Option<OpenFile>,
    next_index: u64,
    retry_at: Option<Instant>,
    /// Each vehicle's display frame (at its first recorded position), kept across files so that
    /// consecutive files show a vehicle in the same frame.
    frames: HashMap<Arc<str>, LocalFrame>,
}

impl Writer {
    fn run(&mut self, rx: &mpsc::Receiver<Item>) {
        // The timeout lets an idle file rotate on time.
        let tick = Duration::from_secs(1).min(Duration::from_secs_f64(self.config.rotate_s));
        loop {
            match rx.recv_timeout(tick) {
                Ok(Item::Record {
                    vehicle,
                    body,
                    log_ns,
                    bytes,
                }) => {
                    let left = self.queued.fetch_sub(bytes, Ordering::AcqRel) - bytes;
                    self.metrics
                        .record_queue_bytes
                        .set(i64::try_from(left).unwrap_or(i64::MAX));
                    self.record(&vehicle, &body, log_ns);
                }
                Ok(Item::Stop) | Err(mpsc::RecvTimeoutError::Disconnected) => break,
                Err(mpsc::RecvTimeoutError::Timeout) => {}
            }
            if self.file.as_ref().is_some_and(|f| {
                f.bytes >= self.config.rotate_bytes
                    || f.opened.elapsed().as_secs_f64() >= self.config.rotate_s
            }) {
                self.close();
            }
        }
        self.close();
    }

    fn record(&mut self, vehicle: &Arc<str>, body: &Body, log_ns: i64) {
        let n = body.messages();
        if self.file.is_none() && !self.open() {
            self.metrics.record_dropped(RecordDrop::WriteError, n);
            return;
        }
        let frame = match body {
            Body::Poses(b) => self.frame(vehicle, b),
            _ => None,
        };
        let Some(file) = self.file.as_mut() else {
            return;
        };
        match write(&mut file.out, vehicle, body, log_ns, frame.as_ref()) {
            Ok(bytes) => {
                file.bytes += bytes;
                file.messages += n;
                self.metrics.record_written.inc_by(n);
                self.metrics.record_bytes.inc_by(bytes);
            }
            Err(e) => {
                warn!(file = %file.path.display(), error = %e, "recording: write failed; file given up");
                self.metrics.record_dropped(RecordDrop::WriteError, n);
                // The file is not finished: a reader may still recover its complete chunks.
                self.file = None;
                self.retry_at = Some(Instant::now() + RETRY_AFTER);
            }
        }
    }

    /// The display frame of `vehicle`, set at its first pose with a position.
    fn frame(&mut self, vehicle: &Arc<str>, b: &PoseBatch) -> Option<LocalFrame> {
        if let Some(f) = self.frames.get(vehicle) {
            return Some(*f);
        }
        let lla = b
            .poses
            .iter()
            .find_map(|p| p.position.as_ref().and_then(|g| Lla::try_from(g).ok()))?;
        let frame = LocalFrame::new(lla);
        self.frames.insert(Arc::clone(vehicle), frame);
        Some(frame)
    }

    /// Opens the next file (after the retry delay of a failure); false when it cannot.
    fn open(&mut self) -> bool {
        if self.retry_at.is_some_and(|t| Instant::now() < t) {
            return false;
        }
        self.retain(self.config.retain_bytes);
        let path = file_path(&self.dir, self.next_index);
        self.next_index += 1;
        match McapWriter::create(&path, &McapOptions::default()) {
            Ok(out) => {
                self.retry_at = None;
                self.file = Some(OpenFile {
                    out,
                    path,
                    bytes: 0,
                    messages: 0,
                    opened: Instant::now(),
                });
                true
            }
            Err(e) => {
                warn!(file = %path.display(), error = %e, "recording: cannot create the file");
                self.retry_at = Some(Instant::now() + RETRY_AFTER);
                false
            }
        }
    }

    /// Finishes the open file, then applies retention.
    fn close(&mut self) {
        let Some(file) = self.file.take() else {
            return;
        };
        match file.out.finish() {
            Ok(()) => {
                self.metrics.record_files.inc();
            }
            Err(e) => {
                // Buffered chunks reach the disk only here: a full disk often shows first at
                // the finish, and then everything the file held is lost.
                warn!(file = %file.path.display(), error = %e, "recording: finishing failed");
                self.metrics
                    .record_dropped(RecordDrop::WriteError, file.messages);
                self.retry_at = Some(Instant::now() + RETRY_AFTER);
            }
        }
        self.retain(self.config.retain_bytes);
    }

    /// Deletes the oldest closed recordings until the rest fit in `budget` bytes.
    fn retain(&self, budget: u64) {
        let files = match recordings(&self.dir) {
            Ok(f) => f,
            Err(e) => {
                warn!(directory = %self.dir.display(), error = %e, "recording: cannot list");
                return;
            }
        };
        let open = self.file.as_ref().map(|f| f.path.as_path());
        let mut total: u64 = files.iter().map(|f| f.bytes).sum();
        for f in files {
            if total <= budget {
                break;
            }
            if Some(f.path.as_path()) == open {
                continue;
            }
            match std::fs::remove_file(&f.path) {
                Ok(()) => {
                    total = total.saturating_sub(f.bytes);
                    info!(file = %f.path.display(), "recording: deleted (retention)");
                }
                Err(e) => warn!(file = %f.path.display(), error = %e, "recording: cannot delete"),
            }
        }
    }
}

/// Writes one record; returns its message bytes.
fn write(
    out: &mut McapWriter,
    vehicle: &str,
    body: &Body,
    log_ns: i64,
    frame: Option<&LocalFrame>,
) -> uavnav_dataset::Result<u64> {
    let input = match body {
        Body::Imu(m) => InputRef::Imu(m),
        Body::Gnss(m) => InputRef::Gnss(m),
        Body::Mag(m) => InputRef::Mag(m),
        Body::Baro(m) => InputRef::Baro(m),
        // Validation made sure a recorded frame has its image.
        Body::Camera(m) => InputRef::Camera(m),
        Body::Config(m) => InputRef::Config(m),
        Body::Poses(b) => {
            let mut bytes = 0;
            for p in &b.poses {
                let wire = p.to_wire(vehicle);
                out.write_pose(vehicle, &wire, log_ns, frame)?;
                bytes += wire.encoded_len() as u64;
            }
            return Ok(bytes);
        }
    };
    // The live layout of `uavnav record` too (the dataset crate's writer holds it once).
    out.write_input(vehicle, input, log_ns)
}
