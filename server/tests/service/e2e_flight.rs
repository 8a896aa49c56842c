//! End to end: a simulated flight streamed into the service over gRPC, and over Zenoh, gives
//! exactly the poses of the offline runner (`push_inline`, what `uavnav estimate` does) on the same
//! data: the actor's ordering, the vision pool and the transports change nothing.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use crate::common;

use std::time::Duration;

use crate::common::test_config;
use prost::Message;
use uavnav_core::SensorEvent;
use uavnav_proto::keys::{self, Leaf};
use uavnav_proto::v1 as pb;
use uavnavd::Server;

/// Configures `id` over gRPC and streams `events` to it, one envelope each; every one accepted.
async fn configure_and_feed(
    server: &uavnavd::RunningServer,
    id: &str,
    config: &uavnav_core::VehicleConfig,
    events: &[SensorEvent],
) {
    let mut c = common::client(server).await;
    c.configure_vehicle(pb::ConfigureVehicleRequest {
        vehicle_id: id.into(),
        config: Some(config.into()),
    })
    .await
    .unwrap();
    let envs: Vec<_> = events
        .iter()
        .enumerate()
        .map(|(i, e)| common::event_env(id, i as u64, e))
        .collect();
    let acks = common::ingest(&mut c, envs).await.unwrap();
    assert_eq!(acks.len(), events.len());
    for a in &acks {
        assert_eq!(a.status, pb::IngestStatus::Accepted as i32, "{a:?}");
    }
}

fn strip(mut p: pb::PoseEstimate) -> pb::PoseEstimate {
    p.vehicle_id.clear();
    p.ingest_wall_ns = 0;
    p
}

async fn collect(
    rx: &mut tokio::sync::broadcast::Receiver<std::sync::Arc<uavnavd::hub::PoseBatch>>,
    n: usize,
) -> Vec<pb::PoseEstimate> {
    let mut got = Vec::with_capacity(n);
    let all = async {
        while got.len() < n {
            got.extend(rx.recv().await.unwrap().to_wire().into_iter().map(strip));
        }
    };
    tokio::time::timeout(Duration::from_secs(60), all)
        .await
        .expect("all poses within 60 s");
    got
}

fn assert_same(got: &[pb::PoseEstimate], want: &[pb::PoseEstimate]) {
    assert_eq!(got.len(), want.len());
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert_eq!(g, w, "pose {i} differs");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn grpc_flight_equals_offline_estimate() {
    let (config, events) = common::sim_flight("mag-baro", 4.0);
    let want = common::offline_poses(&config, &events);
    assert!(
        want.len() > 500,
        "the offline run produced {} poses",
        want.len()
    );

    let server = Server::start(test_config()).await.unwrap();
    let mut rx = server.registry().ctx().hub.poses.subscribe();
    configure_and_feed(&server, "e2e", &config, &events).await;
    let got = collect(&mut rx, want.len()).await;
    assert_same(&got, &want);
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn zenoh_flight_equals_offline_estimate() {
    let (config, events) = common::sim_flight("mag-baro", 2.0);
    let want = common::offline_poses(&config, &events);
    let mut cfg = test_config();
    let endpoint = common::listen_zenoh(&mut cfg);
    let server = Server::start(cfg).await.unwrap();
    let mut rx = server.registry().ctx().hub.poses.subscribe();

    let z = common::zenoh_peer(&endpoint).await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let key = |leaf: Leaf| keys::vehicle_key("ze2e", leaf);
    let enc = |leaf: Leaf| uavnavd::zenoh_io::encoding(leaf.message_name());
    let block = zenoh::qos::CongestionControl::Block;
    let cfg_msg = pb::VehicleConfig::from(&config);
    z.put(key(Leaf::Config), cfg_msg.encode_to_vec())
        .encoding(enc(Leaf::Config))
        .congestion_control(block)
        .await
        .unwrap();
    for e in &events {
        let (leaf, body) = match e {
            SensorEvent::Imu(s) => (
                Leaf::Imu,
                pb::ImuBatch {
                    samples: vec![s.into()],
                }
                .encode_to_vec(),
            ),
            SensorEvent::Gnss(f) => (Leaf::Gnss, pb::GnssFix::from(f).encode_to_vec()),
            SensorEvent::Mag(m) => (Leaf::Mag, pb::MagSample::from(m).encode_to_vec()),
            SensorEvent::Baro(b) => (Leaf::Baro, pb::BaroSample::from(b).encode_to_vec()),
            SensorEvent::Camera(f) => (Leaf::Camera, pb::CameraFrame::from(f).encode_to_vec()),
        };
        z.put(key(leaf), body)
            .encoding(enc(leaf))
            .congestion_control(block)
            .await
            .unwrap();
    }
    let got = collect(&mut rx, want.len()).await;
    assert_same(&got, &want);
    z.close().await.unwrap();
    server.shutdown().await.unwrap();
}

/// IMU samples at the sensor's range (a hard landing, a strike) are counted by the estimator and
/// reach the vehicle's health and `/metrics`; the health carries the GNSS velocity delay in use.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clipped_imu_samples_reach_health_and_metrics() {
    let (config, mut events) = common::sim_flight("smoke", 3.0);
    // 20 consecutive samples two seconds in read 200 m/s² (beyond the 15.5 g default range).
    let (mut k, mut n) = (0, 0);
    for e in events.iter_mut() {
        if let SensorEvent::Imu(s) = e {
            k += 1;
            if (400..420).contains(&k) {
                s.accel_mps2.x = 200.0;
                n += 1;
            }
        }
    }
    assert_eq!(n, 20);
    let server = Server::start(test_config()).await.unwrap();
    configure_and_feed(&server, "clip", &config, &events).await;
    let h = server.registry().get("clip").unwrap();
    let clipped = || {
        h.shared
            .latest_health
            .borrow()
            .as_ref()
            .and_then(|r| r.counters)
            .map_or(0, |c| c.imu_clipped)
    };
    assert!(
        common::eventually(Duration::from_secs(10), || clipped() >= 19).await,
        "health says {} clipped",
        clipped()
    );
    assert_eq!(server.metrics().imu_clipped.get(), clipped());
    assert!(
        server
            .metrics()
            .encode()
            .contains("uavnav_imu_clipped_total")
    );
    // The GNSS velocity delay in use rides in the same report: 3 s are too few windows to learn
    // another, so it is the configured one.
    let delay = h
        .shared
        .latest_health
        .borrow()
        .as_ref()
        .and_then(|r| r.gnss_velocity_delay_s);
    let configured_s = config.gnss.map_or(0, |g| g.delay_ns) as f64 * 1e-9;
    assert_eq!(delay, Some(configured_s));
    server.shutdown().await.unwrap();
}

/// A link that drops for 0.8 s (every sensor) in flight: the estimator bridges the gap instead of
/// restarting, and says so in the vehicle's health and in `/metrics`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dropped_link_is_bridged_and_counted() {
    let (config, events) = common::sim_flight("smoke", 6.0);
    let t0 = events.iter().map(|e| e.t_ns()).min().unwrap();
    let hole = (t0 + 4_000_000_000)..(t0 + 4_800_000_000);
    let events: Vec<_> = events
        .into_iter()
        .filter(|e| !hole.contains(&e.t_ns()))
        .collect();
    let server = Server::start(test_config()).await.unwrap();
    configure_and_feed(&server, "gap", &config, &events).await;
    let h = server.registry().get("gap").unwrap();
    let report = || h.shared.latest_health.borrow().clone();
    let bridged = || {
        report()
            .and_then(|r| r.counters)
            .map_or(0, |c| c.imu_gaps_bridged)
    };
    assert!(
        common::eventually(Duration::from_secs(10), || bridged() == 1).await,
        "health says {:?}",
        report()
    );
    assert_eq!(server.metrics().imu_gaps_bridged.get(), 1);
    assert!(
        server
            .metrics()
            .encode()
            .contains("uavnav_imu_gaps_bridged_total 1")
    );
    // Not restarted: no input refused, and the estimator is still navigating.
    let r = report().unwrap();
    assert_eq!(r.counters.unwrap().dropped, 0, "{r:?}");
    assert_eq!(r.mode, pb::EstimatorMode::Nominal as i32, "{r:?}");
    server.shutdown().await.unwrap();
}

/// A vehicle configured without a receiver: the real engine starts it from the IMU alone and
/// its poses carry the attitude only (`eskf::gnssless`, and `paper::gnssless` for a vehicle of
/// the `paper` profile).
#[tokio::test]
async fn a_vehicle_without_gnss_gets_its_attitude_and_no_position() {
    for profile in [pb::FilterProfile::Eskf, pb::FilterProfile::Paper] {
        without_gnss(profile).await;
    }
}

async fn without_gnss(profile: pb::FilterProfile) {
    // The real engine (the kit's echo engine makes no attitude).
    let server = Server::start(test_config()).await.unwrap();
    let mut c = common::client(&server).await;
    let mut poses = c
        .watch_poses(pb::WatchRequest {
            vehicle_ids: vec!["indoor".into()],
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let mut config = uavnav_tests::wire::vehicle_config(false);
    config.gnss = None;
    config.profile = profile as i32;
    let mut envs = vec![pb::SensorEnvelope {
        vehicle_id: "indoor".into(),
        sequence: 0,
        payload: Some(pb::sensor_envelope::Payload::Config(config)),
    }];
    // 1.5 s of a level, still IMU in 50 ms batches: no fix ever.
    let t0 = 1_000_000_000;
    for b in 0..30i64 {
        let samples = (0..10)
            .map(|k| uavnav_tests::wire::imu(t0 + (b * 10 + k) * 5_000_000))
            .collect();
        envs.push(uavnav_tests::wire::imu_env("indoor", 1 + b as u64, samples));
    }
    let acks = common::ingest(&mut c, envs).await.unwrap();
    assert!(
        acks.iter()
            .all(|a| a.status == pb::IngestStatus::Accepted as i32),
        "{acks:?}"
    );
    let p = tokio::time::timeout(Duration::from_secs(5), poses.message())
        .await
        .unwrap()
        .unwrap()
        .unwrap();
    assert_eq!(
        p.mode,
        pb::EstimatorMode::AttitudeOnly as i32,
        "{profile:?} {p:?}"
    );
    assert!(p.position.is_none() && p.vel_ned_mps.is_none() && p.sigma_pos_ned_m.is_none());
    // Level: roll and pitch near zero, with a stated σ.
    assert!(p.roll_rad.abs() < 0.01 && p.pitch_rad.abs() < 0.01, "{p:?}");
    assert!(p.sigma_att_rad.is_some_and(|s| s.x > 0.0 && s.x < 0.2));
    let latest = c
        .get_pose(pb::GetPoseRequest {
            vehicle_id: "indoor".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(latest.mode, pb::EstimatorMode::AttitudeOnly as i32);
    assert!(latest.position.is_none());
    server.shutdown().await.unwrap();
}

/// The heading's health rides in every vehicle health report: on a simulated flight with a
/// compass the heading is the magnetometer's, the compass active and nothing disturbed; with
/// the same compass reading all zeros (a dead sensor, as on a shared real copter) the compass
/// is stopped for the flight and says so, and the heading is not the magnetometer's. The IMU's
/// measured noise against its configuration rides along too.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_heading_source_and_the_compass_state_reach_health() {
    // The simulated multirotor: it hovers first, so the compass aligns the heading (the fixed
    // wings of the other scenarios are declared, and their course aligns it first).
    let (config, events) = common::sim_flight("multirotor", 12.0);
    assert!(config.mag.is_some());
    let dead: Vec<_> = events
        .iter()
        .map(|e| match e {
            SensorEvent::Mag(m) => {
                let mut m = *m;
                m.field_t = nalgebra::Vector3::zeros();
                SensorEvent::Mag(m)
            }
            other => other.clone(),
        })
        .collect();
    let server = Server::start(test_config()).await.unwrap();
    configure_and_feed(&server, "compass", &config, &events).await;
    configure_and_feed(&server, "dead-compass", &config, &dead).await;
    let heading = |id: &str| {
        server
            .registry()
            .get(id)
            .unwrap()
            .shared
            .latest_health
            .borrow()
            .as_ref()
            .and_then(|r| r.heading)
    };
    // The calibration's own fields (its offset, its test ratio) change with every sample; a
    // compass calibrated as well as this one's is never corrected.
    let as_wanted = |h: Option<pb::HeadingStatus>| {
        h.is_some_and(|h| {
            h.source == pb::HeadingSource::Magnetometer as i32
                && h.magnetometer == pb::MagnetometerState::Active as i32
                && h.magnetometer_disturbed == 0
                && h.yaw_resets == 0
                && h.magnetometer_calibration != pb::MagnetometerCalibration::Applied as i32
                && h.magnetometer_calibration != pb::MagnetometerCalibration::Unspecified as i32
                // A compass in the Earth's field: nothing learnt is refused as implausible.
                && h.magnetometer_calibration_restarts == 0
        })
    };
    assert!(
        common::eventually(Duration::from_secs(20), || as_wanted(heading("compass"))).await,
        "health says {:?}",
        heading("compass")
    );
    let stopped = |h: Option<pb::HeadingStatus>| {
        h.is_some_and(|h| {
            h.magnetometer == pb::MagnetometerState::StoppedDead as i32
                && h.source != pb::HeadingSource::Magnetometer as i32
        })
    };
    assert!(
        common::eventually(Duration::from_secs(20), || stopped(heading("dead-compass"))).await,
        "health says {:?}",
        heading("dead-compass")
    );
    // The IMU's measured noise rides along: the simulated IMU is as noisy as its configuration.
    let noise = server
        .registry()
        .get("compass")
        .unwrap()
        .shared
        .latest_health
        .borrow()
        .as_ref()
        .and_then(|r| r.imu_noise);
    let noise = noise.expect("imu_noise in health");
    for r in [noise.gyro_ratio, noise.accel_ratio] {
        assert!((0.5..2.0).contains(&r), "{noise:?}");
    }
    server.shutdown().await.unwrap();
}
