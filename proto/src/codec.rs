//! The gRPC codec of `uavnav.v1.UavNav` (generated code uses it through `codec_path`): prost
//! encoding, and decoding that checks size limits on the wire before it allocates.
//!
//! A repeated field's entries can be far smaller encoded than decoded (an empty `ImuSample` is 2
//! bytes on the wire, 56 in memory), so a message within `max_decoding_message_size` may still
//! decode into hundreds of megabytes. The request types with a repeated field count their entries
//! first ([`crate::wire`]):
//!
//! - `SensorEnvelope`: an IMU batch above [`limits::MAX_IMU_BATCH_SAMPLES`] decodes with only the
//!   first `limit + 1` samples, so the service refuses it in its ack (RESOURCE_EXHAUSTED, the
//!   stream goes on) having allocated at most that much;
//! - `WatchRequest`: more than [`limits::MAX_WATCH_IDS`] vehicle ids is INVALID_ARGUMENT.
//!
//! Malformed protobuf is reported as prost's codec reports it (INTERNAL, "failed to decode
//! Protobuf message"; the service maps that to INVALID_ARGUMENT for requests).

use std::marker::PhantomData;

use prost::Message;
use prost::bytes::Buf;
use tonic::Status;
use tonic::codec::{BufferSettings, Codec, DecodeBuf, Decoder};
use tonic_prost::ProstEncoder;

use crate::convert::limits;
use crate::v1;
use crate::wire::{self, WireError};

/// Decoding of one request or response type with its size limits checked on the wire first.
pub trait BoundedDecode: Message + Default + Sized {
    /// Decodes `bytes` (one whole message). The default is the plain prost decode.
    fn decode_bounded(bytes: prost::bytes::Bytes) -> Result<Self, Status> {
        Self::decode(bytes).map_err(malformed)
    }
}

/// The status of bytes prost cannot decode (that of `tonic_prost::ProstCodec`).
fn malformed(e: prost::DecodeError) -> Status {
    Status::internal(e.to_string())
}

/// The status of bytes the wire scanner cannot walk (prost could not decode them either).
fn wire_status(e: WireError) -> Status {
    match e {
        WireError::Malformed(e) => malformed(e),
        other => Status::internal(format!("failed to decode Protobuf message: {other}")),
    }
}

impl BoundedDecode for v1::SensorEnvelope {
    fn decode_bounded(bytes: prost::bytes::Bytes) -> Result<Self, Status> {
        let max = limits::MAX_IMU_BATCH_SAMPLES;
        if wire::envelope_imu_samples(&bytes).map_err(wire_status)? > max {
            return wire::decode_envelope_bounded(&bytes, max).map_err(wire_status);
        }
        Self::decode(bytes).map_err(malformed)
    }
}

impl BoundedDecode for v1::WatchRequest {
    fn decode_bounded(bytes: prost::bytes::Bytes) -> Result<Self, Status> {
        let ids = wire::count_field(&bytes, 1).map_err(wire_status)?;
        if ids > limits::MAX_WATCH_IDS {
            return Err(Status::invalid_argument(format!(
                "vehicle_ids: {ids} ids, limit {} (select by id_prefix or all)",
                limits::MAX_WATCH_IDS
            )));
        }
        Self::decode(bytes).map_err(malformed)
    }
}

/// The messages without a repeated field of their own decode as usual.
macro_rules! plain {
    ($($t:ty),* $(,)?) => { $(impl BoundedDecode for $t {})* };
}

plain!(
    v1::IngestAck,
    v1::PoseEstimate,
    v1::VehicleHealth,
    v1::GetPoseRequest,
    v1::ListVehiclesRequest,
    v1::ListVehiclesResponse,
    v1::ConfigureVehicleRequest,
    v1::ConfigureVehicleResponse,
    v1::ResetVehicleRequest,
    v1::ResetVehicleResponse,
);

/// The codec: prost encoding, [`BoundedDecode`] decoding.
#[derive(Debug, Clone)]
pub struct BoundedCodec<T, U> {
    _pd: PhantomData<(T, U)>,
}

impl<T, U> Default for BoundedCodec<T, U> {
    fn default() -> Self {
        Self { _pd: PhantomData }
    }
}

impl<T, U> Codec for BoundedCodec<T, U>
where
    T: Message + Send + 'static,
    U: BoundedDecode + Send + 'static,
{
    type Encode = T;
    type Decode = U;
    type Encoder = ProstEncoder<T>;
    type Decoder = BoundedDecoder<U>;

    fn encoder(&mut self) -> Self::Encoder {
        ProstEncoder::new(BufferSettings::default())
    }

    fn decoder(&mut self) -> Self::Decoder {
        BoundedDecoder { _pd: PhantomData }
    }
}

/// The decoder of [`BoundedCodec`].
#[derive(Debug, Clone)]
pub struct BoundedDecoder<U> {
    _pd: PhantomData<U>,
}

impl<U: BoundedDecode> Decoder for BoundedDecoder<U> {
    type Item = U;
    type Error = Status;

    fn decode(&mut self, buf: &mut DecodeBuf<'_>) -> Result<Option<U>, Status> {
        // The message's bytes, without a copy (tonic's buffer is split off).
        let bytes = buf.copy_to_bytes(buf.remaining());
        U::decode_bounded(bytes).map(Some)
    }
}
