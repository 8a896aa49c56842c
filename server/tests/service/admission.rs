//! Issue 19 row 2, admission under a flood of junk ids: with `max_vehicles` filled by vehicles
//! nobody configured, a real vehicle still gets in (the least recently active idle unconfigured
//! vehicle is displaced, counted), while configured vehicles and streaming ones are never
//! displaced.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::Duration;

use crate::common::*;
use uavnav_proto::v1 as pb;

fn status(a: &pb::IngestAck) -> pb::IngestStatus {
    pb::IngestStatus::try_from(a.status).unwrap()
}

#[tokio::test]
async fn junk_ids_cannot_lock_a_real_vehicle_out() {
    let mut cfg = test_config();
    cfg.vehicles.max_vehicles = 8;
    let server = start(cfg).await;
    let mut c = client(&server).await;
    // The flood: 8 junk ids, one IMU sample each, never configured.
    let junk: Vec<pb::SensorEnvelope> = (0..8)
        .map(|k| imu_env(&format!("junk-{k}"), k, vec![imu(1_000_000_000)]))
        .collect();
    let acks = ingest(&mut c, junk).await.unwrap();
    assert!(
        acks.iter().all(|a| status(a) == pb::IngestStatus::Accepted),
        "{acks:?}"
    );
    assert_eq!(server.registry().len(), 8);
    // Right away, a new vehicle is refused: the junk is not yet idle (it may be a real stream).
    let early = ingest(
        &mut c,
        vec![imu_env("drone-1", 100, vec![imu(1_000_000_000)])],
    )
    .await
    .unwrap();
    assert_eq!(
        status(&early[0]),
        pb::IngestStatus::ResourceExhausted,
        "{early:?}"
    );
    // Once the junk is silent, a real drone configures and gets in; a junk vehicle made room.
    tokio::time::sleep(Duration::from_millis(1_100)).await;
    let created = c
        .configure_vehicle(pb::ConfigureVehicleRequest {
            vehicle_id: "drone-1".into(),
            config: Some(vehicle_config(false)),
        })
        .await
        .unwrap();
    assert!(created.get_ref().created);
    let fed = ingest(
        &mut c,
        vec![imu_env("drone-1", 101, vec![imu(1_000_000_000)])],
    )
    .await
    .unwrap();
    assert_eq!(status(&fed[0]), pb::IngestStatus::Accepted);
    assert_eq!(server.registry().len(), 8);
    assert_eq!(server.metrics().admission_evictions.get(), 1);
    let junk_left = server.registry().list("junk-").len();
    assert_eq!(junk_left, 7);

    // Fill the rest with configured vehicles: they are never displaced, so the next is refused.
    tokio::time::sleep(Duration::from_millis(1_100)).await;
    for k in 0..7 {
        c.configure_vehicle(pb::ConfigureVehicleRequest {
            vehicle_id: format!("drone-{}", k + 2),
            config: Some(vehicle_config(false)),
        })
        .await
        .unwrap();
    }
    assert_eq!(
        server.registry().list("junk-").len(),
        0,
        "every junk vehicle made room"
    );
    assert_eq!(server.registry().list("drone-").len(), 8);
    tokio::time::sleep(Duration::from_millis(1_100)).await;
    let e = c
        .configure_vehicle(pb::ConfigureVehicleRequest {
            vehicle_id: "drone-9".into(),
            config: Some(vehicle_config(false)),
        })
        .await
        .unwrap_err();
    assert_eq!(e.code(), tonic::Code::ResourceExhausted, "{e:?}");
    assert_eq!(server.metrics().admission_evictions.get(), 8);
    server.shutdown().await.unwrap();
}
