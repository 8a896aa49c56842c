//! Zenoh round trip: a vehicle fed over Zenoh (config, IMU, GNSS on its keys) is watched over
//! Zenoh (pose, health, `pose/latest`, `vehicles`, liveliness) and over gRPC; bad payloads are
//! counted. Sessions use explicit loopback endpoints and no multicast scouting, so parallel tests
//! never see each other.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::Duration;

use crate::common::*;
use prost::Message;
use uavnav_proto::keys::{self, Leaf};
use uavnav_proto::v1 as pb;
use zenoh::Wait;

fn enc(name: &str) -> zenoh::bytes::Encoding {
    uavnavd::zenoh_io::encoding(name)
}

/// Zenoh puts have no ack, so a Zenoh client learns from the health reports that a vehicle it
/// feeds runs without its configuration (a restarted service, an idle eviction): `configured`
/// is false until the configuration is put again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn health_says_when_a_vehicle_lost_its_configuration() {
    let mut cfg = test_config();
    let endpoint = listen_zenoh(&mut cfg);
    let server = start(cfg).await;
    let z = zenoh_peer(&endpoint).await;
    let health = z
        .declare_subscriber(keys::vehicle_key("forgot", Leaf::Health))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(500)).await;
    let key = |leaf: Leaf| keys::vehicle_key("forgot", leaf);
    let put_imu = |t: i64| {
        let batch = pb::ImuBatch {
            samples: vec![imu(t)],
        };
        z.put(key(Leaf::Imu), batch.encode_to_vec())
            .encoding(enc("uavnav.v1.ImuBatch"))
    };
    put_imu(1_000_000_000).await.unwrap();
    let next = || async {
        let s = tokio::time::timeout(Duration::from_secs(5), health.recv_async())
            .await
            .expect("health over zenoh")
            .unwrap();
        pb::VehicleHealth::decode(&*s.payload().to_bytes()).unwrap()
    };
    let h = next().await;
    assert!(!h.configured, "created from data alone: {h:?}");
    z.put(key(Leaf::Config), vehicle_config(false).encode_to_vec())
        .encoding(enc("uavnav.v1.VehicleConfig"))
        .await
        .unwrap();
    put_imu(1_005_000_000).await.unwrap();
    let mut configured = false;
    for _ in 0..20 {
        if next().await.configured {
            configured = true;
            break;
        }
    }
    assert!(configured, "the health never said configured");
    server.shutdown().await.unwrap();
}

/// The `unconfigured` key carries a vehicle's health reports while it runs without its
/// configuration, and nothing once it has one: a sender's keeper subscribes there, so the service
/// publishes nothing for the configured vehicles it feeds.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unconfigured_reports_come_only_while_a_vehicle_lacks_its_configuration() {
    let mut cfg = test_config();
    let endpoint = listen_zenoh(&mut cfg);
    let server = start(cfg).await;
    let z = zenoh_peer(&endpoint).await;
    let key = |leaf: Leaf| keys::vehicle_key("lost", leaf);
    let reports = z.declare_subscriber(key(Leaf::Unconfigured)).await.unwrap();
    tokio::time::sleep(Duration::from_millis(500)).await;
    let put_imu = |t: i64| {
        let batch = pb::ImuBatch {
            samples: vec![imu(t)],
        };
        z.put(key(Leaf::Imu), batch.encode_to_vec())
            .encoding(enc("uavnav.v1.ImuBatch"))
    };
    put_imu(1_000_000_000).await.unwrap();
    let s = tokio::time::timeout(Duration::from_secs(5), reports.recv_async())
        .await
        .expect("an unconfigured report over zenoh")
        .unwrap();
    let h = pb::VehicleHealth::decode(&*s.payload().to_bytes()).unwrap();
    assert_eq!((h.vehicle_id.as_str(), h.configured), ("lost", false));
    z.put(key(Leaf::Config), vehicle_config(false).encode_to_vec())
        .encoding(enc("uavnav.v1.VehicleConfig"))
        .await
        .unwrap();
    // Reports already on their way may still come; then none, over ten health periods.
    tokio::time::sleep(Duration::from_millis(500)).await;
    while reports.try_recv().ok().flatten().is_some() {}
    for k in 1..=10 {
        put_imu(1_000_000_000 + k * 5_000_000).await.unwrap();
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(
        reports.try_recv().ok().flatten().is_none(),
        "a configured vehicle's report on the unconfigured key"
    );
    server.shutdown().await.unwrap();
}

/// A quiet vehicle's repeated health reports (nothing but the clocks changed) go out on Zenoh
/// only within `zenoh.repeat_health_per_s`: with a budget of 0 a watcher gets every report with
/// news and no repeat, and each repeat held back is counted; with a budget it gets them.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_quiet_vehicles_repeats_go_out_only_within_the_budget() {
    use uavnavd::health::repeats;
    for budget in [0.0, 1000.0] {
        let mut cfg = test_config();
        // A quiet vehicle reports once in ten periods: every 200 ms.
        cfg.health.period_ms = 20;
        cfg.zenoh.repeat_health_per_s = budget;
        let endpoint = listen_zenoh(&mut cfg);
        let server = start(cfg).await;
        let z = zenoh_peer(&endpoint).await;
        let key = |leaf: Leaf| keys::vehicle_key("quiet", leaf);
        let health = z.declare_subscriber(key(Leaf::Health)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(500)).await;
        let batch = pb::ImuBatch {
            samples: vec![imu(1_000_000_000)],
        };
        z.put(key(Leaf::Imu), batch.encode_to_vec())
            .encoding(enc("uavnav.v1.ImuBatch"))
            .await
            .unwrap();
        tokio::time::sleep(Duration::from_millis(2000)).await;
        let mut got = Vec::new();
        while let Ok(Some(s)) = health.try_recv() {
            got.push(pb::VehicleHealth::decode(&*s.payload().to_bytes()).unwrap());
        }
        let repeated = got.windows(2).filter(|w| repeats(&w[0], &w[1])).count();
        let skipped = server.metrics().zenoh_health_repeats_skipped.get();
        assert!(!got.is_empty(), "budget {budget}: no report at all");
        if budget == 0.0 {
            assert_eq!(repeated, 0, "budget 0 published repeats: {got:?}");
            assert!(skipped >= 4, "budget 0: {skipped} repeats counted");
        } else {
            assert!(
                repeated >= 4,
                "budget {budget}: {repeated} repeats in {got:?}"
            );
            assert_eq!(skipped, 0);
        }
        z.close().await.unwrap();
        server.shutdown().await.unwrap();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn zenoh_round_trip() {
    let mut cfg = test_config();
    let endpoint = listen_zenoh(&mut cfg);
    let instance = cfg.zenoh.instance.clone();
    let server = start(cfg).await;
    let z = zenoh_peer(&endpoint).await;
    let poses = z
        .declare_subscriber(keys::vehicle_key("zv", Leaf::Pose))
        .await
        .unwrap();
    let health = z
        .declare_subscriber(keys::vehicle_key("zv", Leaf::Health))
        .await
        .unwrap();
    // Let the subscriptions propagate to the service.
    tokio::time::sleep(Duration::from_millis(500)).await;
    let alive = z
        .liveliness()
        .get(keys::service_key(&instance))
        .await
        .unwrap();
    assert!(
        tokio::time::timeout(Duration::from_secs(3), alive.recv_async())
            .await
            .unwrap()
            .is_ok(),
        "service token"
    );

    let key = |leaf: Leaf| keys::vehicle_key("zv", leaf);
    z.put(key(Leaf::Config), vehicle_config(false).encode_to_vec())
        .encoding(enc("uavnav.v1.VehicleConfig"))
        .await
        .unwrap();
    z.put(key(Leaf::Gnss), fix(1_000).encode_to_vec())
        .encoding(enc("uavnav.v1.GnssFix"))
        .await
        .unwrap();
    let n = 20;
    for k in 0..n {
        let batch = pb::ImuBatch {
            samples: vec![imu(2_000 + k * 5_000_000)],
        };
        z.put(key(Leaf::Imu), batch.encode_to_vec())
            .encoding(enc("uavnav.v1.ImuBatch"))
            .await
            .unwrap();
    }
    // Garbage on an input key is counted, not fatal.
    z.put(key(Leaf::Imu), vec![0x0A, 0xFF, 0x01])
        .wait()
        .unwrap();

    let mut got = Vec::new();
    while got.len() < n as usize {
        let s = tokio::time::timeout(Duration::from_secs(5), poses.recv_async())
            .await
            .expect("pose over zenoh")
            .unwrap();
        assert_eq!(s.encoding(), &enc("uavnav.v1.PoseEstimate"));
        let p = pb::PoseEstimate::decode(&*s.payload().to_bytes()).unwrap();
        assert_eq!(p.vehicle_id, "zv");
        got.push(p.t_ns);
    }
    assert_eq!(
        got,
        (0..n).map(|k| 2_000 + k * 5_000_000).collect::<Vec<_>>()
    );

    let h = tokio::time::timeout(Duration::from_secs(3), health.recv_async())
        .await
        .unwrap()
        .unwrap();
    assert_eq!(h.encoding(), &enc("uavnav.v1.VehicleHealth"));
    let h = pb::VehicleHealth::decode(&*h.payload().to_bytes()).unwrap();
    assert_eq!(h.vehicle_id, "zv");
    assert!(h.configured, "configured over Zenoh: {h:?}");

    // The malformed put shows up in the vehicle's health and the metrics.
    let reg = server.registry().clone();
    assert!(
        eventually(Duration::from_secs(3), || {
            reg.get("zv")
                .and_then(|v| v.shared.health())
                .and_then(|h| h.counters)
                .is_some_and(|c| c.rejected == 1)
        })
        .await
    );
    assert!(
        server
            .metrics()
            .encode()
            .contains("transport=\"zenoh\",kind=\"imu\",outcome=\"invalid\"")
    );
    // A put on a key that names no input is counted, not ignored (issue 19 row 8).
    z.put("uavnav/v1/vehicle/zv/speed", vec![1u8, 2, 3])
        .await
        .unwrap();
    let m = server.metrics().clone();
    assert!(
        eventually(Duration::from_secs(3), || {
            m.encode()
                .contains("transport=\"zenoh\",kind=\"malformed\",reason=\"unknown_key\"} 1")
        })
        .await,
        "unknown key counted"
    );

    // Queryables.
    let replies = z.get(keys::pose_latest_key("zv")).await.unwrap();
    let r = tokio::time::timeout(Duration::from_secs(3), replies.recv_async())
        .await
        .unwrap()
        .unwrap();
    let s = r.result().unwrap();
    assert_eq!(s.encoding(), &enc("uavnav.v1.PoseEstimate"));
    assert_eq!(
        pb::PoseEstimate::decode(&*s.payload().to_bytes())
            .unwrap()
            .t_ns,
        2_000 + (n - 1) * 5_000_000
    );
    let replies = z.get(keys::VEHICLES).await.unwrap();
    let r = tokio::time::timeout(Duration::from_secs(3), replies.recv_async())
        .await
        .unwrap()
        .unwrap();
    let list =
        pb::ListVehiclesResponse::decode(&*r.result().unwrap().payload().to_bytes()).unwrap();
    assert_eq!(
        list.vehicles
            .iter()
            .map(|v| v.vehicle_id.as_str())
            .collect::<Vec<_>>(),
        ["zv"]
    );
    let alive = z.liveliness().get(keys::alive_key("zv")).await.unwrap();
    assert!(
        tokio::time::timeout(Duration::from_secs(3), alive.recv_async())
            .await
            .unwrap()
            .is_ok(),
        "vehicle token"
    );

    // The same vehicle is visible over gRPC.
    let mut c = client(&server).await;
    let p = c
        .get_pose(pb::GetPoseRequest {
            vehicle_id: "zv".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(p.t_ns, 2_000 + (n - 1) * 5_000_000);

    z.close().await.unwrap();
    server.shutdown().await.unwrap();
}

/// Poses cost nothing on Zenoh while nobody subscribes (issue 19: an unwatched fleet's output
/// is not encoded or routed), and every pose of every vehicle goes out, counted, once someone
/// does.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn poses_are_put_only_while_someone_watches() {
    let mut cfg = test_config();
    let endpoint = listen_zenoh(&mut cfg);
    let server = start(cfg).await;
    let z = zenoh_peer(&endpoint).await;
    let n = 20;
    let feed = |id: &'static str, first: i64| {
        let z = z.clone();
        async move {
            let key = |leaf: Leaf| keys::vehicle_key(id, leaf);
            z.put(key(Leaf::Config), vehicle_config(false).encode_to_vec())
                .encoding(enc("uavnav.v1.VehicleConfig"))
                .await
                .unwrap();
            z.put(key(Leaf::Gnss), fix(first - 1_000).encode_to_vec())
                .encoding(enc("uavnav.v1.GnssFix"))
                .await
                .unwrap();
            for k in 0..n {
                let batch = pb::ImuBatch {
                    samples: vec![imu(first + k * 5_000_000)],
                };
                z.put(key(Leaf::Imu), batch.encode_to_vec())
                    .encoding(enc("uavnav.v1.ImuBatch"))
                    .await
                    .unwrap();
            }
        }
    };
    let last_t = |first: i64| first + (n - 1) * 5_000_000;
    feed("first", 2_000).await;
    feed("second", 2_000).await;
    let reg = server.registry().clone();
    let done = |id: &'static str, t: i64| {
        let reg = reg.clone();
        move || {
            reg.get(id)
                .and_then(|v| v.shared.pose())
                .is_some_and(|p| p.t_ns == t)
        }
    };
    assert!(eventually(Duration::from_secs(5), done("first", last_t(2_000))).await);
    assert!(eventually(Duration::from_secs(5), done("second", last_t(2_000))).await);
    let published = || server.metrics().zenoh_poses_published.get();
    // Give a stray put the time to show.
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(published(), 0, "nobody watched: nothing was put");

    let all = z
        .declare_subscriber(keys::vehicle_key("*", Leaf::Pose))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(500)).await;
    feed("first", 100_002_000).await;
    feed("second", 100_002_000).await;
    let mut by_vehicle = std::collections::BTreeMap::<String, i64>::new();
    while by_vehicle.values().sum::<i64>() < 2 * n {
        let s = tokio::time::timeout(Duration::from_secs(5), all.recv_async())
            .await
            .expect("every vehicle's poses on the fleet-wide key")
            .unwrap();
        let p = pb::PoseEstimate::decode(&*s.payload().to_bytes()).unwrap();
        *by_vehicle.entry(p.vehicle_id).or_default() += 1;
    }
    assert_eq!(
        by_vehicle.into_iter().collect::<Vec<_>>(),
        [("first".to_string(), n), ("second".to_string(), n)]
    );
    assert_eq!(published(), 2 * n as u64);
    z.close().await.unwrap();
    server.shutdown().await.unwrap();
}
