//! Output fan-out: every pose and health report of every vehicle goes through one broadcast channel
//! each; the gRPC watchers and the Zenoh publisher subscribe and filter.
//!
//! Poses travel in [`PoseBatch`]es, the poses one actor produced for one input message (a few IMU
//! samples' worth): at fleet scale poses come at IMU rate, and one ring slot, one wake-up of each
//! subscriber and one reference count per batch instead of per pose is what keeps the fan-out cheap.
//!
//! A subscriber that falls behind loses the oldest messages (it is told how many), so a slow
//! watcher never slows down estimation.

use std::sync::Arc;

use tokio::sync::{broadcast, watch};
use uavnav_proto::v1 as pb;

/// Pose ring size, in batches (typically 4–10 poses each): a second of the whole fleet's poses at
/// 2000 vehicles × 200 Hz would be 400k poses; a smaller ring keeps memory flat (every slot holds
/// its batch until overwritten) and lagging watchers skip.
pub const POSE_CAPACITY: usize = 1 << 14;
/// Health reports ring size.
pub const HEALTH_CAPACITY: usize = 1 << 14;

/// The output channels plus the service-wide shutdown signal.
#[derive(Debug, Clone)]
pub struct Hub {
    /// Every pose.
    pub poses: broadcast::Sender<Arc<PoseBatch>>,
    /// Every health report.
    pub health: broadcast::Sender<Arc<pb::VehicleHealth>>,
    /// Vehicle lifecycle (id, alive) for liveliness tokens.
    pub lifecycle: broadcast::Sender<(Arc<str>, bool)>,
    /// Becomes `true` when the service starts shutting down.
    pub stopping: watch::Receiver<bool>,
}

impl Hub {
    /// A hub and the sender that triggers shutdown.
    pub fn new() -> (Self, watch::Sender<bool>) {
        let (stop_tx, stopping) = watch::channel(false);
        let hub = Self {
            poses: broadcast::channel(POSE_CAPACITY).0,
            health: broadcast::channel(HEALTH_CAPACITY).0,
            lifecycle: broadcast::channel(4096).0,
            stopping,
        };
        (hub, stop_tx)
    }

    /// Whether shutdown has begun.
    pub fn is_stopping(&self) -> bool {
        *self.stopping.borrow()
    }
}

/// Consecutive poses of one vehicle, oldest first. The poses' own `vehicle_id` is left empty (one
/// string per batch, not per pose): [`PoseBatch::wire`] fills it in for whoever sends one on.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseBatch {
    /// The vehicle.
    pub vehicle_id: Arc<str>,
    /// Its poses, `vehicle_id` empty.
    pub poses: Vec<pb::PoseEstimate>,
}

impl PoseBatch {
    /// Pose `i` as a complete wire message (`None` past the end).
    pub fn wire(&self, i: usize) -> Option<pb::PoseEstimate> {
        let mut p = self.poses.get(i)?.clone();
        p.vehicle_id = self.vehicle_id.to_string();
        Some(p)
    }

    /// Pose `i` encoded as a complete wire message, without cloning it: the `vehicle_id` field
    /// (1) first, then the pose's own fields (its empty id is not encoded). Protobuf decoders read
    /// the concatenation as one message, the same as [`PoseBatch::wire`]'s encoding.
    pub fn encode_wire(&self, i: usize) -> Option<Vec<u8>> {
        use prost::Message;
        use prost::encoding::{WireType, encode_key, encode_varint};
        let p = self.poses.get(i)?;
        if !p.vehicle_id.is_empty() {
            // Not a batch the actor made (the id is already set): encode it as it is.
            return Some(p.encode_to_vec());
        }
        let id = self.vehicle_id.as_bytes();
        let mut buf = Vec::with_capacity(p.encoded_len() + id.len() + 6);
        encode_key(1, WireType::LengthDelimited, &mut buf);
        encode_varint(id.len() as u64, &mut buf);
        buf.extend_from_slice(id);
        // A Vec grows as needed: encoding into it cannot run out of room.
        p.encode(&mut buf).ok()?;
        Some(buf)
    }

    /// The newest pose as a complete wire message.
    pub fn last(&self) -> Option<pb::PoseEstimate> {
        self.wire(self.poses.len().checked_sub(1)?)
    }

    /// Every pose as a complete wire message.
    pub fn to_wire(&self) -> Vec<pb::PoseEstimate> {
        (0..self.poses.len()).filter_map(|i| self.wire(i)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost::Message;

    #[test]
    fn encoded_pose_decodes_to_the_complete_wire_message() {
        let pose = |t_ns| pb::PoseEstimate {
            t_ns,
            roll_rad: 0.25,
            aiding_sources: vec![pb::AidingSource::GnssPosition as i32],
            ..Default::default()
        };
        let b = PoseBatch {
            vehicle_id: "uav-7".into(),
            poses: vec![pose(1), pose(2)],
        };
        for i in 0..2 {
            let bytes = b.encode_wire(i).unwrap();
            let back = pb::PoseEstimate::decode(bytes.as_slice()).unwrap();
            assert_eq!(Some(back), b.wire(i));
            assert_eq!(b.wire(i).unwrap().vehicle_id, "uav-7");
        }
        assert_eq!(b.encode_wire(2), None);
        assert_eq!(b.last().map(|p| p.t_ns), Some(2));
    }
}
