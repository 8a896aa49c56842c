//! A flood of new vehicle ids overran the lifecycle events the Zenoh liveliness task follows
//! (a broadcast of 4,096): the events saying evicted vehicles were gone were lost, and their
//! liveliness tokens stayed declared for ever (about 4.5 kB of service memory each, and a
//! ground station saw vehicles alive that were not). The task now reconciles its tokens with the
//! live vehicles when it falls behind.
//!
//! And a vehicle is announced only once it is configured or has a pose: a flood of ids that
//! merely sent data declares no token at all (issue 19, row 1).
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::Duration;

use crate::common::*;
use uavnav_proto::keys;

/// Vehicle liveliness tokens a Zenoh peer sees now.
async fn alive_tokens(z: &zenoh::Session) -> usize {
    alive_ids(z).await.len()
}

/// The ids of the vehicles whose liveliness tokens a Zenoh peer sees now.
async fn alive_ids(z: &zenoh::Session) -> std::collections::BTreeSet<String> {
    // A callback, not a bounded channel: thousands of replies must not block the query.
    let ids = std::sync::Arc::new(std::sync::Mutex::new(std::collections::BTreeSet::new()));
    let seen = std::sync::Arc::clone(&ids);
    z.liveliness()
        .get(keys::alive_key("*"))
        .callback(move |r| {
            if let Ok(s) = r.result() {
                let id = s
                    .key_expr()
                    .as_str()
                    .rsplit('/')
                    .next()
                    .unwrap_or("")
                    .to_string();
                seen.lock().unwrap().insert(id);
            }
        })
        .timeout(Duration::from_secs(1))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(1200)).await;
    let mut out = std::collections::BTreeSet::new();
    std::mem::swap(&mut out, &mut ids.lock().unwrap());
    out
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
    // Configured vehicles, so that each is announced and the task has tokens to undeclare.
    let envs = (0..n)
        .flat_map(|i| {
            let id = format!("fl-{i}");
            [
                config_env(&id, 2 * i as u64, false),
                imu_env(&id, 2 * i as u64 + 1, vec![imu(1_000_000_000)]),
            ]
        })
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
    // One more vehicle, configured and kept alive by its stream: its token, and no other.
    let feeder = {
        let mut c = client(&server).await;
        tokio::spawn(async move {
            let _ = ingest(&mut c, vec![config_env("after", 0, false)]).await;
            for k in 1..200i64 {
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

/// Ids that only sent data are not announced: no token for any of a flood of them, while a
/// vehicle among them that is configured gets its token, and one fed a flight without a
/// configuration gets its own once it has poses. The product engine: an IMU sample alone gives
/// it no pose (the tests' echo engine makes one of every sample).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn only_configured_or_estimated_vehicles_are_announced() {
    let mut cfg = test_config();
    let endpoint = listen_zenoh(&mut cfg);
    let server = uavnavd::Server::start(cfg).await.unwrap();
    let z = zenoh_peer(&endpoint).await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let mut c = client(&server).await;
    let mut envs: Vec<_> = (0..500)
        .map(|i| imu_env(&format!("junk-{i}"), i as u64, vec![imu(1_000_000_000)]))
        .collect();
    envs.push(config_env("configured", 1000, false));
    // Data only, IMU and GNSS of a simulated flight: the defaults estimate it.
    let (_, events) = sim_flight("smoke", 2.0);
    envs.extend(imu_gnss_envs("estimated", 2000, &events));
    ingest(&mut c, envs).await.unwrap();
    let reg = server.registry().clone();
    assert!(
        eventually(Duration::from_secs(5), || reg
            .get("estimated")
            .is_some_and(|h| h.shared.pose().is_some()))
        .await,
        "the data-only vehicle fed a flight has poses"
    );
    assert_eq!(server.registry().list("junk-").len(), 500);
    assert!(
        reg.list("junk-").iter().all(|h| h.shared.pose().is_none()),
        "an IMU sample alone gives no pose"
    );
    let want: std::collections::BTreeSet<String> =
        ["configured", "estimated"].map(String::from).into();
    let mut seen = Default::default();
    for _ in 0..10 {
        seen = alive_ids(&z).await;
        if seen == want {
            break;
        }
    }
    assert_eq!(
        seen.iter().take(10).collect::<Vec<_>>(),
        want.iter().collect::<Vec<_>>(),
        "tokens ({} in all): the configured and the estimated vehicle only",
        seen.len()
    );
    server.shutdown().await.unwrap();
}
