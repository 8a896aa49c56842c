//! The service's Zenoh key expressions, written once for the service and its clients (plain
//! strings: this crate does not depend on Zenoh).
//!
//! | key expression | direction | payload |
//! |---|---|---|
//! | `uavnav/v1/vehicle/{id}/imu` | in | `uavnav.v1.ImuBatch` |
//! | `uavnav/v1/vehicle/{id}/gnss` | in | `uavnav.v1.GnssFix` |
//! | `uavnav/v1/vehicle/{id}/mag` | in | `uavnav.v1.MagSample` |
//! | `uavnav/v1/vehicle/{id}/baro` | in | `uavnav.v1.BaroSample` |
//! | `uavnav/v1/vehicle/{id}/camera` | in | `uavnav.v1.CameraFrame` |
//! | `uavnav/v1/vehicle/{id}/config` | in | `uavnav.v1.VehicleConfig` |
//! | `uavnav/v1/vehicle/{id}/pose` | out | `uavnav.v1.PoseEstimate` |
//! | `uavnav/v1/vehicle/{id}/health` | out | `uavnav.v1.VehicleHealth` |
//! | `uavnav/v1/vehicle/{id}/unconfigured` | out, only while the vehicle runs without its configuration | `uavnav.v1.VehicleHealth` |
//! | `uavnav/v1/vehicle/{id}/pose/latest` | queryable | `uavnav.v1.PoseEstimate` |
//! | `uavnav/v1/vehicles` | queryable | `uavnav.v1.ListVehiclesResponse` |
//! | `uavnav/v1/service/{instance}` | liveliness token | — |
//! | `uavnav/v1/alive/vehicle/{id}` | liveliness token, once the vehicle is configured or has a pose | — |
//!
//! The vehicles' liveliness tokens live outside `uavnav/v1/vehicle/`, one level below a node of
//! their own: Zenoh routes a put on a key that nobody declared by walking its tree of declared
//! keys, comparing the key with every child of each node it reaches, and it reaches every child
//! of a node whose own key matched (`uavnav/v1` reaches `alive`). A token per vehicle under
//! `vehicle/` made every pose and health put cost in proportion to the fleet (10,000 vehicles:
//! ~4 ms a put, measured with `cargo bench -p uavnavd --bench idle_fleet`), and so did 10,000
//! tokens directly under `alive/`.
//!
//! Payloads are the protobuf encoding of the message, with Zenoh encoding `application/protobuf`
//! and the message's full name ([`Leaf::message_name`]) as schema: [`encoding_for`] gives that
//! encoding as the string Zenoh parses (`Encoding::from`), so that the service and its clients
//! label payloads alike without this crate depending on Zenoh.

use crate::names;
use crate::v1;
use crate::v1::sensor_envelope::Payload;

/// Prefix of every vehicle key.
pub const VEHICLE_PREFIX: &str = "uavnav/v1/vehicle";
/// The vehicle-list queryable.
pub const VEHICLES: &str = "uavnav/v1/vehicles";
/// Prefix of the service liveliness tokens.
pub const SERVICE_PREFIX: &str = "uavnav/v1/service";
/// Prefix of the vehicles' liveliness tokens.
pub const ALIVE_PREFIX: &str = "uavnav/v1/alive/vehicle";
/// Every key under every vehicle (inputs, outputs, queryables).
pub const ALL_VEHICLE_KEYS: &str = "uavnav/v1/vehicle/**";
/// Every `{leaf}` of every vehicle (the service's input subscription; it also matches the
/// outputs, which the service skips).
pub const EVERY_VEHICLE_LEAF: &str = "uavnav/v1/vehicle/*/*";
/// The latest-pose queryables of every vehicle.
pub const EVERY_POSE_LATEST: &str = "uavnav/v1/vehicle/*/pose/latest";

/// The Zenoh encoding of every payload, before the schema: Zenoh's well-known protobuf encoding
/// (a peer that checks the encoding id sees protobuf, not a custom string).
pub const PROTOBUF_ENCODING: &str = "application/protobuf";

/// The Zenoh encoding of a payload whose message has protobuf full name `full_name` (e.g.
/// [`Leaf::message_name`]): `application/protobuf;{full_name}`, Zenoh's `encoding;schema` form.
pub fn encoding_for(full_name: &str) -> String {
    format!("{PROTOBUF_ENCODING};{full_name}")
}

/// Leaf of each input and output of a vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Leaf {
    /// `uavnav.v1.ImuBatch` input.
    Imu,
    /// `uavnav.v1.GnssFix` input.
    Gnss,
    /// `uavnav.v1.MagSample` input.
    Mag,
    /// `uavnav.v1.BaroSample` input.
    Baro,
    /// `uavnav.v1.CameraFrame` input.
    Camera,
    /// `uavnav.v1.VehicleConfig` input.
    Config,
    /// `uavnav.v1.PoseEstimate` output.
    Pose,
    /// `uavnav.v1.VehicleHealth` output.
    Health,
    /// `uavnav.v1.VehicleHealth` output, only the reports of a vehicle that runs without the
    /// configuration a client gave (`configured: false`): what a sender's keeper subscribes to,
    /// so that it makes the service publish nothing for configured vehicles.
    Unconfigured,
}

impl Leaf {
    /// The input leaves (what a sender publishes), in the service's tie order.
    pub const INPUTS: [Leaf; 6] = [
        Leaf::Imu,
        Leaf::Gnss,
        Leaf::Mag,
        Leaf::Baro,
        Leaf::Camera,
        Leaf::Config,
    ];

    /// The output leaves (what the service publishes).
    pub const OUTPUTS: [Leaf; 3] = [Leaf::Pose, Leaf::Health, Leaf::Unconfigured];

    /// The key chunk.
    pub fn as_str(self) -> &'static str {
        match self {
            Leaf::Imu => "imu",
            Leaf::Gnss => "gnss",
            Leaf::Mag => "mag",
            Leaf::Baro => "baro",
            Leaf::Camera => "camera",
            Leaf::Config => "config",
            Leaf::Pose => "pose",
            Leaf::Health => "health",
            Leaf::Unconfigured => "unconfigured",
        }
    }

    /// The full protobuf name of the payload (Zenoh encoding schema, MCAP schema name).
    pub fn message_name(self) -> &'static str {
        match self {
            Leaf::Imu => names::IMU_BATCH,
            Leaf::Gnss => names::GNSS_FIX,
            Leaf::Mag => names::MAG_SAMPLE,
            Leaf::Baro => names::BARO_SAMPLE,
            Leaf::Camera => names::CAMERA_FRAME,
            Leaf::Config => names::VEHICLE_CONFIG,
            Leaf::Pose => names::POSE_ESTIMATE,
            Leaf::Health | Leaf::Unconfigured => names::VEHICLE_HEALTH,
        }
    }

    /// Decodes the protobuf bytes of an input leaf's message into a `SensorEnvelope` payload;
    /// `None` for an output leaf. What the service's Zenoh input and `uavnav record` receive, and
    /// the recording reader reads back (but for a recorded camera frame, stored as its image).
    pub fn decode_input(self, bytes: &[u8]) -> Option<Result<Payload, prost::DecodeError>> {
        use prost::Message;
        Some(match self {
            Leaf::Imu => v1::ImuBatch::decode(bytes).map(Payload::Imu),
            Leaf::Gnss => v1::GnssFix::decode(bytes).map(Payload::Gnss),
            Leaf::Mag => v1::MagSample::decode(bytes).map(Payload::Mag),
            Leaf::Baro => v1::BaroSample::decode(bytes).map(Payload::Baro),
            Leaf::Camera => v1::CameraFrame::decode(bytes).map(Payload::Camera),
            Leaf::Config => v1::VehicleConfig::decode(bytes).map(Payload::Config),
            Leaf::Pose | Leaf::Health | Leaf::Unconfigured => return None,
        })
    }

    /// Whether a sender publishes it (an input of the service).
    pub fn is_input(self) -> bool {
        !matches!(self, Leaf::Pose | Leaf::Health | Leaf::Unconfigured)
    }

    /// Parses a key chunk.
    pub fn parse(s: &str) -> Option<Leaf> {
        Some(match s {
            "imu" => Leaf::Imu,
            "gnss" => Leaf::Gnss,
            "mag" => Leaf::Mag,
            "baro" => Leaf::Baro,
            "camera" => Leaf::Camera,
            "config" => Leaf::Config,
            "pose" => Leaf::Pose,
            "health" => Leaf::Health,
            "unconfigured" => Leaf::Unconfigured,
            _ => return None,
        })
    }
}

/// `uavnav/v1/vehicle/{id}/{leaf}` (`id` may be `*`).
pub fn vehicle_key(id: &str, leaf: Leaf) -> String {
    format!("{VEHICLE_PREFIX}/{id}/{}", leaf.as_str())
}

/// A JSON string literal of `s`: Zenoh configuration values are JSON5, and the service and the
/// client both put paths and names from their own configuration into one (quotes, backslashes
/// and control characters escaped).
pub fn json_string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// `uavnav/v1/vehicle/{id}/pose/latest` (the latest-pose queryable).
pub fn pose_latest_key(id: &str) -> String {
    format!("{VEHICLE_PREFIX}/{id}/pose/latest")
}

/// `uavnav/v1/alive/vehicle/{id}` (the vehicle's liveliness token).
pub fn alive_key(id: &str) -> String {
    format!("{ALIVE_PREFIX}/{id}")
}

/// `uavnav/v1/service/{instance}` (a service's liveliness token).
pub fn service_key(instance: &str) -> String {
    format!("{SERVICE_PREFIX}/{instance}")
}

/// `uavnav/v1/vehicle/{id}/{rest}` → (id, rest), for any vehicle key.
pub fn split_vehicle(key: &str) -> Option<(&str, &str)> {
    let rest = key.strip_prefix(VEHICLE_PREFIX)?.strip_prefix('/')?;
    rest.split_once('/')
}

/// `uavnav/v1/vehicle/{id}/{leaf}` → (id, leaf); `None` for other keys (e.g. `pose/latest`).
pub fn split(key: &str) -> Option<(&str, Leaf)> {
    let (id, leaf) = split_vehicle(key)?;
    Some((id, Leaf::parse(leaf)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: [Leaf; 9] = [
        Leaf::Imu,
        Leaf::Gnss,
        Leaf::Mag,
        Leaf::Baro,
        Leaf::Camera,
        Leaf::Config,
        Leaf::Pose,
        Leaf::Health,
        Leaf::Unconfigured,
    ];

    /// The wire contract: these strings are what deployed senders and ground stations use.
    #[test]
    fn keys_are_the_documented_strings() {
        assert_eq!(
            vehicle_key("uav-7", Leaf::Imu),
            "uavnav/v1/vehicle/uav-7/imu"
        );
        assert_eq!(vehicle_key("*", Leaf::Pose), "uavnav/v1/vehicle/*/pose");
        assert_eq!(pose_latest_key("a"), "uavnav/v1/vehicle/a/pose/latest");
        assert_eq!(pose_latest_key("*"), EVERY_POSE_LATEST);
        assert_eq!(service_key("host-1"), "uavnav/v1/service/host-1");
        assert_eq!(VEHICLES, "uavnav/v1/vehicles");
        assert_eq!(ALL_VEHICLE_KEYS, format!("{VEHICLE_PREFIX}/**"));
        assert_eq!(EVERY_VEHICLE_LEAF, format!("{VEHICLE_PREFIX}/*/*"));
        let chunks: Vec<&str> = ALL.iter().map(|l| l.as_str()).collect();
        assert_eq!(
            chunks,
            [
                "imu",
                "gnss",
                "mag",
                "baro",
                "camera",
                "config",
                "pose",
                "health",
                "unconfigured"
            ]
        );
        assert_eq!(Leaf::Camera.message_name(), "uavnav.v1.CameraFrame");
        assert_eq!(Leaf::Health.message_name(), "uavnav.v1.VehicleHealth");
    }

    /// The encodings deployed peers see: protobuf with the message's full name as schema.
    #[test]
    fn encodings_are_protobuf_with_the_message_name() {
        assert_eq!(
            encoding_for(Leaf::Imu.message_name()),
            "application/protobuf;uavnav.v1.ImuBatch"
        );
        assert_eq!(
            encoding_for(crate::names::LIST_VEHICLES_RESPONSE),
            "application/protobuf;uavnav.v1.ListVehiclesResponse"
        );
        for leaf in ALL {
            let e = encoding_for(leaf.message_name());
            let (prefix, schema) = e.split_once(';').unwrap();
            assert_eq!(prefix, PROTOBUF_ENCODING);
            assert_eq!(schema, leaf.message_name());
        }
    }

    #[test]
    fn inputs_decode_as_their_payload_and_outputs_not_at_all() {
        use prost::Message;
        let fix = v1::GnssFix {
            t_ns: 7,
            latitude_deg: 45.0,
            ..Default::default()
        };
        let got = Leaf::Gnss.decode_input(&fix.encode_to_vec()).unwrap();
        assert_eq!(got.unwrap(), Payload::Gnss(fix));
        let batch = v1::ImuBatch {
            samples: vec![v1::ImuSample::default(); 2],
        };
        let got = Leaf::Imu.decode_input(&batch.encode_to_vec()).unwrap();
        assert_eq!(got.unwrap(), Payload::Imu(batch));
        assert!(Leaf::Config.decode_input(&[0xff, 0xff]).unwrap().is_err());
        for leaf in Leaf::OUTPUTS {
            assert!(leaf.decode_input(&[]).is_none(), "{leaf:?}");
        }
        for leaf in Leaf::INPUTS {
            assert!(leaf.decode_input(&[]).is_some(), "{leaf:?}");
        }
    }

    /// Why the tokens sit where they do (see the module doc): not among the vehicle keys, and
    /// not as children of a node that a put's routing walk enters (a child of `uavnav/v1`).
    #[test]
    fn vehicle_tokens_stay_out_of_the_output_puts_routing_walk() {
        let token = alive_key("a");
        assert!(split_vehicle(&token).is_none() && !token.starts_with(VEHICLE_PREFIX));
        let below_v1 = token.strip_prefix("uavnav/v1/").unwrap();
        assert_eq!(below_v1.split('/').count(), 3, "{token}: alive/<node>/<id>");
    }

    #[test]
    fn json_strings_are_escaped() {
        assert_eq!(json_string(r#"/a "b"\c"#), r#""/a \"b\"\\c""#);
        assert_eq!(json_string("a\nb"), r#""a\u000ab""#);
    }

    #[test]
    fn keys_round_trip() {
        for leaf in ALL {
            assert_eq!(split(&vehicle_key("uav-7", leaf)), Some(("uav-7", leaf)));
            assert_eq!(Leaf::parse(leaf.as_str()), Some(leaf));
            assert_eq!(
                leaf.is_input(),
                Leaf::INPUTS.contains(&leaf),
                "{leaf:?} is an input or an output"
            );
            assert_ne!(Leaf::INPUTS.contains(&leaf), Leaf::OUTPUTS.contains(&leaf));
        }
        assert_eq!(split(&pose_latest_key("a")), None);
        assert_eq!(split(&alive_key("a")), None);
        assert_eq!(split_vehicle(&alive_key("a")), None);
        assert_eq!(alive_key("a"), "uavnav/v1/alive/vehicle/a");
        assert_eq!(split("uavnav/v1/vehicles"), None);
        assert_eq!(split("other/v1/vehicle/a/imu"), None);
    }
}
