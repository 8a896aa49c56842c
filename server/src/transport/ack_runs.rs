//! Acknowledgement runs on an `Ingest` stream that asks for them (request header
//! [`ACK_RUNS_HEADER`]: `1`).
//!
//! Every envelope is still answered, in order, but a run of consecutive plain acceptances (sensor
//! data, ACCEPTED, no reason, `needs_config` false) goes out as one `IngestAck` whose `covers`
//! counts them. At fleet scale nearly every ack is such an acceptance, and each one otherwise
//! costs the service a queue slot, an encoding and a wake-up of the response stream, and the
//! client a decoding: one ack per read of the request stream instead of one per envelope.
//!
//! The gRPC task holds a run only while more envelopes are already received (see
//! `transport::grpc`), and at most [`MAX_RUN`] of them, so an ack is never held while the
//! stream waits. Anything else (a refusal, a reason, `needs_config`, a configuration) ends the
//! run: the run goes out first, then its own ack. A stream that did not ask gets one ack per
//! envelope, as the contract has always said.

use uavnav_proto::v1 as pb;

pub use uavnav_proto::ACK_RUNS_HEADER;

/// Most envelopes one ack answers (bounds how far acks trail a stream that never pauses).
pub const MAX_RUN: u32 = 64;

/// Whether `metadata` asks for acknowledgement runs.
pub fn asked(metadata: &tonic::metadata::MetadataMap) -> bool {
    metadata
        .get(ACK_RUNS_HEADER)
        .is_some_and(|v| v.as_bytes() == b"1")
}

/// The run being held on one stream.
#[derive(Debug, Default)]
pub struct AckRuns {
    enabled: bool,
    run: Option<pb::IngestAck>,
}

impl AckRuns {
    /// Runs on (`enabled`: the stream asked) or off (one ack per envelope).
    pub fn new(enabled: bool) -> Self {
        Self { enabled, run: None }
    }

    /// Takes the ack of the next envelope (`data`: it carried sensor data, not a configuration)
    /// and returns what must go out now, in order: a finished run, then the ack itself when it
    /// cannot join a run.
    pub fn push(&mut self, mut ack: pb::IngestAck, data: bool) -> [Option<pb::IngestAck>; 2] {
        if !self.enabled {
            return [None, Some(ack)];
        }
        let plain = data
            && ack.status == pb::IngestStatus::Accepted as i32
            && ack.reason.is_empty()
            && !ack.needs_config;
        ack.covers = 1;
        if !plain {
            return [self.run.take(), Some(ack)];
        }
        match self.run.as_mut() {
            Some(run) => {
                run.covers += 1;
                run.sequence = ack.sequence;
                run.vehicle_id = ack.vehicle_id;
                if run.covers >= MAX_RUN {
                    return [self.run.take(), None];
                }
            }
            None => self.run = Some(ack),
        }
        [None, None]
    }

    /// Whether a run is held (the caller sends it with [`AckRuns::flush`] before waiting).
    pub fn holding(&self) -> bool {
        self.run.is_some()
    }

    /// The run held, to send now.
    pub fn flush(&mut self) -> Option<pb::IngestAck> {
        self.run.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ack(sequence: u64, status: pb::IngestStatus) -> pb::IngestAck {
        pb::IngestAck {
            sequence,
            vehicle_id: format!("v{sequence}"),
            status: status as i32,
            ..Default::default()
        }
    }

    /// Feeds acks through `runs`, flushing at the end; every ack sent, in order.
    fn feed(runs: &mut AckRuns, acks: Vec<(pb::IngestAck, bool)>) -> Vec<pb::IngestAck> {
        let mut out = Vec::new();
        for (a, data) in acks {
            out.extend(runs.push(a, data).into_iter().flatten());
        }
        out.extend(runs.flush());
        out
    }

    #[test]
    fn off_answers_every_envelope_unchanged() {
        let mut runs = AckRuns::new(false);
        let sent = feed(
            &mut runs,
            (0..5)
                .map(|i| (ack(i, pb::IngestStatus::Accepted), true))
                .collect(),
        );
        assert_eq!(sent.len(), 5);
        assert!(sent.iter().all(|a| a.covers == 0));
        assert!(!runs.holding());
    }

    #[test]
    fn a_run_answers_every_envelope_in_order_and_a_refusal_breaks_it() {
        let mut runs = AckRuns::new(true);
        let mut acks: Vec<_> = (0..3)
            .map(|i| (ack(i, pb::IngestStatus::Accepted), true))
            .collect();
        acks.push((ack(3, pb::IngestStatus::Late), true));
        acks.extend((4..6).map(|i| (ack(i, pb::IngestStatus::Accepted), true)));
        // A configuration, even accepted, is answered alone (its sender matches its sequence).
        acks.push((ack(6, pb::IngestStatus::Accepted), false));
        let mut needs = ack(7, pb::IngestStatus::Accepted);
        needs.needs_config = true;
        acks.push((needs, true));
        let mut remark = ack(8, pb::IngestStatus::Accepted);
        remark.reason = "1 of 4 samples dropped".into();
        acks.push((remark, true));
        acks.push((ack(9, pb::IngestStatus::Accepted), true));
        let sent = feed(&mut runs, acks);
        let shape: Vec<(u64, u32)> = sent.iter().map(|a| (a.sequence, a.covers)).collect();
        assert_eq!(
            shape,
            vec![(2, 3), (3, 1), (5, 2), (6, 1), (7, 1), (8, 1), (9, 1)]
        );
        assert_eq!(
            sent[0].vehicle_id, "v2",
            "a run carries its last envelope's id"
        );
        assert_eq!(sent.iter().map(|a| a.covers).sum::<u32>(), 10);
    }

    #[test]
    fn a_run_never_exceeds_its_cap() {
        let mut runs = AckRuns::new(true);
        let n = u64::from(MAX_RUN) * 2 + 5;
        let sent = feed(
            &mut runs,
            (0..n)
                .map(|i| (ack(i, pb::IngestStatus::Accepted), true))
                .collect(),
        );
        let covers: Vec<u32> = sent.iter().map(|a| a.covers).collect();
        assert_eq!(covers, vec![MAX_RUN, MAX_RUN, 5]);
    }

    #[test]
    fn only_the_exact_header_value_asks() {
        let mut m = tonic::metadata::MetadataMap::new();
        assert!(!asked(&m));
        m.insert(ACK_RUNS_HEADER, "0".parse().unwrap());
        assert!(!asked(&m));
        m.insert(ACK_RUNS_HEADER, "1".parse().unwrap());
        assert!(asked(&m));
    }
}
