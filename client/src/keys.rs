//! The service's Zenoh key expressions (see the server's `zenoh_io` module; a test checks they agree).

/// Prefix of every vehicle key.
pub const VEHICLE_PREFIX: &str = "uavnav/v1/vehicle";
/// The vehicle-list queryable.
pub const VEHICLES: &str = "uavnav/v1/vehicles";
/// Prefix of the service liveliness tokens.
pub const SERVICE_PREFIX: &str = "uavnav/v1/service";
/// Every key under every vehicle (inputs and outputs).
pub const ALL_VEHICLE_KEYS: &str = "uavnav/v1/vehicle/**";

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
        }
    }

    /// The full protobuf name of the payload (Zenoh encoding schema, MCAP schema name).
    pub fn message_name(self) -> &'static str {
        use uavnav_proto::names;
        match self {
            Leaf::Imu => names::IMU_BATCH,
            Leaf::Gnss => names::GNSS_FIX,
            Leaf::Mag => names::MAG_SAMPLE,
            Leaf::Baro => names::BARO_SAMPLE,
            Leaf::Camera => names::CAMERA_FRAME,
            Leaf::Config => names::VEHICLE_CONFIG,
            Leaf::Pose => names::POSE_ESTIMATE,
            Leaf::Health => names::VEHICLE_HEALTH,
        }
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
            _ => return None,
        })
    }
}

/// `uavnav/v1/vehicle/{id}/{leaf}`.
pub fn vehicle_key(id: &str, leaf: Leaf) -> String {
    format!("{VEHICLE_PREFIX}/{id}/{}", leaf.as_str())
}

/// `uavnav/v1/vehicle/{id}/pose/latest` (the latest-pose queryable).
pub fn pose_latest_key(id: &str) -> String {
    format!("{VEHICLE_PREFIX}/{id}/pose/latest")
}

/// `uavnav/v1/vehicle/{id}/{leaf}` → (id, leaf); `None` for other keys (e.g. `pose/latest`, `alive`).
pub fn split(key: &str) -> Option<(&str, Leaf)> {
    let rest = key.strip_prefix(VEHICLE_PREFIX)?.strip_prefix('/')?;
    let (id, leaf) = rest.split_once('/')?;
    Some((id, Leaf::parse(leaf)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_round_trip() {
        for leaf in [
            Leaf::Imu,
            Leaf::Gnss,
            Leaf::Mag,
            Leaf::Baro,
            Leaf::Camera,
            Leaf::Config,
            Leaf::Pose,
            Leaf::Health,
        ] {
            assert_eq!(split(&vehicle_key("uav-7", leaf)), Some(("uav-7", leaf)));
        }
        assert_eq!(split(&pose_latest_key("a")), None);
        assert_eq!(split("uavnav/v1/vehicle/a/alive"), None);
    }
}
