//! MAVLink telemetry logs (`.tlog`, as ground stations record them): the byte layer.
//!
//! A tlog is a sequence of records, each an 8-byte big-endian UNIX time in µs (when the ground
//! station received it) followed by one MAVLink frame, v1 (`FE len seq sys comp id payload crc`)
//! or v2 (`FD len incompat compat seq sys comp id[3] payload crc [signature 13]`). The frame's
//! checksum is CRC-16/MCRF4XX over the frame after the start byte, then the message's `CRC_EXTRA`
//! byte (a hash of its definition), so a frame is only trusted for the messages whose definition
//! we know ([`crc_extra`]); others are framed by their length and counted. v2 drops the trailing
//! zero bytes of a payload; they are restored here.
//!
//! Radio links corrupt and drop bytes, so a tlog is read past damage: a record whose start byte is
//! wrong, or whose checksum fails, is skipped and the reader resynchronises on the next record
//! whose start byte and receive time are plausible. Skips are counted for the import's notes; a
//! record cut by the end of the file is a cut tail.

/// One decoded frame.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Frame {
    /// Ground-station receive time, UNIX µs.
    pub(crate) rx_us: u64,
    /// Sending system and component.
    pub(crate) sys: u8,
    pub(crate) comp: u8,
    /// Message id.
    pub(crate) id: u32,
    /// Payload, zero-padded to its full length for known messages.
    pub(crate) payload: Vec<u8>,
}

/// What the byte layer found.
#[derive(Debug, Clone, Default)]
pub(crate) struct Tlog {
    /// Frames of known messages whose checksum passed, in file order.
    pub(crate) frames: Vec<Frame>,
    /// Frames of messages we do not decode, by id (framed by their length, not checked).
    pub(crate) unknown: std::collections::BTreeMap<u32, usize>,
    /// Known frames whose checksum failed.
    pub(crate) crc_errors: usize,
    /// Places where the reader lost the framing and searched for the next record.
    pub(crate) resyncs: usize,
    /// Byte offset of a last record cut by the end of the file.
    pub(crate) cut_at: Option<usize>,
}

/// UNIX µs of 2000-01-01 and 2100-01-01: the plausible receive times.
const RX_MIN_US: u64 = 946_684_800_000_000;
const RX_MAX_US: u64 = 4_102_444_800_000_000;
const STX_V1: u8 = 0xFE;
const STX_V2: u8 = 0xFD;

/// `CRC_EXTRA` and full payload length of the messages the importer reads (MAVLink common set).
pub(crate) fn crc_extra(id: u32) -> Option<(u8, usize)> {
    Some(match id {
        0 => (50, 9),    // HEARTBEAT
        2 => (137, 12),  // SYSTEM_TIME
        22 => (220, 25), // PARAM_VALUE
        24 => (24, 52),  // GPS_RAW_INT (v2 extensions included)
        27 => (144, 29), // RAW_IMU (v2 extensions included)
        29 => (115, 16), // SCALED_PRESSURE (v2 extension included)
        30 => (39, 28),  // ATTITUDE
        33 => (104, 28), // GLOBAL_POSITION_INT
        116 => (76, 24), // SCALED_IMU2 (v2 extension included)
        _ => return None,
    })
}

/// The v1 payload length of those messages (before the v2 extension fields).
fn v1_len(id: u32) -> Option<usize> {
    Some(match id {
        24 => 30,
        27 => 26,
        29 => 14,
        116 => 22,
        _ => crc_extra(id)?.1,
    })
}

/// Whether `data` starts like a tlog: a plausible receive time and a MAVLink start byte.
pub(crate) fn sniff(data: &[u8]) -> bool {
    record_start(data, 0)
}

fn rx_us(data: &[u8], at: usize) -> Option<u64> {
    let b: [u8; 8] = data.get(at..at + 8)?.try_into().ok()?;
    Some(u64::from_be_bytes(b))
}

fn record_start(data: &[u8], at: usize) -> bool {
    rx_us(data, at).is_some_and(|t| (RX_MIN_US..RX_MAX_US).contains(&t))
        && matches!(data.get(at + 8), Some(&STX_V1 | &STX_V2))
}

/// CRC-16/MCRF4XX, MAVLink's `X25` checksum.
pub(crate) fn crc16(bytes: &[u8], mut crc: u16) -> u16 {
    for &b in bytes {
        let mut tmp = b ^ (crc & 0xFF) as u8;
        tmp ^= tmp << 4;
        let t = u16::from(tmp);
        crc = (crc >> 8) ^ (t << 8) ^ (t << 3) ^ (t >> 4);
    }
    crc
}

enum Step {
    /// A frame (or a skipped one) ending at this offset.
    Next(usize),
    /// The framing is lost at this offset.
    Lost,
    /// The record is cut by the end of the input.
    Cut,
}

/// Reads the record at `at` into `log`.
fn step(data: &[u8], at: usize, log: &mut Tlog) -> Step {
    let Some(rx) = rx_us(data, at) else {
        return Step::Cut;
    };
    let f = at + 8;
    let Some(&stx) = data.get(f) else {
        return Step::Cut;
    };
    let (head, id_of): (usize, fn(&[u8]) -> u32) = match stx {
        STX_V1 => (6, |h| u32::from(h[5])),
        STX_V2 => (10, |h| u32::from_le_bytes([h[7], h[8], h[9], 0])),
        _ => return Step::Lost,
    };
    let Some(h) = data.get(f..f + head) else {
        return Step::Cut;
    };
    let len = usize::from(h[1]);
    let signed = stx == STX_V2 && h[2] & 0x01 != 0;
    let total = head + len + 2 + if signed { 13 } else { 0 };
    let Some(frame) = data.get(f..f + total) else {
        return Step::Cut;
    };
    let id = id_of(h);
    let (sys, comp) = if stx == STX_V1 {
        (h[3], h[4])
    } else {
        (h[5], h[6])
    };
    let Some((extra, full)) = crc_extra(id) else {
        *log.unknown.entry(id).or_default() += 1;
        return Step::Next(f + total);
    };
    let body = &frame[1..head + len];
    let crc = crc16(&[extra], crc16(body, 0xFFFF));
    let got = u16::from_le_bytes([frame[head + len], frame[head + len + 1]]);
    // A v1 frame must carry the whole v1 payload; v2 may drop trailing zeros.
    let short = stx == STX_V1 && v1_len(id).is_some_and(|n| len < n);
    if crc != got || len > full || short {
        log.crc_errors += 1;
        return Step::Next(f + total);
    }
    let mut payload = frame[head..head + len].to_vec();
    payload.resize(full, 0);
    log.frames.push(Frame {
        rx_us: rx,
        sys,
        comp,
        id,
        payload,
    });
    Step::Next(f + total)
}

/// Reads every record; never fails (damage is counted, see the module doc).
pub(crate) fn parse(data: &[u8]) -> Tlog {
    let mut log = Tlog::default();
    let mut at = 0;
    while at < data.len() {
        match step(data, at, &mut log) {
            Step::Next(next) => at = next,
            Step::Cut => {
                log.cut_at = Some(at);
                break;
            }
            Step::Lost => {
                log.resyncs += 1;
                match (at + 1..data.len()).find(|&p| record_start(data, p)) {
                    Some(p) => at = p,
                    None => break,
                }
            }
        }
    }
    log
}

/// Little-endian field readers over a zero-padded payload (lengths are checked at parse time).
pub(crate) struct Fields<'a>(pub(crate) &'a [u8]);

impl Fields<'_> {
    fn arr<const K: usize>(&self, at: usize) -> [u8; K] {
        let mut b = [0u8; K];
        if let Some(s) = self.0.get(at..at + K) {
            b.copy_from_slice(s);
        }
        b
    }
    /// A `char[N]` field: the bytes before the first NUL (a MAVLink 2 payload may be cut short).
    pub(crate) fn text(&self, at: usize, n: usize) -> String {
        let bytes = self.0.get(at..).unwrap_or_default();
        let bytes = &bytes[..bytes.len().min(n)];
        let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
        String::from_utf8_lossy(&bytes[..end]).into_owned()
    }
    pub(crate) fn u8(&self, at: usize) -> u8 {
        self.0.get(at).copied().unwrap_or(0)
    }
    pub(crate) fn i16(&self, at: usize) -> f64 {
        f64::from(i16::from_le_bytes(self.arr(at)))
    }
    pub(crate) fn u16(&self, at: usize) -> f64 {
        f64::from(u16::from_le_bytes(self.arr(at)))
    }
    pub(crate) fn i32(&self, at: usize) -> f64 {
        f64::from(i32::from_le_bytes(self.arr(at)))
    }
    pub(crate) fn u32(&self, at: usize) -> f64 {
        f64::from(u32::from_le_bytes(self.arr(at)))
    }
    pub(crate) fn u64(&self, at: usize) -> u64 {
        u64::from_le_bytes(self.arr(at))
    }
    pub(crate) fn f32(&self, at: usize) -> f64 {
        f64::from(f32::from_le_bytes(self.arr(at)))
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// One v1 record of message `id` with `payload` at receive time `rx_us`.
    pub(crate) fn record_v1(rx_us: u64, id: u8, payload: &[u8]) -> Vec<u8> {
        let mut out = rx_us.to_be_bytes().to_vec();
        let mut frame = vec![STX_V1, payload.len() as u8, 0, 1, 1, id];
        frame.extend(payload);
        let extra = crc_extra(u32::from(id)).map_or(0, |e| e.0);
        let crc = crc16(&[extra], crc16(&frame[1..], 0xFFFF));
        frame.extend(crc.to_le_bytes());
        out.extend(frame);
        out
    }

    #[test]
    fn the_checksum_matches_mavlinks_reference_value() {
        // MCRF4XX of "123456789" is 0x6F91.
        assert_eq!(crc16(b"123456789", 0xFFFF), 0x6F91);
    }

    #[test]
    fn records_are_framed_checked_and_resynchronised() {
        let t = 1_533_737_161_905_000u64;
        let mut data = record_v1(t, 2, &[0u8; 12]);
        let mut bad = record_v1(t + 1, 2, &[1u8; 12]);
        let n = bad.len();
        bad[n - 1] ^= 0xFF; // checksum broken
        data.extend(bad);
        data.extend([0x00, 0x11, 0x22]); // line noise
        data.extend(record_v1(t + 2, 0, &[0u8; 9]));
        data.extend(&record_v1(t + 3, 2, &[0u8; 12])[..10]); // cut
        let log = parse(&data);
        assert_eq!(log.frames.len(), 2);
        assert_eq!(log.crc_errors, 1);
        assert_eq!(log.resyncs, 1);
        assert!(log.cut_at.is_some());
        assert_eq!(log.frames[1].id, 0);
    }
}
