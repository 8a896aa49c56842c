//! Many vehicles at once over gRPC: each gets exactly its own poses; listing, watching with a
//! prefix and decimation, GetPose, configure and reset.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::collections::BTreeMap;
use std::time::Duration;

use crate::common::*;
use uavnav_proto::v1 as pb;

const VEHICLES: usize = 40;
const SAMPLES: i64 = 50;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn many_vehicles_in_parallel() {
    let server = start(test_config()).await;
    let mut watcher = client(&server).await;
    let mut poses = watcher
        .watch_poses(pb::WatchRequest {
            id_prefix: "fleet-".into(),
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let mut decimated = watcher
        .watch_poses(pb::WatchRequest {
            vehicle_ids: vec!["fleet-0".into()],
            decimation: 10,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let mut tasks = Vec::new();
    for v in 0..VEHICLES {
        let mut c = client(&server).await;
        tasks.push(tokio::spawn(async move {
            let id = format!("fleet-{v}");
            // Distinct clocks per vehicle: one must never see another's timestamps.
            let t0 = (v as i64 + 1) * 1_000_000_000_000;
            let mut envs = vec![config_env(&id, 0, false), gnss_env(&id, 1, fix(t0))];
            for k in 0..SAMPLES {
                envs.push(imu_env(
                    &id,
                    2 + k as u64,
                    vec![imu(t0 + 1 + k * 5_000_000)],
                ));
            }
            let acks = ingest(&mut c, envs).await.unwrap();
            assert!(
                acks.iter()
                    .all(|a| a.status == pb::IngestStatus::Accepted as i32),
                "{acks:?}"
            );
        }));
    }
    for t in tasks {
        t.await.unwrap();
    }
    // The last window of each vehicle is flushed after the idle flush delay.
    let mut per_vehicle: BTreeMap<String, Vec<i64>> = BTreeMap::new();
    let total = VEHICLES * SAMPLES as usize;
    let collect = async {
        while per_vehicle.values().map(Vec::len).sum::<usize>() < total {
            let p = poses.message().await.unwrap().unwrap();
            per_vehicle
                .entry(p.vehicle_id.clone())
                .or_default()
                .push(p.t_ns);
        }
    };
    tokio::time::timeout(Duration::from_secs(20), collect)
        .await
        .expect("all poses within 20 s");
    assert_eq!(per_vehicle.len(), VEHICLES);
    for (id, ts) in &per_vehicle {
        let v: i64 = id.trim_start_matches("fleet-").parse().unwrap();
        let t0 = (v + 1) * 1_000_000_000_000;
        let want: Vec<i64> = (0..SAMPLES).map(|k| t0 + 1 + k * 5_000_000).collect();
        assert_eq!(
            ts, &want,
            "{id}: poses in order, one per sample, own clock only"
        );
    }
    let mut got = Vec::new();
    while got.len() < (SAMPLES as usize).div_ceil(10) {
        got.push(
            tokio::time::timeout(Duration::from_secs(5), decimated.message())
                .await
                .unwrap()
                .unwrap()
                .unwrap(),
        );
    }
    let t0 = 1_000_000_000_000;
    assert_eq!(
        got.iter().map(|p| p.t_ns).collect::<Vec<_>>(),
        (0..SAMPLES)
            .step_by(10)
            .map(|k| t0 + 1 + k * 5_000_000)
            .collect::<Vec<_>>()
    );

    let mut c = client(&server).await;
    let list = c
        .list_vehicles(pb::ListVehiclesRequest {
            id_prefix: "fleet-".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(list.vehicles.len(), VEHICLES);
    let ids: Vec<_> = list.vehicles.iter().map(|v| v.vehicle_id.clone()).collect();
    let mut sorted = ids.clone();
    sorted.sort();
    assert_eq!(ids, sorted);
    assert!(list.vehicles.iter().all(|v| v.configured));
    let pose = c
        .get_pose(pb::GetPoseRequest {
            vehicle_id: "fleet-3".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(
        pose.t_ns,
        4 * 1_000_000_000_000 + 1 + (SAMPLES - 1) * 5_000_000
    );
    assert_eq!(pose.position.unwrap().latitude_deg, 45.0);
    assert!(pose.ingest_wall_ns > 0);

    // Reset forgets the stream: older timestamps are accepted again.
    c.reset_vehicle(pb::ResetVehicleRequest {
        vehicle_id: "fleet-3".into(),
    })
    .await
    .unwrap();
    let acks = ingest(&mut c, vec![imu_env("fleet-3", 1, vec![imu(5)])])
        .await
        .unwrap();
    assert_eq!(
        acks[0].status,
        pb::IngestStatus::Accepted as i32,
        "{acks:?}"
    );
    let created = c
        .configure_vehicle(pb::ConfigureVehicleRequest {
            vehicle_id: "fleet-3".into(),
            config: Some(vehicle_config(true)),
        })
        .await
        .unwrap()
        .into_inner()
        .created;
    assert!(!created);
    server.shutdown().await.unwrap();
}

#[tokio::test]
async fn health_is_published_at_a_fixed_rate() {
    let server = start(test_config()).await;
    let mut c = client(&server).await;
    let mut health = c
        .watch_health(pb::WatchRequest {
            vehicle_ids: vec!["h".into()],
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let mut envs = vec![config_env("h", 0, true), gnss_env("h", 1, fix(1_000_000))];
    for k in 0..20 {
        envs.push(imu_env(
            "h",
            2 + k,
            vec![imu(1_000_001 + k as i64 * 5_000_000)],
        ));
    }
    envs.push(camera_env("h", 100, 100_000_000, camera_jpeg_header()));
    ingest(&mut c, envs).await.unwrap();
    let mut reports = Vec::new();
    let start = tokio::time::Instant::now();
    while reports.len() < 4 {
        reports.push(
            tokio::time::timeout(Duration::from_secs(2), health.message())
                .await
                .unwrap()
                .unwrap()
                .unwrap(),
        );
    }
    let elapsed = start.elapsed();
    assert!(
        elapsed >= Duration::from_millis(200),
        "period 100 ms: {elapsed:?}"
    );
    let last = reports.last().unwrap();
    let counters = last.counters.unwrap();
    assert_eq!(counters.accepted, 22, "20 IMU + 1 GNSS + 1 frame");
    assert_eq!(last.mode, pb::EstimatorMode::Nominal as i32);
    assert!(last.latency.is_some() && last.input_rates.is_some());
    assert!(
        reports
            .iter()
            .any(|r| r.vision.is_some_and(|v| v.tracked == 1)),
        "{reports:?}"
    );
    server.shutdown().await.unwrap();
}

#[tokio::test]
async fn http_endpoints() {
    let server = start(test_config()).await;
    let get = |path: &str| {
        let addr = server.http_addr;
        let path = path.to_string();
        async move {
            use tokio::io::{AsyncReadExt, AsyncWriteExt};
            let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
            s.write_all(
                format!("GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n").as_bytes(),
            )
            .await
            .unwrap();
            let mut out = String::new();
            s.read_to_string(&mut out).await.unwrap();
            out
        }
    };
    assert!(get("/livez").await.starts_with("HTTP/1.1 200"));
    assert!(get("/readyz").await.starts_with("HTTP/1.1 200"));
    let m = get("/metrics").await;
    assert!(
        m.contains("uavnav_vehicles") && m.contains("uavnav_ingest_to_pose_latency_seconds"),
        "{m}"
    );
    // The process's own figures, what `uavnav loadtest --metrics` divides by the samples.
    let value = |text: &str, name: &str| -> Option<f64> {
        text.lines()
            .find(|l| l.starts_with(name) && l[name.len()..].starts_with(' '))
            .and_then(|l| l[name.len()..].trim().parse().ok())
    };
    if cfg!(target_os = "linux") {
        let cpu = value(&m, "uavnav_process_cpu_seconds_total");
        let rss = value(&m, "uavnav_process_resident_memory_bytes");
        assert!(cpu.is_some_and(|c| c > 0.0), "{m}");
        assert!(rss.is_some_and(|r| r > 1e6), "{m}");
        // A counter: a later scrape never reads less.
        let later = value(&get("/metrics").await, "uavnav_process_cpu_seconds_total");
        assert!(later >= cpu, "{later:?} after {cpu:?}");
    }
    server.shutdown().await.unwrap();
}

/// One message of 1,000 IMU samples: the actor publishes its poses in batches of at most
/// `hub::MAX_BATCH_POSES` (so that the output ring's slots are bounded in bytes); a watcher gets
/// all 1,000 in order, and `GetPose` the last.
#[tokio::test]
async fn a_large_message_reaches_watchers_whole_and_in_order() {
    let server = start(test_config()).await;
    let mut c = client(&server).await;
    let mut watch = c
        .watch_poses(pb::WatchRequest {
            vehicle_ids: vec!["big".into()],
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let t0 = 1_000_000_000_000i64;
    let samples: Vec<_> = (0..1000).map(|k| imu(t0 + 1 + k * 5_000_000)).collect();
    let envs = vec![
        config_env("big", 0, false),
        gnss_env("big", 1, fix(t0)),
        imu_env("big", 2, samples),
    ];
    ingest(&mut c, envs).await.unwrap();
    for k in 0..1000 {
        let p = tokio::time::timeout(Duration::from_secs(10), watch.message())
            .await
            .unwrap()
            .unwrap()
            .unwrap();
        assert_eq!(p.t_ns, t0 + 1 + k * 5_000_000, "pose {k}");
    }
    let pose = c
        .get_pose(pb::GetPoseRequest {
            vehicle_id: "big".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(pose.t_ns, t0 + 1 + 999 * 5_000_000);
}
