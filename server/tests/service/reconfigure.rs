//! Configuring a vehicle with the configuration it already runs with changes nothing (a client
//! re-sends its configurations when its stream reopens after a network break, and that must not
//! restart the vehicle's estimator); a different one replaces the engine.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::common::*;
use uavnav_core::VehicleConfig;
use uavnav_proto::v1 as pb;
use uavnavd::Server;
use uavnavd::engine::{BoxedEngine, EngineFactory, boxed};

/// Echo engines, counting how many were made.
#[derive(Debug, Default)]
struct Counting(AtomicUsize);

impl EngineFactory for Counting {
    fn create(&self, _config: &VehicleConfig) -> BoxedEngine {
        self.0.fetch_add(1, Ordering::Relaxed);
        boxed(EchoEngine::default())
    }
}

#[tokio::test]
async fn the_same_configuration_again_keeps_the_engine() {
    let factory = Arc::new(Counting::default());
    let server = Server::start_with(test_config(), factory.clone())
        .await
        .unwrap();
    let mut c = client(&server).await;
    let configure = |config: pb::VehicleConfig| pb::ConfigureVehicleRequest {
        vehicle_id: "same".into(),
        config: Some(config),
    };
    let first = vehicle_config(false);
    let created = c.configure_vehicle(configure(first)).await.unwrap();
    assert!(created.into_inner().created);
    assert_eq!(factory.0.load(Ordering::Relaxed), 1);
    let again = c.configure_vehicle(configure(first)).await.unwrap();
    assert!(!again.into_inner().created);
    assert_eq!(
        factory.0.load(Ordering::Relaxed),
        1,
        "the engine was rebuilt"
    );
    // A different configuration is applied.
    let mut other = first;
    other.gnss.as_mut().unwrap().lever_arm_body_m = Some(pb::Vector3 {
        x: 0.1,
        y: 0.0,
        z: 0.0,
    });
    c.configure_vehicle(configure(other)).await.unwrap();
    assert_eq!(factory.0.load(Ordering::Relaxed), 2);
    server.shutdown().await.unwrap();
}

/// Acks of sensor data say whether the vehicle runs without a client's configuration
/// (`needs_config`), so that a client whose vehicle the service forgot can configure it again.
#[tokio::test]
async fn acks_say_when_a_vehicle_has_no_configuration() {
    let server = start(test_config()).await;
    let mut c = client(&server).await;
    let acks = ingest(&mut c, vec![imu_env("bare", 1, vec![imu(1_000_000_000)])])
        .await
        .unwrap();
    assert_eq!(acks[0].status, pb::IngestStatus::Accepted as i32);
    assert!(acks[0].needs_config, "{:?}", acks[0]);
    let config = pb::SensorEnvelope {
        vehicle_id: "bare".into(),
        sequence: 2,
        payload: Some(pb::sensor_envelope::Payload::Config(vehicle_config(false))),
    };
    let acks = ingest(
        &mut c,
        vec![config, imu_env("bare", 3, vec![imu(1_100_000_000)])],
    )
    .await
    .unwrap();
    assert!(
        acks.iter()
            .all(|a| a.status == pb::IngestStatus::Accepted as i32)
    );
    assert!(acks.iter().all(|a| !a.needs_config), "{acks:?}");
    // A refusal says nothing about the configuration.
    let acks = ingest(&mut c, vec![imu_env("bare", 4, vec![imu(500_000_000)])])
        .await
        .unwrap();
    assert_ne!(acks[0].status, pb::IngestStatus::Accepted as i32);
    assert!(!acks[0].needs_config);
    server.shutdown().await.unwrap();
}
