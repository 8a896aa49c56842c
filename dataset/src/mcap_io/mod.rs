//! MCAP recordings with protobuf schemas, one channel per vehicle and stream.
//!
//! ## Topics
//!
//! | topic | schema | content |
//! |---|---|---|
//! | `/uavnav/{vehicle}/imu` | `uavnav.v1.ImuBatch` | IMU samples (one sample per message when written here) |
//! | `/uavnav/{vehicle}/gnss` | `uavnav.v1.GnssFix` | GNSS fixes |
//! | `/uavnav/{vehicle}/gnss/location` | `foxglove.LocationFix` | the same fixes for Foxglove's map (display only, ignored when reading) |
//! | `/uavnav/{vehicle}/mag` | `uavnav.v1.MagSample` | magnetometer samples (tesla, magnetometer frame) |
//! | `/uavnav/{vehicle}/baro` | `uavnav.v1.BaroSample` | barometer samples |
//! | `/uavnav/{vehicle}/camera` | `foxglove.CompressedImage` | camera frames: `frame_id` = `cam{id}`, `timestamp` = `t_ns` |
//! | `/uavnav/{vehicle}/config` | `uavnav.v1.VehicleConfig` | the vehicle configuration |
//! | `/uavnav/{vehicle}/info` | `uavnav.v1.DatasetInfo` | the truth's NED origin |
//! | `/uavnav/{vehicle}/truth` | `uavnav.v1.TruthSample` | ground truth |
//! | `/uavnav/{vehicle}/reference` | `uavnav.v1.TruthSample` | another estimator's output, not truth (a flight log's autopilot EKF); channel metadata `reference` names it |
//! | `/uavnav/{vehicle}/pose` | `uavnav.v1.PoseEstimate` | estimator output |
//! | `/uavnav/{vehicle}/pose/frame` | `foxglove.PoseInFrame` | the same poses for Foxglove's 3-D panel |
//! | `/uavnav/{vehicle}/health` | `uavnav.v1.VehicleHealth` | health reports |
//!
//! Vehicle ids never contain `/`. Camera frames are stored as plain `foxglove.CompressedImage`
//! (not wrapped in `uavnav.v1.CameraFrame`), so the image panel shows them without duplicating the
//! bytes; the image carries everything a `CameraFrame` does.
//!
//! ## Times
//!
//! *Publish time* is the sensor time of validity (`t_ns`, the vehicle's sensor clock). *Log time*
//! is when the recorder received or wrote the message: a live recorder passes its wall clock. For
//! converted or simulated data there is no receive time, so the converters set log time = publish
//! time = `t_ns` (the Foxglove timeline then shows sensor time); configuration and info messages get
//! the time of the first sensor event. MCAP times are unsigned: negative `t_ns` cannot be recorded.
//! Chunks are zstd-compressed by default.

pub mod reader;
pub mod writer;

use std::collections::BTreeSet;

use prost::Message;
use prost_types::FileDescriptorSet;
use uavnav_proto::{FILE_DESCRIPTOR_SET, names};

/// The streams of one vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Stream {
    /// `imu`
    Imu,
    /// `gnss`
    Gnss,
    /// `gnss/location` (display)
    GnssLocation,
    /// `mag`
    Mag,
    /// `baro`
    Baro,
    /// `camera`
    Camera,
    /// `config`
    Config,
    /// `info`
    Info,
    /// `truth`
    Truth,
    /// `reference` (not truth)
    Reference,
    /// `pose`
    Pose,
    /// `pose/frame` (display)
    PoseFrame,
    /// `health`
    Health,
}

/// Every stream, for lookups.
const STREAMS: [Stream; 13] = [
    Stream::Imu,
    Stream::Gnss,
    Stream::GnssLocation,
    Stream::Mag,
    Stream::Baro,
    Stream::Camera,
    Stream::Config,
    Stream::Info,
    Stream::Truth,
    Stream::Reference,
    Stream::Pose,
    Stream::PoseFrame,
    Stream::Health,
];

/// The topic prefix.
pub const TOPIC_PREFIX: &str = "/uavnav/";

/// The channel metadata key naming what produced a `reference` stream (`EKF1`, ...).
pub const REFERENCE_METADATA_KEY: &str = "reference";

impl Stream {
    /// The topic suffix after `/uavnav/{vehicle}/`.
    pub fn suffix(self) -> &'static str {
        match self {
            Stream::Imu => "imu",
            Stream::Gnss => "gnss",
            Stream::GnssLocation => "gnss/location",
            Stream::Mag => "mag",
            Stream::Baro => "baro",
            Stream::Camera => "camera",
            Stream::Config => "config",
            Stream::Info => "info",
            Stream::Truth => "truth",
            Stream::Reference => "reference",
            Stream::Pose => "pose",
            Stream::PoseFrame => "pose/frame",
            Stream::Health => "health",
        }
    }

    /// The protobuf message (schema) name.
    pub fn schema(self) -> &'static str {
        match self {
            Stream::Imu => names::IMU_BATCH,
            Stream::Gnss => names::GNSS_FIX,
            Stream::GnssLocation => names::FOXGLOVE_LOCATION_FIX,
            Stream::Mag => names::MAG_SAMPLE,
            Stream::Baro => names::BARO_SAMPLE,
            Stream::Camera => names::FOXGLOVE_COMPRESSED_IMAGE,
            Stream::Config => names::VEHICLE_CONFIG,
            Stream::Info => names::DATASET_INFO,
            Stream::Truth | Stream::Reference => names::TRUTH_SAMPLE,
            Stream::Pose => names::POSE_ESTIMATE,
            Stream::PoseFrame => names::FOXGLOVE_POSE_IN_FRAME,
            Stream::Health => names::VEHICLE_HEALTH,
        }
    }
}

/// `/uavnav/{vehicle}/{stream}`.
pub fn topic(vehicle: &str, stream: Stream) -> String {
    format!("{TOPIC_PREFIX}{vehicle}/{}", stream.suffix())
}

/// Splits a topic into vehicle and stream; `None` for foreign topics.
pub fn parse_topic(topic: &str) -> Option<(&str, Stream)> {
    let rest = topic.strip_prefix(TOPIC_PREFIX)?;
    let (vehicle, suffix) = rest.split_once('/')?;
    let stream = STREAMS.into_iter().find(|s| s.suffix() == suffix)?;
    (!vehicle.is_empty()).then_some((vehicle, stream))
}

/// The MCAP `protobuf` schema data for a message: a `FileDescriptorSet` holding the file that
/// defines it and everything it imports (source info stripped to keep recordings small).
pub fn schema_data(message: &str) -> Option<Vec<u8>> {
    let all = FileDescriptorSet::decode(FILE_DESCRIPTOR_SET).ok()?;
    let (package, name) = message.rsplit_once('.')?;
    let root = all
        .file
        .iter()
        .find(|f| f.package() == package && f.message_type.iter().any(|m| m.name() == name))?;
    let mut wanted = BTreeSet::new();
    let mut stack = vec![root.name().to_owned()];
    while let Some(file) = stack.pop() {
        if !wanted.insert(file.clone()) {
            continue;
        }
        if let Some(f) = all.file.iter().find(|f| f.name() == file) {
            stack.extend(f.dependency.iter().cloned());
        }
    }
    // Dependencies first, as protoc orders them.
    let mut out = FileDescriptorSet::default();
    for f in &all.file {
        if wanted.contains(f.name()) {
            let mut f = f.clone();
            f.source_code_info = None;
            out.file.push(f);
        }
    }
    Some(out.encode_to_vec())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn topics_round_trip() {
        for s in STREAMS {
            let t = topic("uav-7", s);
            assert_eq!(parse_topic(&t), Some(("uav-7", s)));
        }
        assert_eq!(topic("a", Stream::GnssLocation), "/uavnav/a/gnss/location");
        assert_eq!(parse_topic("/other/a/imu"), None);
        assert_eq!(parse_topic("/uavnav/a/unknown"), None);
    }

    #[test]
    fn schemas_exist_and_are_self_contained() {
        for s in STREAMS {
            let data = schema_data(s.schema()).unwrap();
            let fds = FileDescriptorSet::decode(data.as_slice()).unwrap();
            let names: Vec<_> = fds.file.iter().map(|f| f.name().to_owned()).collect();
            for f in &fds.file {
                for d in &f.dependency {
                    assert!(names.contains(d), "{} needs {d}", s.schema());
                }
            }
        }
    }
}
