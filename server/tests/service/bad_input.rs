//! Every bad-input case gets its exact status, and never disturbs another vehicle.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::Duration;

use crate::common::*;
use prost::Message;
use uavnav_proto::v1 as pb;

fn status_of(acks: &[pb::IngestAck], seq: u64) -> (pb::IngestStatus, String) {
    let a = acks
        .iter()
        .find(|a| a.sequence == seq)
        .unwrap_or_else(|| panic!("no ack for {seq}"));
    (
        pb::IngestStatus::try_from(a.status).unwrap(),
        a.reason.clone(),
    )
}

#[tokio::test]
async fn each_bad_envelope_gets_its_status_and_reason() {
    let mut cfg = test_config();
    cfg.vision.max_image_bytes = 64 * 1024;
    let server = start(cfg).await;
    let mut c = client(&server).await;
    let s = 1_000_000_000i64;
    let mut nan = imu(s + 10_000_000);
    nan.gyro_x_radps = f64::NAN;
    let mut absurd = imu(s + 20_000_000);
    absurd.accel_y_mps2 = 1e6;
    let mut bad_fix = fix(s + 30_000_000);
    bad_fix.latitude_deg = 91.0;
    let mut unspecified_fix = fix(s + 31_000_000);
    unspecified_fix.fix_type = 0;
    let envs = vec![
        config_env("cam", 1, true),
        imu_env("cam", 2, vec![imu(s)]),
        imu_env("cam", 3, vec![nan]),
        imu_env("cam", 4, vec![absurd]),
        imu_env("cam", 5, vec![imu(s + 50_000_000), imu(s + 40_000_000)]),
        imu_env("cam", 6, vec![imu(s)]),
        imu_env("cam", 7, vec![imu(s + 3600 * 1_000_000_000)]),
        gnss_env("cam", 8, bad_fix),
        gnss_env("cam", 9, unspecified_fix),
        camera_env("cam", 10, s + 5_000_000, vec![0xFF, 0xD8, 0x00, 0x13, 0x37]),
        camera_env("cam", 11, s + 6_000_000, jpeg_header(320, 240)),
        camera_env("cam", 12, s + 7_000_000, {
            let mut big = camera_jpeg_header();
            big.resize(100 * 1024, 0);
            big
        }),
        camera_env("nocam", 13, s, camera_jpeg_header()),
        imu_env("bad/id", 14, vec![imu(s)]),
        pb::SensorEnvelope {
            vehicle_id: "cam".into(),
            sequence: 15,
            payload: None,
        },
        imu_env("cam", 16, vec![imu(s + 100_000_000)]),
        imu_env("cam", 17, vec![imu(s + 1_000)]),
        camera_env("cam", 18, s + 200_000_000, camera_jpeg_header()),
    ];
    let acks = ingest(&mut c, envs).await.unwrap();
    use pb::IngestStatus as S;
    let expect = [
        (1, S::Accepted, ""),
        (2, S::Accepted, ""),
        (3, S::InvalidArgument, "imu.samples[0].gyro_x_radps"),
        (4, S::InvalidArgument, "imu.samples[0].accel_y_mps2"),
        (5, S::InvalidArgument, "imu.samples[1].t_ns"),
        (6, S::Late, "duplicate"),
        (7, S::OutOfRange, "ahead"),
        (8, S::InvalidArgument, "gnss.latitude_deg"),
        (9, S::InvalidArgument, "gnss.fix_type"),
        (10, S::InvalidArgument, "camera.image.data: corrupt jpeg"),
        (11, S::InvalidArgument, "320x240"),
        (12, S::ResourceExhausted, "camera.image.data"),
        (13, S::FailedPrecondition, "camera"),
        (14, S::InvalidArgument, "vehicle_id"),
        (15, S::InvalidArgument, "payload"),
        (16, S::Accepted, ""),
        (17, S::Late, "older than"),
        (18, S::Accepted, ""),
    ];
    for (seq, status, needle) in expect {
        let (got, reason) = status_of(&acks, seq);
        assert_eq!(got, status, "envelope {seq}: {reason}");
        assert!(
            reason.contains(needle),
            "envelope {seq}: reason {reason:?} lacks {needle:?}"
        );
    }
    // Rejections are visible in the vehicle's health.
    let reg = server.registry().clone();
    assert!(
        eventually(Duration::from_secs(3), || {
            reg.get("cam")
                .and_then(|h| h.shared.health())
                .and_then(|h| h.counters)
                .is_some_and(|k| k.rejected >= 7)
        })
        .await
    );
    let metrics = server.metrics().encode();
    assert!(metrics.contains("outcome=\"invalid\""), "{metrics}");
    server.shutdown().await.unwrap();
}

async fn raw_call(
    server: &uavnavd::RunningServer,
    path: &'static str,
    bodies: Vec<Vec<u8>>,
) -> tonic::Status {
    let mut grpc = raw_grpc(server).await;
    let path = tonic::codegen::http::uri::PathAndQuery::from_static(path);
    let request = tonic::Request::new(futures::stream::iter(bodies));
    match grpc.streaming(request, path, RawCodec).await {
        Err(s) => s,
        Ok(resp) => {
            let mut stream = resp.into_inner();
            loop {
                match stream.message().await {
                    Ok(Some(_)) => continue,
                    Ok(None) => return tonic::Status::ok("stream ended"),
                    Err(s) => return s,
                }
            }
        }
    }
}

#[tokio::test]
async fn malformed_protobuf_ends_ingest_with_invalid_argument() {
    let server = start(test_config()).await;
    let good = imu_env("ok", 1, vec![imu(1_000)]).encode_to_vec();
    // Field 1 (vehicle_id) as a length-delimited string whose length runs past the end.
    let garbage = vec![0x0A, 0xFF, 0x01, b'x'];
    let status = raw_call(&server, "/uavnav.v1.UavNav/Ingest", vec![good, garbage]).await;
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
    assert!(status.message().contains("malformed"), "{status:?}");
    // The vehicle fed before the garbage is untouched.
    assert!(server.registry().get("ok").is_some());
    server.shutdown().await.unwrap();
}

#[tokio::test]
async fn malformed_unary_request_is_invalid_argument() {
    let server = start(test_config()).await;
    let channel = tonic::transport::Endpoint::from_shared(format!("http://{}", server.grpc_addr))
        .unwrap()
        .connect()
        .await
        .unwrap();
    let mut grpc = tonic::client::Grpc::new(channel);
    grpc.ready().await.unwrap();
    // The raw-bytes codec: the call fails on the request, before any response is decoded.
    let path = tonic::codegen::http::uri::PathAndQuery::from_static("/uavnav.v1.UavNav/GetPose");
    let status = grpc
        .unary(tonic::Request::new(vec![0x0A, 0xFF, 0x01]), path, RawCodec)
        .await
        .unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
    server.shutdown().await.unwrap();
}

#[tokio::test]
async fn oversize_message_is_resource_exhausted() {
    let mut cfg = test_config();
    cfg.grpc.max_message_bytes = 8 << 20;
    let server = start(cfg).await;
    let mut env = camera_env("big", 1, 1_000, camera_jpeg_header());
    if let Some(pb::sensor_envelope::Payload::Camera(c)) = env.payload.as_mut() {
        let mut d = c.image.as_ref().unwrap().data.to_vec();
        d.resize(9 << 20, 0);
        c.image.as_mut().unwrap().data = d.into();
    }
    let status = raw_call(
        &server,
        "/uavnav.v1.UavNav/Ingest",
        vec![env.encode_to_vec()],
    )
    .await;
    assert_eq!(status.code(), tonic::Code::ResourceExhausted, "{status:?}");
    server.shutdown().await.unwrap();
}

#[tokio::test]
async fn unary_calls_name_the_problem() {
    let server = start(test_config()).await;
    let mut c = client(&server).await;
    let mut cfg = vehicle_config(true);
    cfg.camera.as_mut().unwrap().fx_px = -1.0;
    let st = c
        .configure_vehicle(pb::ConfigureVehicleRequest {
            vehicle_id: "v".into(),
            config: Some(cfg),
        })
        .await
        .unwrap_err();
    assert_eq!(st.code(), tonic::Code::InvalidArgument);
    assert!(st.message().contains("config.camera.fx_px"), "{st:?}");
    let st = c
        .configure_vehicle(pb::ConfigureVehicleRequest {
            vehicle_id: "v".into(),
            config: None,
        })
        .await
        .unwrap_err();
    assert_eq!(st.code(), tonic::Code::InvalidArgument);
    let st = c
        .get_pose(pb::GetPoseRequest {
            vehicle_id: "nobody".into(),
        })
        .await
        .unwrap_err();
    assert_eq!(st.code(), tonic::Code::NotFound);
    let st = c
        .get_pose(pb::GetPoseRequest {
            vehicle_id: "a b".into(),
        })
        .await
        .unwrap_err();
    assert_eq!(st.code(), tonic::Code::InvalidArgument);
    let st = c
        .reset_vehicle(pb::ResetVehicleRequest {
            vehicle_id: "nobody".into(),
        })
        .await
        .unwrap_err();
    assert_eq!(st.code(), tonic::Code::NotFound);
    let st = c
        .watch_poses(pb::WatchRequest::default())
        .await
        .unwrap_err();
    assert_eq!(st.code(), tonic::Code::InvalidArgument);
    server.shutdown().await.unwrap();
}

#[tokio::test]
async fn vehicle_limit_is_resource_exhausted() {
    let mut cfg = test_config();
    cfg.vehicles.max_vehicles = 2;
    let server = start(cfg).await;
    let mut c = client(&server).await;
    let acks = ingest(
        &mut c,
        vec![
            imu_env("a", 1, vec![imu(1)]),
            imu_env("b", 2, vec![imu(1)]),
            imu_env("c", 3, vec![imu(1)]),
        ],
    )
    .await
    .unwrap();
    assert_eq!(
        acks[2].status,
        pb::IngestStatus::ResourceExhausted as i32,
        "{:?}",
        acks[2]
    );
    assert!(acks[2].reason.contains("vehicle limit"));
    server.shutdown().await.unwrap();
}

/// An id over the limit is refused, and its acknowledgement echoes it cut at the limit: a client
/// that sends megabytes as an id does not get them back (and the ack queue does not hold them).
#[tokio::test]
async fn an_overlong_id_is_refused_and_echoed_cut_at_the_limit() {
    let server = start(test_config()).await;
    let mut c = client(&server).await;
    let long = "v".repeat(1 << 20);
    let acks = ingest(&mut c, vec![imu_env(&long, 1, vec![imu(1_000_000_000)])])
        .await
        .unwrap();
    let (status, reason) = status_of(&acks, 1);
    assert_eq!(status, pb::IngestStatus::InvalidArgument, "{reason}");
    assert!(reason.contains("longer than 128"), "{reason}");
    assert_eq!(acks[0].vehicle_id, "v".repeat(128));
}
