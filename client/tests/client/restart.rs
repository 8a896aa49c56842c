//! A service restarted under a feeding client (issue row 10: the client reconnected and resent
//! its data but not the vehicle's configuration, so camera frames were refused and poses lost):
//! the reopened ingest stream re-sends the configurations first, and the new service runs the
//! vehicle with them.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::sync::atomic::Ordering;
use std::time::Duration;

use crate::common::*;
use uavnav_client::{Client, ConnectOptions};
use uavnav_tests::net::eventually;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_reopened_stream_resends_the_vehicle_configurations() {
    let port = free_port();
    let mut cfg = loopback_config();
    cfg.grpc.addr = std::net::SocketAddr::from(([127, 0, 0, 1], port));
    let first = uavnavd::Server::start(cfg.clone()).await.unwrap();
    let url = format!("grpc://127.0.0.1:{port}");
    let client = Client::connect(&url.parse().unwrap(), ConnectOptions::default())
        .await
        .unwrap();
    let (config, msgs) = flight(4.0);
    // One vehicle configured by the unary call, one inside the stream.
    client.configure("rs-unary", &config).await.unwrap();
    let ingest = client.ingest().await.unwrap();
    ingest
        .send(
            "rs-stream",
            uavnav_client::pb::sensor_envelope::Payload::Config(config),
        )
        .await
        .unwrap();
    let half = msgs.len() / 2;
    for m in &msgs[..half] {
        ingest.send("rs-unary", m.clone()).await.unwrap();
        ingest.send("rs-stream", m.clone()).await.unwrap();
    }
    let stats = std::sync::Arc::clone(ingest.stats());
    let all = 1 + 2 * half as u64;
    assert!(
        eventually(Duration::from_secs(20), || stats
            .acked
            .load(Ordering::Relaxed)
            == all)
        .await
    );
    assert_eq!(stats.configs_resent.load(Ordering::Relaxed), 0);

    // The service restarts (a new process would be the same: nothing of the vehicles survives).
    first.shutdown().await.unwrap();
    let second = uavnavd::Server::start(cfg).await.unwrap();
    assert!(second.registry().get("rs-unary").is_none());
    for m in &msgs[half..] {
        ingest.send("rs-unary", m.clone()).await.unwrap();
        ingest.send("rs-stream", m.clone()).await.unwrap();
    }
    let stats = ingest.finish(Duration::from_secs(30)).await;
    assert!(stats.reconnects.load(Ordering::Relaxed) >= 1);
    assert_eq!(stats.configs_resent.load(Ordering::Relaxed), 2);
    assert!(
        stats.errors().keys().all(|e| !e.contains("re-sent")),
        "{:?}",
        stats.errors()
    );
    for id in ["rs-unary", "rs-stream"] {
        let h = second.registry().get(id).unwrap();
        assert!(
            h.shared.configured.load(Ordering::Relaxed),
            "{id}: created by data, without its configuration"
        );
        let running = h.shared.config.lock().unwrap().clone().unwrap();
        let given = uavnav_core::VehicleConfig::try_from(&config).unwrap();
        assert_eq!(*running, given, "{id}");
    }
    second.shutdown().await.unwrap();
}

/// A vehicle the service forgot while the client's stream stayed open (evicted after
/// `idle_evict_s` of silence): the next acks say `needs_config`, and the client re-sends the
/// configuration it gave, once, in the same stream.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_forgotten_vehicle_is_configured_again() {
    let mut cfg = loopback_config();
    cfg.vehicles.idle_evict_s = 0.5;
    let server = uavnavd::Server::start(cfg).await.unwrap();
    let url = format!("grpc://{}", server.grpc_addr);
    let client = Client::connect(&url.parse().unwrap(), ConnectOptions::default())
        .await
        .unwrap();
    let (config, msgs) = flight(4.0);
    let ingest = client.ingest().await.unwrap();
    ingest
        .send(
            "evicted",
            uavnav_client::pb::sensor_envelope::Payload::Config(config),
        )
        .await
        .unwrap();
    let half = msgs.len() / 2;
    for m in &msgs[..half] {
        ingest.send("evicted", m.clone()).await.unwrap();
    }
    let stats = std::sync::Arc::clone(ingest.stats());
    assert!(
        eventually(Duration::from_secs(20), || stats
            .acked
            .load(Ordering::Relaxed)
            == 1 + half as u64)
        .await
    );
    // Silence: the service evicts the vehicle, configuration and all.
    assert!(
        eventually(Duration::from_secs(10), || server
            .registry()
            .get("evicted")
            .is_none())
        .await,
        "the vehicle was not evicted"
    );
    // The drone streams on: the acks of its next messages say the service lost its
    // configuration, and the client sends it again in the same stream.
    let quarter = half + (msgs.len() - half) / 2;
    for m in &msgs[half..quarter] {
        ingest.send("evicted", m.clone()).await.unwrap();
    }
    assert!(
        eventually(Duration::from_secs(20), || stats
            .configs_resent
            .load(Ordering::Relaxed)
            >= 1)
        .await,
        "no configuration was re-sent"
    );
    for m in &msgs[quarter..] {
        ingest.send("evicted", m.clone()).await.unwrap();
    }
    let stats = ingest.finish(Duration::from_secs(30)).await;
    assert_eq!(stats.reconnects.load(Ordering::Relaxed), 0);
    assert_eq!(stats.configs_resent.load(Ordering::Relaxed), 1);
    let h = server.registry().get("evicted").unwrap();
    assert!(h.shared.configured.load(Ordering::Relaxed));
    let running = h.shared.config.lock().unwrap().clone().unwrap();
    assert_eq!(
        *running,
        uavnav_core::VehicleConfig::try_from(&config).unwrap()
    );
    server.shutdown().await.unwrap();
}

/// Over Zenoh there are no acks: a vehicle the service forgot (evicted after `idle_evict_s` of
/// silence) says so in its health reports (`configured: false`), and the ingest stream's keeper
/// puts the configuration the client gave again.
#[cfg(feature = "zenoh")]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_forgotten_vehicle_is_configured_again_over_zenoh() {
    let mut cfg = loopback_config();
    let endpoint = uavnav_tests::service::listen_zenoh(&mut cfg);
    cfg.vehicles.idle_evict_s = 0.5;
    cfg.health.period_ms = 200;
    let server = uavnavd::Server::start(cfg).await.unwrap();
    let url = format!("zenoh/{endpoint}");
    let client = Client::connect(&url.parse().unwrap(), ConnectOptions::default())
        .await
        .unwrap();
    let (config, msgs) = flight(4.0);
    client.configure("zevicted", &config).await.unwrap();
    let ingest = client.ingest().await.unwrap();
    let half = msgs.len() / 2;
    for m in &msgs[..half] {
        ingest.send("zevicted", m.clone()).await.unwrap();
    }
    let configured = |s: &uavnavd::RunningServer| {
        s.registry()
            .get("zevicted")
            .is_some_and(|h| h.shared.configured.load(Ordering::Relaxed))
    };
    assert!(eventually(Duration::from_secs(10), || configured(&server)).await);
    let stats = std::sync::Arc::clone(ingest.stats());
    assert_eq!(stats.configs_resent.load(Ordering::Relaxed), 0);
    assert!(
        eventually(Duration::from_secs(10), || server
            .registry()
            .get("zevicted")
            .is_none())
        .await,
        "the vehicle was not evicted"
    );
    // The drone streams on: the service creates the vehicle from its data, on its defaults, and
    // its health says so; the keeper puts the configuration again.
    for m in &msgs[half..] {
        ingest.send("zevicted", m.clone()).await.unwrap();
    }
    assert!(
        eventually(Duration::from_secs(20), || stats
            .configs_resent
            .load(Ordering::Relaxed)
            >= 1)
        .await,
        "no configuration was re-put"
    );
    assert!(
        eventually(Duration::from_secs(10), || configured(&server)).await,
        "the vehicle runs without its configuration"
    );
    let h = server.registry().get("zevicted").unwrap();
    let running = h.shared.config.lock().unwrap().clone().unwrap();
    assert_eq!(
        *running,
        uavnav_core::VehicleConfig::try_from(&config).unwrap()
    );
    drop(h);
    drop(ingest);
    client.close().await;
    server.shutdown().await.unwrap();
}
