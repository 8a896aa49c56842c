//! Looking into encoded protobuf without decoding it: how many entries a repeated field holds,
//! so that a size limit is checked before anything is allocated.
//!
//! Decoding allocates per entry, and an entry can be tiny on the wire: an empty `ImuSample` is 2
//! bytes (key and zero length) but 56 bytes decoded, so a 16 MiB `ImuBatch` of empty samples is
//! 8.4 million samples and, with the vector's growth, ~700 MB. The scanner below walks the wire
//! format with prost's own primitives (keys, varints, skipping) and allocates nothing; a message it
//! cannot walk is one prost would refuse too.

use prost::Message;
use prost::encoding::{DecodeContext, WireType, decode_key, decode_varint, skip_field};

use crate::v1;

/// Why encoded bytes are not a protobuf message.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WireError {
    /// The bytes are not valid protobuf (truncated, bad key, bad varint...).
    #[error("{0}")]
    Malformed(#[from] prost::DecodeError),
    /// A known field is encoded with a wire type its declaration does not allow.
    #[error("field {field}: wire type {wire_type:?} where a message is declared")]
    WireType {
        /// The field path.
        field: &'static str,
        /// The wire type found.
        wire_type: WireType,
    },
}

/// One top-level field of an encoded message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field<'a> {
    /// Field number.
    pub number: u32,
    /// Wire type.
    pub wire_type: WireType,
    /// The field's encoding, key included.
    pub raw: &'a [u8],
    /// The payload of a length-delimited field (`None` for other wire types).
    pub body: Option<&'a [u8]>,
}

/// The top-level fields of an encoded message, in wire order. Yields one error and stops at the
/// first malformed field.
#[derive(Debug, Clone)]
pub struct Fields<'a> {
    rest: &'a [u8],
    failed: bool,
}

/// The top-level fields of `msg`.
pub fn fields(msg: &[u8]) -> Fields<'_> {
    Fields {
        rest: msg,
        failed: false,
    }
}

impl<'a> Fields<'a> {
    fn step(&mut self) -> Result<Field<'a>, prost::DecodeError> {
        let start = self.rest;
        let mut buf = self.rest;
        let (number, wire_type) = decode_key(&mut buf)?;
        let body = if wire_type == WireType::LengthDelimited {
            let len = decode_varint(&mut buf)?;
            let len = usize::try_from(len)
                .ok()
                .filter(|&l| l <= buf.len())
                .ok_or_else(|| truncated("length-delimited field runs past the end"))?;
            let (body, after) = buf.split_at(len);
            buf = after;
            Some(body)
        } else {
            skip_field(wire_type, number, &mut buf, DecodeContext::default())?;
            None
        };
        let used = start.len() - buf.len();
        self.rest = buf;
        Ok(Field {
            number,
            wire_type,
            raw: &start[..used],
            body,
        })
    }
}

#[allow(deprecated)] // `DecodeError::new` is the only public way to describe a custom failure
fn truncated(what: &'static str) -> prost::DecodeError {
    prost::DecodeError::new(what)
}

impl<'a> Iterator for Fields<'a> {
    type Item = Result<Field<'a>, prost::DecodeError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed || self.rest.is_empty() {
            return None;
        }
        let r = self.step();
        self.failed = r.is_err();
        Some(r)
    }
}

/// How many times field `number` occurs at the top level of `msg` (for a repeated field: its
/// entries), without decoding anything.
pub fn count_field(msg: &[u8], number: u32) -> Result<usize, WireError> {
    let mut n = 0;
    for f in fields(msg) {
        if f?.number == number {
            n += 1;
        }
    }
    Ok(n)
}

/// `SensorEnvelope` field numbers of the `payload` oneof, and the IMU batch's.
const ENVELOPE_IMU: u32 = 3;
const ENVELOPE_PAYLOADS: std::ops::RangeInclusive<u32> = 3..=8;
const BATCH_SAMPLES: u32 = 1;

/// The IMU batch bodies an encoded `SensorEnvelope` decodes to: protobuf merges repeated
/// occurrences of a message field, and a later member of the `payload` oneof replaces an earlier
/// one, so these are the `imu` occurrences after the last other payload, or none when another
/// payload comes last.
fn envelope_imu_bodies(env: &[u8]) -> Result<Vec<&[u8]>, WireError> {
    let mut bodies = Vec::new();
    for f in fields(env) {
        let f = f?;
        if !ENVELOPE_PAYLOADS.contains(&f.number) {
            continue;
        }
        if f.number != ENVELOPE_IMU {
            bodies.clear();
            continue;
        }
        match f.body {
            Some(b) => bodies.push(b),
            None => {
                return Err(WireError::WireType {
                    field: "imu",
                    wire_type: f.wire_type,
                });
            }
        }
    }
    Ok(bodies)
}

/// How many IMU samples an encoded `SensorEnvelope` carries (0 when its payload is not an IMU
/// batch), counted on the wire.
pub fn envelope_imu_samples(env: &[u8]) -> Result<usize, WireError> {
    let mut n = 0;
    for body in envelope_imu_bodies(env)? {
        n += count_field(body, BATCH_SAMPLES)?;
    }
    Ok(n)
}

/// Decodes a `SensorEnvelope` whose IMU batch may hold more than `max_samples` samples, keeping
/// at most `max_samples + 1` of them: enough for the validator to refuse the batch, with memory
/// bounded by the limit instead of the message length. Everything else decodes as usual.
pub fn decode_envelope_bounded(
    env: &[u8],
    max_samples: usize,
) -> Result<v1::SensorEnvelope, WireError> {
    let imu = envelope_imu_bodies(env)?;
    // The envelope without its IMU batches (small: the rest is an id and a sequence number).
    let mut rest = Vec::new();
    for f in fields(env) {
        let f = f?;
        if f.number != ENVELOPE_IMU {
            rest.extend_from_slice(f.raw);
        }
    }
    let mut out = v1::SensorEnvelope::decode(rest.as_slice())?;
    if imu.is_empty() {
        return Ok(out);
    }
    let keep = max_samples.saturating_add(1);
    let mut samples = Vec::with_capacity(keep.min(1 << 16));
    'bodies: for body in imu {
        for f in fields(body) {
            let f = f?;
            if f.number != BATCH_SAMPLES {
                continue;
            }
            let sample = f.body.ok_or(WireError::WireType {
                field: "imu.samples",
                wire_type: f.wire_type,
            })?;
            samples.push(v1::ImuSample::decode(sample)?);
            if samples.len() >= keep {
                break 'bodies;
            }
        }
    }
    out.payload = Some(v1::sensor_envelope::Payload::Imu(v1::ImuBatch { samples }));
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use v1::sensor_envelope::Payload;

    fn envelope(samples: usize) -> v1::SensorEnvelope {
        v1::SensorEnvelope {
            vehicle_id: "uav-1".into(),
            sequence: 7,
            payload: Some(Payload::Imu(v1::ImuBatch {
                samples: (0..samples)
                    .map(|i| v1::ImuSample {
                        t_ns: i as i64 + 1,
                        ..Default::default()
                    })
                    .collect(),
            })),
        }
    }

    #[test]
    fn counts_without_decoding_and_agrees_with_prost() {
        for n in [0usize, 1, 3, 1000] {
            let bytes = envelope(n).encode_to_vec();
            assert_eq!(envelope_imu_samples(&bytes).unwrap(), n);
            let batch = v1::ImuBatch {
                samples: vec![v1::ImuSample::default(); n],
            };
            assert_eq!(count_field(&batch.encode_to_vec(), 1).unwrap(), n);
        }
        let gnss = v1::SensorEnvelope {
            payload: Some(Payload::Gnss(v1::GnssFix::default())),
            ..Default::default()
        };
        assert_eq!(envelope_imu_samples(&gnss.encode_to_vec()).unwrap(), 0);
    }

    #[test]
    fn oneof_and_merge_rules_are_those_of_prost() {
        // imu (2 samples), then gnss, then imu (3 samples): prost keeps the last imu only.
        let a = envelope(2).encode_to_vec();
        let g = v1::SensorEnvelope {
            payload: Some(Payload::Gnss(v1::GnssFix::default())),
            ..Default::default()
        }
        .encode_to_vec();
        let b = envelope(3).encode_to_vec();
        let joined = [a.clone(), g.clone(), b.clone()].concat();
        let decoded = v1::SensorEnvelope::decode(joined.as_slice()).unwrap();
        let Some(Payload::Imu(batch)) = &decoded.payload else {
            panic!("{decoded:?}")
        };
        assert_eq!(envelope_imu_samples(&joined).unwrap(), batch.samples.len());
        // Two imu occurrences merge.
        let merged = [a.clone(), b.clone()].concat();
        assert_eq!(envelope_imu_samples(&merged).unwrap(), 5);
        // gnss last: no IMU samples.
        assert_eq!(envelope_imu_samples(&[a, g].concat()).unwrap(), 0);
    }

    #[test]
    fn bounded_decode_keeps_one_more_than_the_limit_and_the_rest_of_the_envelope() {
        let bytes = envelope(50).encode_to_vec();
        let env = decode_envelope_bounded(&bytes, 10).unwrap();
        assert_eq!((env.vehicle_id.as_str(), env.sequence), ("uav-1", 7));
        let Some(Payload::Imu(batch)) = env.payload else {
            panic!()
        };
        assert_eq!(batch.samples.len(), 11);
        assert_eq!(batch.samples[10].t_ns, 11);
        // Under the limit it is the plain decode.
        let small = decode_envelope_bounded(&envelope(5).encode_to_vec(), 10).unwrap();
        assert_eq!(small, envelope(5));
    }

    #[test]
    fn malformed_bytes_are_errors_not_panics() {
        for bad in [
            &[0x0A, 0xFF, 0x01, b'x'][..],
            &[0x1A, 0x05, 0x0A][..],
            &[0xFF][..],
            &[0x1B][..],
        ] {
            assert!(envelope_imu_samples(bad).is_err(), "{bad:?}");
            assert!(decode_envelope_bounded(bad, 1).is_err(), "{bad:?}");
            assert!(v1::SensorEnvelope::decode(bad).is_err(), "{bad:?}");
        }
        // field 3 as a varint: a wire-type error, as for prost.
        assert!(envelope_imu_samples(&[0x18, 0x01]).is_err());
        assert!(v1::SensorEnvelope::decode(&[0x18, 0x01][..]).is_err());
    }
}
