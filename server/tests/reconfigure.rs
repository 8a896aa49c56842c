//! Configuring a vehicle with the configuration it already runs with changes nothing (a client
//! re-sends its configurations when its stream reopens after a network break, and that must not
//! restart the vehicle's estimator); a different one replaces the engine.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

mod common;

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use common::*;
use uavnav_core::VehicleConfig;
use uavnav_proto::v1 as pb;
use uavnavd::Server;
use uavnavd::engine::{Engine, EngineFactory};

/// Echo engines, counting how many were made.
#[derive(Debug, Default)]
struct Counting(AtomicUsize);

impl EngineFactory for Counting {
    fn create(&self, _config: &VehicleConfig) -> Box<dyn Engine> {
        self.0.fetch_add(1, Ordering::Relaxed);
        Box::new(EchoEngine::default())
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
