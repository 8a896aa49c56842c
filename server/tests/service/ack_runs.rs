//! Acknowledgement runs (`IngestAck.covers`), in process on port 0: a stream that asks (header
//! `uavnav-ack-runs: 1`) gets every envelope answered, in order, with fewer acks; a refusal in
//! the middle keeps its own ack; a stream that does not ask gets one ack per envelope.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use crate::common::*;
use uavnav_proto::v1 as pb;

/// The stream's first sample time (the stale envelope is 10 s before it).
const T0_NS: i64 = 100_000_000_000;
/// 200 Hz.
const DT: i64 = 5_000_000;

/// A configuration, then `n` 4-sample IMU envelopes, with one envelope of samples from before
/// the stream's start (LATE) after the first half.
fn envelopes(id: &str, n: usize) -> Vec<pb::SensorEnvelope> {
    let t0 = T0_NS;
    let mut envs = vec![config_env(id, 0, false)];
    for k in 0..n {
        let t = t0 + 4 * DT * k as i64;
        envs.push(imu_env(
            id,
            envs.len() as u64,
            (0..4).map(|i| imu(t + i * DT)).collect(),
        ));
        if k == n / 2 {
            let stale = vec![imu(t0 - 10_000_000_000)];
            envs.push(imu_env(id, envs.len() as u64, stale));
        }
    }
    envs
}

/// Sends `envs` on one stream (all at once), asking for runs or not, and reads acks until every
/// envelope is answered.
async fn acks(
    server: &uavnavd::RunningServer,
    envs: Vec<pb::SensorEnvelope>,
    runs: bool,
) -> Vec<pb::IngestAck> {
    let n = envs.len() as u64;
    let mut c = client(server).await;
    let mut request = tonic::Request::new(futures::stream::iter(envs));
    if runs {
        request
            .metadata_mut()
            .insert(uavnav_proto::ACK_RUNS_HEADER, "1".parse().unwrap());
    }
    let mut stream = c.ingest(request).await.unwrap().into_inner();
    let (mut out, mut answered) = (Vec::new(), 0u64);
    while answered < n {
        let a = stream
            .message()
            .await
            .unwrap()
            .expect("the stream ended before every ack");
        answered += u64::from(a.covers.max(1));
        out.push(a);
    }
    assert_eq!(answered, n, "acks answered more envelopes than were sent");
    out
}

#[tokio::test]
async fn a_stream_that_asks_gets_every_envelope_answered_in_fewer_acks() {
    let server = start(test_config()).await;
    let envs = envelopes("runs-a", 400);
    let n = envs.len();
    let late_seq = envs
        .iter()
        .position(|e| matches!(&e.payload, Some(pb::sensor_envelope::Payload::Imu(b)) if b.samples[0].t_ns < T0_NS))
        .unwrap() as u64;
    let got = acks(&server, envs, true).await;
    assert!(
        got.len() < n / 2,
        "{} acks for {n} envelopes: no runs formed",
        got.len()
    );
    // Each ack answers the envelopes up to its own sequence: the covers add up to it.
    let mut answered = 0u64;
    for a in &got {
        answered += u64::from(a.covers.max(1));
        assert_eq!(
            a.sequence + 1,
            answered,
            "ack {a:?} out of step with the envelopes it answers"
        );
        assert_eq!(a.vehicle_id, "runs-a");
        let status = pb::IngestStatus::try_from(a.status).unwrap();
        if a.sequence == late_seq || a.sequence == 0 {
            assert_eq!(
                a.covers, 1,
                "a refusal and a configuration are answered alone: {a:?}"
            );
        }
        if a.covers > 1 {
            assert_eq!(status, pb::IngestStatus::Accepted);
            assert!(a.reason.is_empty() && !a.needs_config);
        }
    }
    let late = got
        .iter()
        .find(|a| a.sequence == late_seq)
        .expect("the refusal's own ack");
    assert_eq!(
        pb::IngestStatus::try_from(late.status).unwrap(),
        pb::IngestStatus::Late
    );
    assert!(!late.reason.is_empty());
    server.shutdown().await.unwrap();
}

#[tokio::test]
async fn a_stream_that_does_not_ask_gets_one_ack_per_envelope() {
    let server = start(test_config()).await;
    let envs = envelopes("runs-b", 100);
    let n = envs.len();
    let got = acks(&server, envs, false).await;
    assert_eq!(got.len(), n);
    for (i, a) in got.iter().enumerate() {
        assert_eq!(a.sequence, i as u64);
        assert_eq!(a.covers, 0, "covers is left unset without the header");
    }
    server.shutdown().await.unwrap();
}
