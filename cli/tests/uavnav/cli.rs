//! The online `uavnav` subcommands end to end against an in-process `uavnavd`: management,
//! replay, watch (CSV, TUM, Foxglove live view).
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::Duration;

use crate::common::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cli_management_subcommands() {
    let svc = start().await;
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("s.toml");
    std::fs::write(
        &scenario,
        smoke_text().replace("duration_s = 20.0", "duration_s = 3.0"),
    )
    .unwrap();
    let sc = scenario.display().to_string();
    let g = svc.grpc.clone();

    // configure: created, then reconfigured; over Zenoh: published.
    let out = run_async(vec![
        "configure".into(),
        "--from".into(),
        g.clone(),
        "--vehicle".into(),
        "cli-1".into(),
        "--scenario".into(),
        sc.clone(),
        "--no-camera".into(),
    ])
    .await;
    assert_eq!(
        (out.status.code(), stdout(&out).trim()),
        (Some(0), "created cli-1")
    );
    let out = run_async(vec![
        "configure".into(),
        "--from".into(),
        g.clone(),
        "--vehicle".into(),
        "cli-1".into(),
        "--scenario".into(),
        sc.clone(),
    ])
    .await;
    assert_eq!(
        (out.status.code(), stdout(&out).trim()),
        (Some(0), "reconfigured cli-1")
    );
    let out = run_async(vec![
        "configure".into(),
        "--from".into(),
        svc.zenoh.clone(),
        "--vehicle".into(),
        "cli-2".into(),
        "--scenario".into(),
        sc.clone(),
    ])
    .await;
    assert_eq!(
        (out.status.code(), stdout(&out).trim()),
        (Some(0), "published cli-2")
    );

    // vehicles: both listed (over gRPC and Zenoh).
    tokio::time::sleep(Duration::from_millis(300)).await;
    for url in [&g, &svc.zenoh] {
        let out = run_async(vec![
            "vehicles".into(),
            "--from".into(),
            url.clone(),
            "--json".into(),
        ])
        .await;
        assert_eq!(out.status.code(), Some(0));
        let ids: Vec<String> = stdout(&out)
            .lines()
            .map(|l| {
                serde_json::from_str::<serde_json::Value>(l).unwrap()["vehicle_id"]
                    .as_str()
                    .unwrap()
                    .to_string()
            })
            .collect();
        assert_eq!(ids, vec!["cli-1", "cli-2"]);
    }

    // health: service check, then per vehicle; --max-age on an unknown vehicle = exit 3.
    let out = run_async(vec!["health".into(), "--from".into(), g.clone()]).await;
    assert_eq!(out.status.code(), Some(0));
    assert!(stdout(&out).starts_with("ok: "));
    let out = run_async(vec![
        "health".into(),
        "--from".into(),
        g.clone(),
        "--vehicle".into(),
        "cli-1".into(),
        // Several health periods (1 s by default): one period failed once on a loaded CI machine.
        "--wait".into(),
        "3".into(),
        "--json".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(0));
    let h: serde_json::Value = serde_json::from_str(stdout(&out).lines().next().unwrap()).unwrap();
    assert_eq!(h["vehicle_id"], "cli-1");
    // The heading's health rides along (the smoke flight's compass-less fixed wing: course or
    // not yet known; no compass).
    assert_eq!(h["magnetometer"], "off", "{h}");
    assert_eq!(h["magnetometer_calibration"], "off", "{h}");
    assert!(h["magnetometer_offset_t"].is_null(), "{h}");
    assert!(
        ["course", "unknown", "yaw_bank"].contains(&h["heading_source"].as_str().unwrap()),
        "{h}"
    );
    let out = run_async(vec![
        "health".into(),
        "--from".into(),
        g.clone(),
        "--vehicle".into(),
        "ghost".into(),
        "--wait".into(),
        "0.2".into(),
        "--max-age".into(),
        "5".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(3));

    // reset: ok, unknown = 2, over Zenoh = 2 (unsupported).
    let out = run_async(vec![
        "reset".into(),
        "--from".into(),
        g.clone(),
        "--vehicle".into(),
        "cli-1".into(),
    ])
    .await;
    assert_eq!(
        (out.status.code(), stdout(&out).trim()),
        (Some(0), "reset cli-1")
    );
    let out = run_async(vec![
        "reset".into(),
        "--from".into(),
        g.clone(),
        "--vehicle".into(),
        "ghost".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(2));
    let out = run_async(vec![
        "reset".into(),
        "--from".into(),
        svc.zenoh.clone(),
        "--vehicle".into(),
        "cli-1".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(2));

    // Bad URL = 2, unreachable = 1; every subcommand has --help with the exit codes.
    assert_eq!(
        run(&["vehicles", "--from", "ftp://x:1"]).status.code(),
        Some(2)
    );
    assert_eq!(
        run(&["vehicles", "--from", "grpc://127.0.0.1:1"])
            .status
            .code(),
        Some(1)
    );
    for sub in [
        "replay",
        "watch",
        "record",
        "vehicles",
        "health",
        "configure",
        "reset",
        "loadtest",
    ] {
        let out = run(&[sub, "--help"]);
        assert_eq!(out.status.code(), Some(0));
        assert!(stdout(&out).contains("Exit codes"), "{sub}");
    }
    svc.server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn replay_and_watch_end_to_end() {
    let svc = start().await;
    let dir = tempfile::tempdir().unwrap();
    let ds = simulate(dir.path(), "flight", 4.0);
    let csv = dir.path().join("poses.csv");
    let tum = dir.path().join("poses.tum");
    // Watchers first (CSV over gRPC, TUM over Zenoh), then 2 copies replayed at 4x.
    let w1 = tokio::spawn(run_async(vec![
        "watch".into(),
        "--from".into(),
        svc.grpc.clone(),
        "--prefix".into(),
        "rp-".into(),
        "--out".into(),
        csv.display().to_string(),
        "--idle-exit".into(),
        "1.5".into(),
        "--duration".into(),
        "20".into(),
    ]));
    let w2 = tokio::spawn(run_async(vec![
        "watch".into(),
        "--from".into(),
        svc.zenoh.clone(),
        "--vehicle".into(),
        "rp-1".into(),
        "--out".into(),
        tum.display().to_string(),
        "--idle-exit".into(),
        "1.5".into(),
        "--duration".into(),
        "20".into(),
    ]));
    // A Foxglove live view of rp-0 from a watcher, seen by a Foxglove WebSocket client.
    let fox_port = free_port();
    let w3 = tokio::spawn(run_async(vec![
        "watch".into(),
        "--from".into(),
        svc.grpc.clone(),
        "--vehicle".into(),
        "rp-0".into(),
        "--foxglove".into(),
        format!("127.0.0.1:{fox_port}"),
        "--idle-exit".into(),
        "1.5".into(),
        "--duration".into(),
        "20".into(),
    ]));
    let fox = tokio::spawn(foxglove_first_pose(fox_port, "/vehicle/rp-0/pose"));
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let out = run_async(vec![
        "replay".into(),
        ds.display().to_string(),
        "--to".into(),
        svc.grpc.clone(),
        "--speed".into(),
        "4".into(),
        "--vehicles".into(),
        "2".into(),
        "--id-prefix".into(),
        "rp-".into(),
    ])
    .await;
    assert_eq!(out.status.code(), Some(0));
    assert!(stdout(&out).starts_with("sent "));
    let (o1, o2) = (w1.await.unwrap(), w2.await.unwrap());
    assert_eq!((o1.status.code(), o2.status.code()), (Some(0), Some(0)));
    let o3 = w3.await.unwrap();
    assert_eq!(o3.status.code(), Some(0));
    assert!(
        o3.stdout.is_empty(),
        "with --foxglove and no --out, nothing on stdout"
    );
    let err3 = String::from_utf8_lossy(&o3.stderr);
    assert!(err3.contains("live view showed 1 vehicles"), "{err3}");
    let pose = fox.await.unwrap();
    assert_eq!(pose.frame_id, "ned");
    let p = pose.pose.unwrap().position.unwrap();
    assert!(p.x.is_finite() && p.x.abs() < 1e4, "{p:?}");

    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    assert_eq!(
        header,
        format!("{},vehicle_id", uavnav_dataset::poses::csv_header())
    );
    let rows: Vec<&str> = lines.collect();
    let ncol = header.split(',').count();
    assert!(rows.iter().all(|r| r.split(',').count() == ncol));
    for id in ["rp-0", "rp-1"] {
        let n = rows
            .iter()
            .filter(|r| r.ends_with(&format!(",{id}")))
            .count();
        assert!(n > 300, "{n} rows of {id}");
    }
    let tum_lines = std::fs::read_to_string(&tum).unwrap();
    let n_tum = tum_lines.lines().count();
    assert!(n_tum > 300, "{n_tum} TUM lines");
    assert!(tum_lines.lines().all(|l| l.split(' ').count() == 8));
    svc.server.shutdown().await.unwrap();
}

/// Connects to a Foxglove live view (retrying while it starts), subscribes to `topic` once it is
/// advertised and returns the first message on it, decoded.
async fn foxglove_first_pose(port: u16, topic: &str) -> foxglove::messages::PoseInFrame {
    use futures::{SinkExt, StreamExt};
    use prost::Message as _;
    use tokio_tungstenite::tungstenite::{Message, client::IntoClientRequest};
    let mut ws = None;
    for _ in 0..100 {
        let mut req = format!("ws://127.0.0.1:{port}")
            .into_client_request()
            .unwrap();
        req.headers_mut()
            .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
        if let Ok((s, _)) = tokio_tungstenite::connect_async(req).await {
            ws = Some(s);
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let mut ws = ws.expect("the live view accepts connections");
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    while let Ok(Some(Ok(m))) = tokio::time::timeout_at(deadline, ws.next()).await {
        match m {
            Message::Text(t) => {
                let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap();
                if v["op"] != "advertise" {
                    continue;
                }
                for c in v["channels"].as_array().unwrap() {
                    if c["topic"] == topic {
                        let sub = serde_json::json!({"op": "subscribe",
                            "subscriptions": [{"id": 1, "channelId": c["id"]}]});
                        ws.send(Message::Text(sub.to_string().into()))
                            .await
                            .unwrap();
                    }
                }
            }
            Message::Binary(b) if b.first() == Some(&1) && b.len() > 13 => {
                return foxglove::messages::PoseInFrame::decode(&b[13..]).unwrap();
            }
            _ => {}
        }
    }
    panic!("no {topic} message from the live view");
}
