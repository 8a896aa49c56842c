//! uavnav MCAP recordings as the wire messages a replay sends (feature `recording`).
//!
//! A recording is an MCAP file in the layout of [`uavnav_proto::topics`]: what `uavnav record`
//! and the service's recorder (`[record]` in `uavnavd.toml`) write, and what `uavnav simulate` /
//! `uavnav convert` write for `.mcap` outputs. [`RecordingReader`] yields the service inputs it
//! holds (`imu`, `gnss`, `mag`, `baro`, `camera`, `config` of every vehicle, or of one) as
//! [`RecordedMessage`]s ready for [`crate::Ingest::send`], in log-time order; outputs (poses,
//! health), truth and the Foxglove display channels are skipped.
//!
//! Log time is when the recorder received the message (its wall clock; for simulated or converted
//! data, the sensor time): replaying at the pace of the log times reproduces the recorded arrival
//! pattern, IMU batches as they were sent. The file is read as a stream (memory stays flat for
//! long recordings with images); messages are put back in log-time order within a window of
//! [`DEFAULT_WINDOW`] messages (recorders write them in order up to thread scheduling). A message
//! that is further out of order is an error ([`RecordingError::OutOfOrder`]). After an error the
//! reader yields the messages it had read before it (a recorder that died leaves a truncated file
//! whose complete chunks are good), then the error, then ends.
//!
//! ```no_run
//! # fn demo() -> Result<(), uavnav_client::recording::RecordingError> {
//! use uavnav_client::recording::RecordingReader;
//! for m in RecordingReader::open("fleet.mcap")? {
//!     let m = m?;
//!     println!("{} at {} ns: {:?}", m.vehicle_id, m.log_time_ns, uavnav_client::ingest::leaf_of(&m.payload));
//! }
//! # Ok(()) }
//! ```

use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use uavnav_proto::keys::Leaf;
use uavnav_proto::topics;

use crate::pb::sensor_envelope::Payload;

/// Messages held back to restore log-time order.
pub const DEFAULT_WINDOW: usize = 1024;

/// Why a recording could not be read.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The file could not be opened.
    #[error("{path}: {source}")]
    Io {
        /// The recording.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The MCAP structure is broken (truncated file, bad chunk, unknown compression...).
    #[error("{path}: not a readable MCAP recording: {reason}")]
    Mcap {
        /// The recording.
        path: PathBuf,
        /// The MCAP reader's reason.
        reason: String,
    },
    /// A message could not be decoded as its topic's schema.
    #[error("{path}: {topic} message seq {sequence} (log time {log_time_ns} ns): {reason}")]
    Message {
        /// The recording.
        path: PathBuf,
        /// The message's topic.
        topic: String,
        /// The message's sequence number in its channel.
        sequence: u32,
        /// Its log time, ns.
        log_time_ns: u64,
        /// What is wrong with it.
        reason: String,
    },
    /// A message lies further back in log time than the reorder window can restore.
    #[error(
        "{path}: message at log time {log_time_ns} ns comes after {previous_ns} ns: out of \
         order beyond the {window}-message window"
    )]
    OutOfOrder {
        /// The recording.
        path: PathBuf,
        /// The late message's log time, ns.
        log_time_ns: u64,
        /// The log time of a message already yielded, ns.
        previous_ns: u64,
        /// The window, messages.
        window: usize,
    },
}

/// One service input of a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedMessage {
    /// The vehicle it was recorded for.
    pub vehicle_id: Arc<str>,
    /// When the recorder received it, ns (UNIX time for live recorders; sensor time for
    /// simulated and converted data).
    pub log_time_ns: u64,
    /// The sensor time of validity, ns (an IMU batch: its last sample; a configuration: the log
    /// time).
    pub publish_time_ns: u64,
    /// The message, as [`crate::Ingest::send`] takes it.
    pub payload: Payload,
}

fn open_file(path: &Path) -> Result<mcap::io::MessageReader<BufReader<File>>, RecordingError> {
    let file = File::open(path).map_err(|source| RecordingError::Io {
        path: path.to_owned(),
        source,
    })?;
    Ok(mcap::io::MessageReader::new(BufReader::new(file)))
}

/// The vehicles with at least one input channel in the recording, sorted (reads the whole file).
pub fn vehicles(path: impl AsRef<Path>) -> Result<Vec<String>, RecordingError> {
    let path = path.as_ref();
    let mut out = BTreeSet::new();
    for msg in open_file(path)? {
        let msg = msg.map_err(|e| RecordingError::Mcap {
            path: path.to_owned(),
            reason: e.to_string(),
        })?;
        if let Some((v, stream)) = topics::parse_topic(&msg.channel.topic)
            && stream.input().is_some()
        {
            out.insert(v.to_owned());
        }
    }
    Ok(out.into_iter().collect())
}

/// Streams a recording's inputs in log-time order (see the module doc).
pub struct RecordingReader {
    path: PathBuf,
    messages: mcap::io::MessageReader<BufReader<File>>,
    vehicle: Option<String>,
    window: usize,
    ids: BTreeMap<String, Arc<str>>,
    /// (log time, arrival counter) → message; the counter keeps equal log times in file order.
    pending: BTreeMap<(u64, u64), RecordedMessage>,
    counter: u64,
    last_log_ns: Option<u64>,
    /// The file has no more messages.
    exhausted: bool,
    /// The error that stopped reading, yielded once the messages read before it are.
    failed: Option<RecordingError>,
    done: bool,
}

impl std::fmt::Debug for RecordingReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RecordingReader")
            .field("path", &self.path)
            .field("vehicle", &self.vehicle)
            .field("window", &self.window)
            .finish_non_exhaustive()
    }
}

impl RecordingReader {
    /// Opens a recording (every vehicle).
    pub fn open(path: impl AsRef<Path>) -> Result<Self, RecordingError> {
        let path = path.as_ref().to_owned();
        Ok(Self {
            messages: open_file(&path)?,
            path,
            vehicle: None,
            window: DEFAULT_WINDOW,
            ids: BTreeMap::new(),
            pending: BTreeMap::new(),
            counter: 0,
            last_log_ns: None,
            exhausted: false,
            failed: None,
            done: false,
        })
    }

    /// Only the messages of `vehicle_id`.
    pub fn vehicle(mut self, vehicle_id: impl Into<String>) -> Self {
        self.vehicle = Some(vehicle_id.into());
        self
    }

    /// Holds up to `messages` back to restore log-time order (at least 1).
    pub fn window(mut self, messages: usize) -> Self {
        self.window = messages.max(1);
        self
    }

    /// The recording.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Decodes one MCAP message into the pending set (nothing for non-input topics).
    fn queue(&mut self, msg: &mcap::Message<'_>) -> Result<(), RecordingError> {
        let Some((vehicle, stream)) = topics::parse_topic(&msg.channel.topic) else {
            return Ok(());
        };
        if stream.input().is_none() || self.vehicle.as_deref().is_some_and(|v| v != vehicle) {
            return Ok(());
        }
        let data = msg.data.as_ref();
        let payload = match stream.input() {
            // Recorders store a camera frame as its plain image.
            Some(Leaf::Camera) => Payload::Camera(
                topics::decode_camera(data, msg.publish_time)
                    .map_err(|e| self.bad_message(msg, e.to_string()))?,
            ),
            Some(leaf) => match leaf.decode_input(data) {
                Some(Ok(p)) => p,
                Some(Err(e)) => {
                    let reason = format!("undecodable {}: {e}", stream.schema());
                    return Err(self.bad_message(msg, reason));
                }
                None => return Ok(()),
            },
            None => return Ok(()),
        };
        let vehicle_id = match self.ids.get(vehicle) {
            Some(id) => Arc::clone(id),
            None => {
                let id: Arc<str> = Arc::from(vehicle);
                self.ids.insert(vehicle.to_owned(), Arc::clone(&id));
                id
            }
        };
        self.counter += 1;
        self.pending.insert(
            (msg.log_time, self.counter),
            RecordedMessage {
                vehicle_id,
                log_time_ns: msg.log_time,
                publish_time_ns: msg.publish_time,
                payload,
            },
        );
        Ok(())
    }

    fn bad_message(&self, msg: &mcap::Message<'_>, reason: String) -> RecordingError {
        RecordingError::Message {
            path: self.path.clone(),
            topic: msg.channel.topic.clone(),
            sequence: msg.sequence,
            log_time_ns: msg.log_time,
            reason,
        }
    }

    /// The earliest pending message, unless it is older than one already yielded.
    fn pop(&mut self) -> Option<Result<RecordedMessage, RecordingError>> {
        let ((log_time_ns, _), m) = self.pending.pop_first()?;
        if let Some(previous_ns) = self.last_log_ns.filter(|&p| log_time_ns < p) {
            self.done = true;
            return Some(Err(RecordingError::OutOfOrder {
                path: self.path.clone(),
                log_time_ns,
                previous_ns,
                window: self.window,
            }));
        }
        self.last_log_ns = Some(log_time_ns);
        Some(Ok(m))
    }
}

impl Iterator for RecordingReader {
    type Item = Result<RecordedMessage, RecordingError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        while self.failed.is_none() && !self.exhausted && self.pending.len() <= self.window {
            match self.messages.next() {
                Some(Ok(msg)) => {
                    if let Err(e) = self.queue(&msg) {
                        self.failed = Some(e);
                    }
                }
                Some(Err(e)) => {
                    self.failed = Some(RecordingError::Mcap {
                        path: self.path.clone(),
                        reason: e.to_string(),
                    });
                }
                None => self.exhausted = true,
            }
        }
        // What was read before a failure comes first (a recorder that died leaves a truncated
        // file whose complete chunks are still good), then the error.
        match self.pop() {
            Some(item) => Some(item),
            None => {
                self.done = true;
                self.failed.take().map(Err)
            }
        }
    }
}
