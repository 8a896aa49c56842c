//! One sensor input as it travels on the wire, borrowed ([`InputRef`]): what code that handles an
//! input without owning it matches on — the service's ingest path whichever transport the message
//! came by, the recorders writing it to MCAP — so that the six input kinds are listed once.

use crate::v1;
use crate::v1::sensor_envelope::Payload;

/// A borrowed sensor input: the variants of [`Payload`] (a `SensorEnvelope`'s payload), by
/// reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InputRef<'a> {
    /// An IMU batch.
    Imu(&'a v1::ImuBatch),
    /// A GNSS fix.
    Gnss(&'a v1::GnssFix),
    /// A magnetometer sample.
    Mag(&'a v1::MagSample),
    /// A barometer sample.
    Baro(&'a v1::BaroSample),
    /// A camera frame.
    Camera(&'a v1::CameraFrame),
    /// A vehicle configuration.
    Config(&'a v1::VehicleConfig),
}

impl<'a> From<&'a Payload> for InputRef<'a> {
    fn from(p: &'a Payload) -> Self {
        match p {
            Payload::Imu(m) => InputRef::Imu(m),
            Payload::Gnss(m) => InputRef::Gnss(m),
            Payload::Mag(m) => InputRef::Mag(m),
            Payload::Baro(m) => InputRef::Baro(m),
            Payload::Camera(m) => InputRef::Camera(m),
            Payload::Config(m) => InputRef::Config(m),
        }
    }
}
