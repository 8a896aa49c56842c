//! A flood of new vehicle ids overran the lifecycle events the Zenoh liveliness task follows
//! (a broadcast of 4,096): the events saying evicted vehicles were gone were lost, and their
//! liveliness tokens stayed declared for ever (about 4.5 kB of service memory each, and a
//! ground station saw vehicles alive that were not). The task now reconciles its tokens with the
//! live vehicles when it falls behind.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::Duration;

use crate::common::*;
use uavnav_proto::keys;

/// Vehicle liveliness tokens a Zenoh peer sees now.
async fn alive_tokens(z: &zenoh::Session) -> usize {
    // A callback, not a bounded channel: thousands of replies must not block the query.
    let n = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let count = std::sync::Arc::clone(&n);
    z.liveliness()
        .get(keys::alive_key("*"))
        .callback(move |r| {
            if r.result().is_ok() {
                count.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
        })
        .timeout(Duration::from_secs(1))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(1200)).await;
    n.load(std::sync::atomic::Ordering::Relaxed)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn evicted_vehicles_leave_no_token_after_a_flood() {
    let mut cfg = test_config();
    let endpoint = listen_zenoh(&mut cfg);
    cfg.vehicles.idle_evict_s = 0.5;
    let server = start(cfg).await;
    let z = zenoh_peer(&endpoint).await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let n = 6000;
    let mut c = client(&server).await;
    let envs = (0..n)
        .map(|i| imu_env(&format!("fl-{i}"), i as u64, vec![imu(1_000_000_000)]))
        .collect();
    ingest(&mut c, envs).await.unwrap();
    assert!(
        eventually(Duration::from_secs(30), || server
            .registry()
            .ctx()
            .metrics
            .vehicles
            .get()
            == 0)
        .await,
        "the flood's vehicles were not evicted"
    );
    // One more vehicle, kept alive by its stream: its token, and no other.
    let feeder = {
        let mut c = client(&server).await;
        tokio::spawn(async move {
            for k in 0..200i64 {
                let t = 1_000_000_000 + k * 100_000_000;
                let _ = ingest(&mut c, vec![imu_env("after", k as u64, vec![imu(t)])]).await;
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        })
    };
    let mut seen = usize::MAX;
    for _ in 0..20 {
        seen = alive_tokens(&z).await;
        if seen == 1 {
            break;
        }
    }
    assert_eq!(
        seen, 1,
        "tokens of evicted vehicles are still declared, or none for the live one"
    );
    feeder.abort();
    server.shutdown().await.unwrap();
}
