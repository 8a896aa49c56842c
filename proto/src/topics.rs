//! The topics of uavnav MCAP recordings (what `uavnav record`, `uavnav convert`/`simulate` and the
//! service's recorder write, and what the dataset reader and the client's recording reader read):
//! one channel per vehicle and stream, protobuf schemas.
//!
//! | topic | schema | content |
//! |---|---|---|
//! | `/uavnav/{vehicle}/imu` | `uavnav.v1.ImuBatch` | IMU samples (one or more per message) |
//! | `/uavnav/{vehicle}/gnss` | `uavnav.v1.GnssFix` | GNSS fixes |
//! | `/uavnav/{vehicle}/gnss/location` | `foxglove.LocationFix` | the same fixes for Foxglove's map (display only, ignored when reading) |
//! | `/uavnav/{vehicle}/mag` | `uavnav.v1.MagSample` | magnetometer samples (tesla, magnetometer frame) |
//! | `/uavnav/{vehicle}/baro` | `uavnav.v1.BaroSample` | barometer samples |
//! | `/uavnav/{vehicle}/camera` | `foxglove.CompressedImage` | camera frames: `frame_id` = `cam{id}`, `timestamp` = `t_ns` ([`camera_frame_from_image`]) |
//! | `/uavnav/{vehicle}/config` | `uavnav.v1.VehicleConfig` | the vehicle configuration |
//! | `/uavnav/{vehicle}/info` | `uavnav.v1.DatasetInfo` | the truth's NED origin |
//! | `/uavnav/{vehicle}/truth` | `uavnav.v1.TruthSample` | ground truth |
//! | `/uavnav/{vehicle}/reference` | `uavnav.v1.TruthSample` | another estimator's output, not truth (a flight log's autopilot EKF); channel metadata [`REFERENCE_METADATA_KEY`] names it |
//! | `/uavnav/{vehicle}/pose` | `uavnav.v1.PoseEstimate` | estimator output |
//! | `/uavnav/{vehicle}/pose/frame` | `foxglove.PoseInFrame` | the same poses for Foxglove's 3-D panel |
//! | `/uavnav/{vehicle}/health` | `uavnav.v1.VehicleHealth` | health reports |
//!
//! Vehicle ids never contain `/`. Camera frames are stored as plain `foxglove.CompressedImage`
//! (not wrapped in `uavnav.v1.CameraFrame`), so Foxglove's image panel shows them without
//! duplicating the bytes; the image carries everything a `CameraFrame` does.
//!
//! *Publish time* is the sensor time of validity (`t_ns`; an IMU batch: its last sample). *Log
//! time* is when the recorder received the message (a live recorder's wall clock), or `t_ns` for
//! converted and simulated data.

use foxglove::messages::CompressedImage;
use prost::Message;

use crate::convert::ConvertError;
use crate::keys::Leaf;
use crate::{names, v1};

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

/// The topic prefix.
pub const TOPIC_PREFIX: &str = "/uavnav/";

/// The channel metadata key naming what produced a `reference` stream (`EKF1`, ...).
pub const REFERENCE_METADATA_KEY: &str = "reference";

impl Stream {
    /// Every stream.
    pub const ALL: [Stream; 13] = [
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

    /// The service input this stream holds (what a replay sends), if any.
    pub fn input(self) -> Option<Leaf> {
        Some(match self {
            Stream::Imu => Leaf::Imu,
            Stream::Gnss => Leaf::Gnss,
            Stream::Mag => Leaf::Mag,
            Stream::Baro => Leaf::Baro,
            Stream::Camera => Leaf::Camera,
            Stream::Config => Leaf::Config,
            _ => return None,
        })
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
    let stream = Stream::ALL.into_iter().find(|s| s.suffix() == suffix)?;
    (!vehicle.is_empty()).then_some((vehicle, stream))
}

/// A camera-channel image back as the wire frame: the camera id from `frame_id` (`cam{N}`), the
/// time of validity from `timestamp`, else from the message's publish time.
pub fn camera_frame_from_image(
    image: CompressedImage,
    publish_time_ns: u64,
) -> Result<v1::CameraFrame, ConvertError> {
    let camera_id = image
        .frame_id
        .strip_prefix("cam")
        .and_then(|n| n.parse::<u32>().ok())
        .ok_or_else(|| {
            ConvertError::invalid("frame_id", format!("'{}' is not cam<N>", image.frame_id))
        })?;
    let t_ns = match &image.timestamp {
        Some(ts) => i64::try_from(ts.total_nanos()),
        None => i64::try_from(publish_time_ns),
    }
    .map_err(|_| ConvertError::invalid("timestamp", "beyond i64 ns"))?;
    Ok(v1::CameraFrame {
        t_ns,
        camera_id,
        image: Some(image),
    })
}

/// A camera-channel message (encoded `foxglove.CompressedImage`) as the wire frame (see
/// [`camera_frame_from_image`]).
pub fn decode_camera(data: &[u8], publish_time_ns: u64) -> Result<v1::CameraFrame, ConvertError> {
    let image = CompressedImage::decode(data).map_err(|e| {
        ConvertError::invalid(
            "image",
            format!("undecodable foxglove.CompressedImage: {e}"),
        )
    })?;
    camera_frame_from_image(image, publish_time_ns)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn topics_round_trip() {
        for s in Stream::ALL {
            let t = topic("uav-7", s);
            assert_eq!(parse_topic(&t), Some(("uav-7", s)));
        }
        assert_eq!(topic("a", Stream::GnssLocation), "/uavnav/a/gnss/location");
        assert_eq!(topic("a", Stream::Imu), "/uavnav/a/imu");
        assert_eq!(parse_topic("/other/a/imu"), None);
        assert_eq!(parse_topic("/uavnav/a/unknown"), None);
        assert_eq!(parse_topic("/uavnav//imu"), None);
        let inputs: Vec<Leaf> = Stream::ALL.iter().filter_map(|s| s.input()).collect();
        assert_eq!(inputs, Leaf::INPUTS);
    }

    #[test]
    fn camera_images_become_frames() {
        let image = CompressedImage {
            timestamp: crate::foxglove_conv::timestamp(1_500_000_000),
            frame_id: crate::foxglove_conv::camera_frame_id(2),
            data: vec![0xff, 0xd8, 0xff].into(),
            format: "jpeg".into(),
        };
        let f = decode_camera(&image.encode_to_vec(), 7).unwrap();
        assert_eq!((f.t_ns, f.camera_id), (1_500_000_000, 2));
        assert_eq!(f.image, Some(image.clone()));
        let untimed = CompressedImage {
            timestamp: None,
            ..image.clone()
        };
        assert_eq!(camera_frame_from_image(untimed, 7).unwrap().t_ns, 7);
        let bad = CompressedImage {
            frame_id: "left".into(),
            ..image
        };
        let e = camera_frame_from_image(bad, 7).unwrap_err();
        assert_eq!(e.field(), "frame_id");
        assert!(decode_camera(&[0xff, 0xff, 0xff], 0).is_err());
    }
}
