//! `uavnav loadtest` and the load generator, against the service and the discarding sink.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::sync::Arc;
use std::time::Duration;

use crate::common::*;
use uavnav_cli::load::{self, Live, LoadParams, Recording};
use uavnav_client::Client;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn loadtest_measures_against_the_service_and_the_discard_sink() {
    let svc = start().await;
    let (_, msgs) = flight(4.0);
    let rec = Arc::new(Recording::new(msgs).unwrap());
    // The library directly: every vehicle gets poses, latency is measured.
    let client = Client::connect_url(&svc.grpc).await.unwrap();
    let params = LoadParams {
        vehicles: 3,
        duration: Duration::from_secs(2),
        id_prefix: "ltlib-".into(),
        ..LoadParams::default()
    };
    let o = load::run(&client, Arc::clone(&rec), params, Arc::new(Live::default()))
        .await
        .unwrap();
    assert_eq!(o.sent, o.scheduled);
    assert_eq!(o.vehicles_with_poses, 3);
    assert!(o.poses > 100 && !o.latency_ns.is_empty());
    assert_eq!(o.statuses.get("OK").copied(), Some(o.sent));

    // Against the discard sink nothing is expected back.
    let d = Client::connect_url("discard").await.unwrap();
    let params = LoadParams {
        vehicles: 50,
        duration: Duration::from_secs(1),
        id_prefix: "d-".into(),
        ..LoadParams::default()
    };
    let o = load::run(&d, rec, params, Arc::new(Live::default()))
        .await
        .unwrap();
    assert_eq!(o.sent, o.scheduled);
    assert!(
        o.failures(&load::Thresholds::default()).is_empty(),
        "{:?}",
        o.failures(&load::Thresholds::default())
    );

    // The CLI: the JSON report, field by field.
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("lt.json");
    let out = run_async(vec![
        "loadtest".into(),
        "--to".into(),
        svc.grpc.clone(),
        "--vehicles".into(),
        "2".into(),
        "--duration".into(),
        "2s".into(),
        "--no-camera".into(),
        "--quiet".into(),
        "--json".into(),
        json.display().to_string(),
        "--metrics".into(),
        format!("http://{}/metrics", svc.server.http_addr),
    ])
    .await;
    assert_eq!(out.status.code(), Some(0));
    assert!(stdout(&out).contains("Latency (ingest to pose)"));
    // The service's own CPU per accepted input, from its /metrics before and after (Linux).
    if cfg!(target_os = "linux") {
        let text = stdout(&out);
        let line = text
            .lines()
            .find(|l| l.contains("Service process:"))
            .unwrap_or_else(|| panic!("{text}"));
        assert!(
            line.contains("µs per accepted input") && line.contains("MiB resident"),
            "{line}"
        );
        assert!(text.contains("Generator process:"), "{text}");
        // This machine's speed, measured before the load for as many vehicles.
        let reference = text
            .lines()
            .find(|l| l.starts_with("Machine reference:"))
            .unwrap_or_else(|| panic!("{text}"));
        assert!(
            reference.contains("µs per IMU sample for 2 vehicles taking 4-sample messages in turn"),
            "{reference}"
        );
    }
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let count = v["count"].as_u64().unwrap();
    // 2 vehicles × ~2 s (the second starts 0.5 s late) × (50 IMU batches + 5 fixes) per s.
    assert!(count > 150, "count {count}");
    assert_eq!(v["uavnav"]["scheduled"].as_u64(), Some(count));
    let total = v["total"].as_u64().unwrap();
    assert!(
        (1_900_000_000..4_000_000_000).contains(&total),
        "total {total} ns"
    );
    let rps = v["rps"].as_f64().unwrap();
    assert!((rps - count as f64 / (total as f64 * 1e-9)).abs() < 1e-6 * rps);
    let (fastest, average, slowest) = (
        v["fastest"].as_u64().unwrap(),
        v["average"].as_u64().unwrap(),
        v["slowest"].as_u64().unwrap(),
    );
    assert!(
        0 < fastest && fastest <= average && average <= slowest,
        "{fastest} {average} {slowest}"
    );
    let dist = v["latencyDistribution"].as_array().unwrap();
    let pcts: Vec<f64> = dist
        .iter()
        .map(|d| d["percentage"].as_f64().unwrap())
        .collect();
    assert_eq!(pcts, vec![50.0, 75.0, 90.0, 95.0, 99.0, 99.9]);
    let lats: Vec<u64> = dist
        .iter()
        .map(|d| d["latency"].as_u64().unwrap())
        .collect();
    assert!(
        lats.windows(2).all(|w| w[0] <= w[1])
            && lats[0] >= fastest
            && *lats.last().unwrap() <= slowest,
        "{lats:?}"
    );
    assert_eq!(v["statusCodeDistribution"]["OK"].as_u64(), Some(count));
    assert_eq!(v["errorDistribution"].as_object().unwrap().len(), 0);
    let x = &v["uavnav"];
    assert_eq!(x["vehicles"].as_u64(), Some(2));
    assert_eq!(x["camera"].as_bool(), Some(false));
    assert_eq!(x["vehiclesWithPoses"].as_u64(), Some(2));
    assert!(x["poses"].as_u64().unwrap() > 300);
    assert_eq!(x["unacked"].as_u64(), Some(0));
    assert_eq!(x["errorRate"].as_f64(), Some(0.0));
    assert_eq!(x["keptUp"].as_bool(), Some(true));
    assert_eq!(x["service"]["vehiclesReporting"].as_u64(), Some(2));
    assert!(x["service"]["accepted"].as_u64().unwrap() > 0);

    // An impossible latency bound: exit 3 with the reason.
    let out = run_async(vec![
        "loadtest".into(),
        "--to".into(),
        svc.grpc.clone(),
        "--vehicles".into(),
        "1".into(),
        "--duration".into(),
        "1s".into(),
        "--no-camera".into(),
        "--quiet".into(),
        "--max-p99-ms".into(),
        "0.001".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&out.stderr).contains("p99 ingest-to-pose latency"));
    svc.server.shutdown().await.unwrap();
}
