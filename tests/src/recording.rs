//! Flight recordings for tests: MCAP files laid out exactly as the service's recorder and
//! `uavnav record` write them (through their one writer, `McapWriter::write_input`), so that no
//! test hand-writes MCAP; and what a recorder wrote, read back (its poses, a directory's files).
//!
//! Like the rest of the kit these helpers panic on failure: a test that cannot write its fixture
//! has failed.

use std::path::{Path, PathBuf};

use prost::Message;
use uavnav_dataset::{McapOptions, McapWriter};
use uavnav_proto::topics::{Stream, topic};

use crate::pb;
use crate::pb::sensor_envelope::Payload;

/// A recording being written, input by input, as a live recorder writes it.
#[derive(Debug)]
pub struct RecordingBuilder {
    writer: McapWriter,
}

impl RecordingBuilder {
    /// Creates (truncates) the file.
    pub fn create(path: &Path) -> Self {
        let writer = McapWriter::create(path, &McapOptions::default())
            .unwrap_or_else(|e| panic!("creating {}: {e}", path.display()));
        Self { writer }
    }

    /// Writes one input of `vehicle` received at `log_time_ns` (the recorder's wall clock).
    pub fn input(&mut self, vehicle: &str, payload: &Payload, log_time_ns: i64) -> &mut Self {
        self.writer
            .write_input(vehicle, payload.into(), log_time_ns)
            .unwrap_or_else(|e| panic!("recording {vehicle}'s {payload:?}: {e}"));
        self
    }

    /// The underlying writer, for what a recorder of inputs does not write itself (poses, truth,
    /// a message on the wrong channel).
    pub fn writer(&mut self) -> &mut McapWriter {
        &mut self.writer
    }

    /// Writes the summary and index.
    pub fn finish(self) {
        self.writer
            .finish()
            .unwrap_or_else(|e| panic!("finishing the recording: {e}"));
    }
}

/// Writes `records` — (vehicle, payload, log time ns), in file order — as a recorder received
/// them.
pub fn write_recording(path: &Path, records: &[(&str, Payload, i64)]) {
    let mut b = RecordingBuilder::create(path);
    for (vehicle, payload, log_time_ns) in records {
        b.input(vehicle, payload, *log_time_ns);
    }
    b.finish();
}

/// The sensor time of an input (`None` for a configuration and an empty IMU batch).
fn sensor_t_ns(p: &Payload) -> Option<i64> {
    match p {
        Payload::Imu(b) => b.samples.last().map(|s| s.t_ns),
        Payload::Gnss(m) => Some(m.t_ns),
        Payload::Mag(m) => Some(m.t_ns),
        Payload::Baro(m) => Some(m.t_ns),
        Payload::Camera(m) => Some(m.t_ns),
        Payload::Config(_) => None,
    }
}

/// Writes `payloads` of `vehicle` to `path` as a recorder that received each at its sensor time
/// (a configuration at the time of the message before it, or of the first sensor message when it
/// leads).
pub fn record_payloads(path: &Path, vehicle: &str, payloads: &[Payload]) {
    let mut log = payloads.iter().find_map(sensor_t_ns).unwrap_or(0);
    let mut b = RecordingBuilder::create(path);
    for p in payloads {
        log = sensor_t_ns(p).unwrap_or(log);
        b.input(vehicle, p, log);
    }
    b.finish();
}

/// Records the first `duration_s` of the smoke flight without camera ([`crate::flight::wire_flight`])
/// as `vehicle` to `path`; returns what was recorded, in file order.
pub fn record_flight(path: &Path, vehicle: &str, duration_s: f64) -> Vec<Payload> {
    let (_, payloads) = crate::flight::wire_flight(duration_s);
    record_payloads(path, vehicle, &payloads);
    payloads
}

/// The recordings (`*.mcap`) in `dir`, sorted by name (the service's names sort by index).
pub fn recordings(dir: &Path) -> Vec<PathBuf> {
    let entries =
        std::fs::read_dir(dir).unwrap_or_else(|e| panic!("listing {}: {e}", dir.display()));
    let mut out: Vec<PathBuf> = entries
        .map(|e| e.unwrap_or_else(|e| panic!("listing {}: {e}", dir.display())))
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .collect();
    out.sort();
    out
}

/// The poses of `vehicle` in a recording, in file order.
pub fn recorded_poses(path: &Path, vehicle: &str) -> Vec<pb::PoseEstimate> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let topic = topic(vehicle, Stream::Pose);
    let stream = mcap::MessageStream::new(&bytes)
        .unwrap_or_else(|e| panic!("{}: not MCAP: {e}", path.display()));
    let mut out = Vec::new();
    for m in stream {
        let m = m.unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        if m.channel.topic == topic {
            let pose = pb::PoseEstimate::decode(m.data.as_ref())
                .unwrap_or_else(|e| panic!("{}: a pose on {topic}: {e}", path.display()));
            out.push(pose);
        }
    }
    out
}
