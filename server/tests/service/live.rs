//! The Foxglove live view of the service (`uavnavd --foxglove-addr`), seen by a Foxglove WebSocket
//! client speaking the `foxglove.sdk.v1` protocol: each vehicle's pose, path, map fix, GNSS fix and
//! camera image arrive on their topics with the values that were ingested.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::collections::HashMap;
use std::time::Duration;

use futures::{SinkExt, StreamExt};
use prost::Message as _;
use serde_json::Value;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

use crate::common::*;

type Ws =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

const STEP: Duration = Duration::from_secs(10);

async fn connect(port: u16) -> Ws {
    let mut req = format!("ws://127.0.0.1:{port}")
        .into_client_request()
        .unwrap();
    req.headers_mut()
        .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
    let (ws, _) = tokio_tungstenite::connect_async(req).await.unwrap();
    ws
}

/// Next message of the socket (text as JSON, binary as bytes), within [`STEP`].
async fn next(ws: &mut Ws) -> Result<Value, Vec<u8>> {
    loop {
        let m = tokio::time::timeout(STEP, ws.next())
            .await
            .expect("a message from the live view")
            .expect("the socket stays open")
            .expect("a valid frame");
        match m {
            Message::Text(t) => return Ok(serde_json::from_str(t.as_str()).unwrap()),
            Message::Binary(b) => return Err(b.to_vec()),
            _ => {}
        }
    }
}

/// Reads advertisements until `want` topics are known; returns topic → (channel id, schema name).
async fn advertised(ws: &mut Ws, want: usize) -> HashMap<String, (u64, String)> {
    let mut topics = HashMap::new();
    while topics.len() < want {
        let Ok(v) = next(ws).await else { continue };
        if v["op"] != "advertise" {
            continue;
        }
        for c in v["channels"].as_array().unwrap() {
            topics.insert(
                c["topic"].as_str().unwrap().to_owned(),
                (
                    c["id"].as_u64().unwrap(),
                    c["schemaName"].as_str().unwrap().to_owned(),
                ),
            );
        }
    }
    topics
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn live_view_shows_pose_path_gnss_and_camera_of_each_vehicle() {
    let mut config = test_config();
    config.foxglove.addr = Some("127.0.0.1:0".into());
    let server = start(config).await;
    let port = server.foxglove_port().expect("live view configured");
    let mut ws = connect(port).await;
    let info = next(&mut ws).await.expect("serverInfo first");
    assert_eq!(info["op"], "serverInfo");

    // First data creates the vehicle's channels.
    let mut grpc = client(&server).await;
    let t0 = 1_000_000_000_000i64;
    let acks = ingest(
        &mut grpc,
        vec![
            config_env("uav-7", 1, true),
            gnss_env("uav-7", 2, fix(t0)),
            imu_env("uav-7", 3, vec![imu(t0 + 5_000_000)]),
        ],
    )
    .await
    .unwrap();
    assert!(
        acks.iter()
            .all(|a| a.status == uavnav_proto::v1::IngestStatus::Accepted as i32)
    );
    let topics = advertised(&mut ws, 6).await;
    for (topic, schema) in [
        ("/vehicle/uav-7/pose", "foxglove.PoseInFrame"),
        ("/vehicle/uav-7/path", "foxglove.PosesInFrame"),
        ("/vehicle/uav-7/estimate_fix", "foxglove.LocationFix"),
        ("/vehicle/uav-7/gnss", "foxglove.LocationFix"),
        ("/vehicle/uav-7/mag", "foxglove.Vector3"),
        ("/vehicle/uav-7/camera", "foxglove.CompressedImage"),
    ] {
        assert_eq!(topics[topic].1, schema, "{topic}");
    }

    // Subscribe to everything, then stream more: each topic delivers what was ingested.
    let subs: Vec<(u32, &str)> = ["pose", "path", "estimate_fix", "gnss", "camera"]
        .into_iter()
        .enumerate()
        .map(|(i, leaf)| (i as u32 + 1, leaf))
        .collect();
    let sub_msg = serde_json::json!({
        "op": "subscribe",
        "subscriptions": subs.iter().map(|(id, leaf)| serde_json::json!({
            "id": id, "channelId": topics[&format!("/vehicle/uav-7/{leaf}")].0,
        })).collect::<Vec<_>>(),
    });
    ws.send(Message::Text(sub_msg.to_string().into()))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;

    let mut moved = fix(t0 + 1_000_000_000);
    moved.latitude_deg += 1e-4; // ~11 m north
    let jpeg = camera_jpeg_header();
    let acks = ingest(
        &mut grpc,
        vec![
            gnss_env("uav-7", 4, moved),
            camera_env("uav-7", 5, t0 + 1_010_000_000, jpeg.clone()),
            imu_env("uav-7", 6, vec![imu(t0 + 1_100_000_000)]),
        ],
    )
    .await
    .unwrap();
    assert!(
        acks.iter()
            .all(|a| a.status == uavnav_proto::v1::IngestStatus::Accepted as i32)
    );

    // The latest message per topic, until every topic has shown the second batch (poses of the
    // first batch may still be on their way when the subscription starts).
    use foxglove::messages::{CompressedImage, LocationFix, PoseInFrame, PosesInFrame};
    let moved_pose = |b: &Vec<u8>| {
        PoseInFrame::decode(b.as_slice())
            .ok()
            .and_then(|p| p.pose?.position)
            .is_some_and(|p| p.x > 5.0)
    };
    let mut got: HashMap<&str, Vec<u8>> = HashMap::new();
    let long_path =
        |b: &Vec<u8>| PosesInFrame::decode(b.as_slice()).is_ok_and(|p| p.poses.len() >= 2);
    while got.len() < subs.len()
        || !got.get("pose").is_some_and(moved_pose)
        || !got.get("path").is_some_and(long_path)
    {
        let Err(bin) = next(&mut ws).await else {
            continue;
        };
        assert_eq!(bin[0], 1, "message data opcode");
        let sub = u32::from_le_bytes(bin[1..5].try_into().unwrap());
        let leaf = subs.iter().find(|(id, _)| *id == sub).unwrap().1;
        got.insert(leaf, bin[13..].to_vec());
    }
    let pose = PoseInFrame::decode(got["pose"].as_slice()).unwrap();
    assert_eq!(pose.frame_id, "ned");
    let p = pose.pose.unwrap().position.unwrap();
    // The view's NED origin is the first pose (at the first fix): the vehicle moved ~11 m north.
    assert!((p.x - 11.1).abs() < 0.2 && p.y.abs() < 0.1, "{p:?}");
    let path = PosesInFrame::decode(got["path"].as_slice()).unwrap();
    assert_eq!(path.poses.len(), 2, "a path point per 0.5 s of sensor time");
    let map = LocationFix::decode(got["estimate_fix"].as_slice()).unwrap();
    assert!((map.latitude - moved.latitude_deg).abs() < 1e-9);
    let gnss = LocationFix::decode(got["gnss"].as_slice()).unwrap();
    assert!((gnss.latitude - moved.latitude_deg).abs() < 1e-9);
    assert_eq!(gnss.frame_id, "gnss0");
    let img = CompressedImage::decode(got["camera"].as_slice()).unwrap();
    assert_eq!(img.data.as_ref(), jpeg.as_slice());
    assert_eq!(
        (img.format.as_str(), img.frame_id.as_str()),
        ("jpeg", "cam0")
    );
    assert_eq!(img.timestamp.map(|t| t.sec()), Some(1001));
    assert_eq!(
        server.metrics().foxglove_dropped.get(),
        0,
        "nothing skipped at this rate"
    );

    server.shutdown().await.unwrap();
}

/// A vehicle running without GNSS (attitude-only poses) still shows its attitude: its pose topic
/// carries the filter's `nav_from_body`, drawn at the frame's origin (it has no position yet).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn live_view_shows_the_attitude_of_a_vehicle_without_gnss() {
    let mut config = test_config();
    config.foxglove.addr = Some("127.0.0.1:0".into());
    // The real engine: the kit's echo engine makes no attitude.
    let server = uavnavd::Server::start(config).await.unwrap();
    let port = server.foxglove_port().expect("live view configured");
    let mut ws = connect(port).await;
    assert_eq!(
        next(&mut ws).await.expect("serverInfo first")["op"],
        "serverInfo"
    );

    let mut grpc = client(&server).await;
    let mut vehicle = vehicle_config(false);
    vehicle.gnss = None;
    let t0 = 1_000_000_000i64;
    // A level, still IMU in 50 ms batches; `from` counts 5 ms samples.
    let batches = |from: i64, n: i64| -> Vec<uavnav_proto::v1::SensorEnvelope> {
        (0..n)
            .map(|b| {
                let k0 = from + b * 10;
                let samples = (k0..k0 + 10).map(|k| imu(t0 + k * 5_000_000)).collect();
                imu_env("indoor", 1 + k0 as u64, samples)
            })
            .collect()
    };
    let mut first = vec![uavnav_proto::v1::SensorEnvelope {
        vehicle_id: "indoor".into(),
        sequence: 0,
        payload: Some(uavnav_proto::v1::sensor_envelope::Payload::Config(vehicle)),
    }];
    first.extend(batches(0, 30));
    ingest(&mut grpc, first).await.unwrap();
    let topics = advertised(&mut ws, 6).await;
    let pose_channel = topics["/vehicle/indoor/pose"].0;
    let sub = serde_json::json!({
        "op": "subscribe",
        "subscriptions": [{"id": 1, "channelId": pose_channel}],
    });
    ws.send(Message::Text(sub.to_string().into()))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    ingest(&mut grpc, batches(300, 10)).await.unwrap();

    let pose = loop {
        let Err(bin) = next(&mut ws).await else {
            continue;
        };
        assert_eq!(bin[0], 1, "message data opcode");
        break foxglove::messages::PoseInFrame::decode(&bin[13..]).unwrap();
    };
    assert_eq!(pose.frame_id, "ned");
    let inner = pose.pose.unwrap();
    let p = inner.position.unwrap();
    assert_eq!(
        (p.x, p.y, p.z),
        (0.0, 0.0, 0.0),
        "no position: at the origin"
    );
    // Level (heading unknown): a rotation about the vertical only, of unit norm.
    let q = inner.orientation.unwrap();
    assert!(q.x.abs() < 0.01 && q.y.abs() < 0.01, "{q:?}");
    assert!((q.w * q.w + q.z * q.z - 1.0).abs() < 1e-3, "{q:?}");
    server.shutdown().await.unwrap();
}

#[tokio::test]
async fn a_busy_port_is_a_clear_startup_error() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap();
    let mut config = test_config();
    config.foxglove.addr = Some(addr.to_string());
    let err = uavnavd::Server::start(config).await.unwrap_err();
    let msg = format!("{err:#}");
    assert!(msg.contains("Foxglove WebSocket server"), "{msg}");
    assert!(msg.contains(&addr.to_string()), "{msg}");
}
