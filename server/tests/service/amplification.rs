//! Row 4 of issue 19: one 16 MiB `ImuBatch` of 8.4 million empty samples (2 bytes each on the
//! wire, 56 decoded). It used to be decoded in full before the 10,000-sample limit was checked:
//! +713 MB. The sample count is now taken from the wire first (gRPC codec, Zenoh input), so the
//! batch is refused having decoded at most 10,001 samples.
//!
//! Measured by the process's peak resident memory (`VmHWM`, reset through `/proc/self/clear_refs`)
//! while the service handles the message; the same bytes decoded with plain prost in this process
//! give the "before" figure. In its own process (`own_process`), so nothing else allocates
//! meanwhile.

use std::time::Duration;

use crate::common::*;
use prost::Message;
use uavnav_proto::v1 as pb;

/// A field of `/proc/self/status`, kB.
fn status_kb(key: &str) -> u64 {
    let text = std::fs::read_to_string("/proc/self/status").unwrap();
    text.lines()
        .find_map(|l| l.strip_prefix(key))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap()
}

/// Runs `f` and returns its output with the growth of the peak resident memory over the resident
/// memory before it, MB.
async fn peak_growth_mb<T>(f: impl std::future::Future<Output = T>) -> (T, f64) {
    // Resets VmHWM to the current RSS (Linux ≥ 4.0); without it the peak since start counts.
    let _ = std::fs::write("/proc/self/clear_refs", "5");
    let before = status_kb("VmRSS:");
    let out = f.await;
    let peak = status_kb("VmHWM:");
    (out, peak.saturating_sub(before) as f64 / 1024.0)
}

fn varint(mut v: u64, out: &mut Vec<u8>) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// An `ImuBatch` of `n` empty samples, encoded.
fn empty_batch(n: usize) -> Vec<u8> {
    [0x0A, 0x00].repeat(n)
}

/// A `SensorEnvelope` for `id` around `batch` (an encoded `ImuBatch`).
fn envelope(id: &str, batch: &[u8]) -> Vec<u8> {
    let mut e = vec![0x0A, id.len() as u8];
    e.extend(id.as_bytes());
    e.extend([0x10, 0x01, 0x1A]);
    varint(batch.len() as u64, &mut e);
    e.extend(batch);
    e
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_16_mib_batch_of_empty_samples_is_refused_before_it_is_decoded() {
    if crate::own_process::ran_in_own_process(
        "amplification::a_16_mib_batch_of_empty_samples_is_refused_before_it_is_decoded",
    ) {
        return;
    }
    let mut cfg = test_config();
    let endpoint = listen_zenoh(&mut cfg);
    let max = cfg.grpc.max_message_bytes;
    let server = start(cfg).await;

    let n = (max - 64) / 2;
    let batch = empty_batch(n);
    let env = envelope("bomb", &batch);
    assert!(env.len() <= max && env.len() > 16_000_000);

    // Before: what decoding the message costs (what the service did with it).
    let (decoded, plain_mb) = peak_growth_mb(async {
        pb::SensorEnvelope::decode(env.as_slice())
            .map(|e| match e.payload {
                Some(pb::sensor_envelope::Payload::Imu(b)) => b.samples.len(),
                _ => 0,
            })
            .unwrap()
    })
    .await;
    assert_eq!(decoded, n);

    // gRPC: refused in its ack, the stream intact.
    let (ack, grpc_mb) =
        peak_growth_mb(async { raw_first_ack(&server, env.clone()).await.unwrap() }).await;
    assert_eq!(
        ack.status,
        pb::IngestStatus::ResourceExhausted as i32,
        "{ack:?}"
    );
    assert!(ack.reason.contains("more than 10000"), "{ack:?}");

    // Zenoh: the same batch on the vehicle's imu key.
    let z = zenoh_peer(&endpoint).await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let metrics = server.metrics().clone();
    let refused =
        "uavnav_inputs_refused_total{transport=\"zenoh\",kind=\"imu\",reason=\"too_large\"} 1";
    let (seen, zenoh_mb) = peak_growth_mb(async {
        z.put("uavnav/v1/vehicle/bomb/imu", batch.clone())
            .await
            .unwrap();
        eventually(Duration::from_secs(20), || {
            metrics.encode().contains(refused)
        })
        .await
    })
    .await;
    assert!(seen, "{}", metrics.encode());

    eprintln!(
        "16 MiB ImuBatch of {n} empty samples, peak resident memory growth: plain decode {plain_mb:.0} MB, \
         service over gRPC {grpc_mb:.0} MB, over Zenoh {zenoh_mb:.0} MB"
    );
    // The message's own bytes pass through a few buffers (client, HTTP/2, server); decoding adds
    // at most 10,001 samples (0.6 MB).
    assert!(
        plain_mb > 400.0,
        "the plain decode should show the amplification: {plain_mb:.0} MB"
    );
    assert!(grpc_mb < 150.0, "gRPC: {grpc_mb:.0} MB");
    assert!(zenoh_mb < 150.0, "Zenoh: {zenoh_mb:.0} MB");
    z.close().await.unwrap();
    server.shutdown().await.unwrap();
}
