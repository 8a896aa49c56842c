//! The compact pose: one pose estimate as the service carries it from a vehicle's actor to its
//! senders (gRPC watchers, Zenoh, the live view), and batches of them. Plain data, no heap: poses
//! come at IMU rate for every vehicle and most are never sent (watchers decimate), so the wire
//! message is made only for a pose that is sent. [`compact_pose`] makes one from an estimator
//! output, with the mode and aiding vocabulary of [`crate::convert::output`].

use std::sync::Arc;

use uavnav_core::PoseOutput;

use crate::convert::output::{aiding_to_wire, mode_to_wire};
use crate::v1 as pb;

/// An estimator output → the compact pose (`ingest_wall_ns` unset): no `pos_ned_m`, biases or
/// per-pose health (the service sends those on its health stream).
pub fn compact_pose(p: &PoseOutput) -> Pose {
    let aiding = aiding_to_wire(&p.aiding).fold(0, |bits, s| bits | Pose::aiding_bit(s));
    // Position and velocity only where the mode estimates them.
    let pv = p.health.mode.has_position();
    Pose {
        t_ns: p.t_ns,
        position: pv.then(|| (&p.lla).into()),
        vel_ned_mps: pv.then(|| (&p.vel_ned_mps).into()),
        nav_from_body: Some((&p.nav_from_body).into()),
        roll_rad: p.euler_rad.x,
        pitch_rad: p.euler_rad.y,
        yaw_rad: p.euler_rad.z,
        sigma_pos_ned_m: pv.then(|| (&p.sigma_pos_ned_m).into()),
        sigma_vel_ned_mps: pv.then(|| (&p.sigma_vel_mps).into()),
        sigma_att_rad: Some((&p.sigma_att_rad).into()),
        aiding,
        mode: mode_to_wire(p.health.mode),
        ingest_wall_ns: 0,
    }
}

/// One pose estimate as the service carries it from an actor to the senders: plain data, no heap
/// (poses come at IMU rate for every vehicle, and most are never sent: watchers decimate). It is
/// the wire message without `vehicle_id` (one per [`PoseBatch`]), without the unused
/// `covariance_9x9`, and with the aiding sources as bits; [`Pose::to_wire`] makes the message.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// Sensor time, ns.
    pub t_ns: i64,
    /// Geodetic position.
    pub position: Option<pb::GeodeticPosition>,
    /// Velocity, NED, m/s.
    pub vel_ned_mps: Option<pb::Vector3>,
    /// Rotation of body vectors into NED.
    pub nav_from_body: Option<pb::Quaternion>,
    /// Roll, rad.
    pub roll_rad: f64,
    /// Pitch, rad.
    pub pitch_rad: f64,
    /// Yaw, rad.
    pub yaw_rad: f64,
    /// 1-σ position, NED, m.
    pub sigma_pos_ned_m: Option<pb::Vector3>,
    /// 1-σ velocity, NED, m/s.
    pub sigma_vel_ned_mps: Option<pb::Vector3>,
    /// 1-σ roll, pitch, yaw, rad.
    pub sigma_att_rad: Option<pb::Vector3>,
    /// Aiding sources: bit `1 << s` for each `pb::AidingSource` value `s`.
    pub aiding: u8,
    /// Estimator mode.
    pub mode: pb::EstimatorMode,
    /// Arrival of the IMU sample this pose was made from, service wall clock, ns (0 = unknown).
    pub ingest_wall_ns: i64,
}

/// The aiding sources in wire order (the order of `pb::AidingSource` values).
const AIDING_ORDER: [pb::AidingSource; 5] = [
    pb::AidingSource::GnssPosition,
    pb::AidingSource::GnssVelocity,
    pb::AidingSource::Vision,
    pb::AidingSource::VisionRotation,
    pb::AidingSource::VisionTranslation,
];

impl Pose {
    /// The bit of an aiding source in [`Pose::aiding`].
    pub const fn aiding_bit(s: pb::AidingSource) -> u8 {
        1 << (s as u8)
    }

    /// The complete wire message.
    pub fn to_wire(&self, vehicle_id: &str) -> pb::PoseEstimate {
        pb::PoseEstimate {
            vehicle_id: vehicle_id.to_owned(),
            t_ns: self.t_ns,
            position: self.position,
            vel_ned_mps: self.vel_ned_mps,
            nav_from_body: self.nav_from_body,
            roll_rad: self.roll_rad,
            pitch_rad: self.pitch_rad,
            yaw_rad: self.yaw_rad,
            sigma_pos_ned_m: self.sigma_pos_ned_m,
            sigma_vel_ned_mps: self.sigma_vel_ned_mps,
            sigma_att_rad: self.sigma_att_rad,
            covariance_9x9: Vec::new(),
            aiding_sources: AIDING_ORDER
                .iter()
                .filter(|&&s| self.aiding & Self::aiding_bit(s) != 0)
                .map(|&s| s as i32)
                .collect(),
            mode: self.mode as i32,
            ingest_wall_ns: self.ingest_wall_ns,
            // The compact pose: the per-pose estimator detail goes out on the health stream.
            pos_ned_m: None,
            gyro_bias_radps: None,
            accel_bias_mps2: None,
            health: None,
        }
    }

    /// The pose of a wire message (its `vehicle_id` and `covariance_9x9` are not kept; unknown
    /// aiding or mode values read as none / unspecified).
    pub fn from_wire(p: &pb::PoseEstimate) -> Self {
        let aiding = p
            .aiding_sources
            .iter()
            .filter_map(|&v| pb::AidingSource::try_from(v).ok())
            .filter(|s| AIDING_ORDER.contains(s))
            .fold(0, |bits, s| bits | Self::aiding_bit(s));
        Self {
            t_ns: p.t_ns,
            position: p.position,
            vel_ned_mps: p.vel_ned_mps,
            nav_from_body: p.nav_from_body,
            roll_rad: p.roll_rad,
            pitch_rad: p.pitch_rad,
            yaw_rad: p.yaw_rad,
            sigma_pos_ned_m: p.sigma_pos_ned_m,
            sigma_vel_ned_mps: p.sigma_vel_ned_mps,
            sigma_att_rad: p.sigma_att_rad,
            aiding,
            mode: pb::EstimatorMode::try_from(p.mode).unwrap_or_default(),
            ingest_wall_ns: p.ingest_wall_ns,
        }
    }
}

/// Consecutive poses of one vehicle, oldest first, and the vehicle's id (once per batch).
#[derive(Debug, Clone, PartialEq)]
pub struct PoseBatch {
    /// The vehicle.
    pub vehicle_id: Arc<str>,
    /// Its poses.
    pub poses: Vec<Pose>,
    /// The number of the first pose: a vehicle's poses are numbered from 0 since its actor
    /// started, so that a watch decimates them with no state of its own per vehicle.
    pub first_seq: u64,
}

impl PoseBatch {
    /// Pose `i` as a complete wire message (`None` past the end).
    pub fn wire(&self, i: usize) -> Option<pb::PoseEstimate> {
        Some(self.poses.get(i)?.to_wire(&self.vehicle_id))
    }

    /// Pose `i` encoded as a complete wire message without copying the id into it: the
    /// `vehicle_id` field (1) first, then the pose's other fields. Protobuf decoders read the
    /// concatenation as one message, the same as [`PoseBatch::wire`]'s encoding.
    pub fn encode_wire(&self, i: usize) -> Option<Vec<u8>> {
        use prost::Message;
        use prost::encoding::{WireType, encode_key, encode_varint};
        let p = self.poses.get(i)?.to_wire("");
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
        let pose = |t_ns| Pose {
            t_ns,
            roll_rad: 0.25,
            aiding: Pose::aiding_bit(pb::AidingSource::GnssPosition),
            ..Default::default()
        };
        let b = PoseBatch {
            vehicle_id: "uav-7".into(),
            poses: vec![pose(1), pose(2)],
            first_seq: 0,
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

    #[test]
    fn wire_round_trip_keeps_every_field() {
        let v = |x| {
            Some(pb::Vector3 {
                x,
                y: -x,
                z: 2.0 * x,
            })
        };
        let wire = pb::PoseEstimate {
            vehicle_id: "uav-1".into(),
            t_ns: 42,
            position: Some(pb::GeodeticPosition {
                latitude_deg: 45.0,
                longitude_deg: 9.0,
                altitude_m: 120.0,
            }),
            vel_ned_mps: v(1.0),
            nav_from_body: Some(pb::Quaternion {
                w: 1.0,
                ..Default::default()
            }),
            roll_rad: 0.1,
            pitch_rad: -0.2,
            yaw_rad: 3.0,
            sigma_pos_ned_m: v(0.5),
            sigma_vel_ned_mps: v(0.05),
            sigma_att_rad: v(0.01),
            covariance_9x9: Vec::new(),
            aiding_sources: vec![
                pb::AidingSource::GnssPosition as i32,
                pb::AidingSource::Vision as i32,
            ],
            mode: pb::EstimatorMode::GnssDeniedVision as i32,
            ingest_wall_ns: 7,
            ..Default::default()
        };
        assert_eq!(Pose::from_wire(&wire).to_wire("uav-1"), wire);
    }
}
