//! The hostile-input rows of issue 19, each in-process on port 0: the time gate (row 3), the
//! oversize IMU batch's ack (row 4; its memory in `amplification.rs`), image limits and bombs and a
//! corrupt frame body (row 5), bad compressed data (row 8) and implausible configurations (row 9).
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::Duration;

use crate::common::*;
use tonic::codegen::{Body, Service, http};
use uavnav_proto::v1 as pb;

const S: i64 = 1_000_000_000;
/// 200 Hz.
const DT: i64 = 5_000_000;

/// `n` IMU samples at 200 Hz from `t0`, 4 per envelope, sequence numbers from `seq`.
fn stream(id: &str, seq: u64, t0: i64, n: usize) -> Vec<pb::SensorEnvelope> {
    let times: Vec<i64> = (0..n as i64).map(|k| t0 + k * DT).collect();
    times
        .chunks(4)
        .enumerate()
        .map(|(i, c)| imu_env(id, seq + i as u64, c.iter().map(|&t| imu(t)).collect()))
        .collect()
}

/// A config whose clock resynchronisation needs 0.1 s of wall time (0.5 s by default), so that
/// the paced streams below stay short.
fn resync_config() -> uavnavd::Config {
    let mut cfg = test_config();
    cfg.vehicles.clock_resync_s = 0.1;
    cfg
}

/// Sends `envelopes` on one Ingest stream, one every `every` (a stream in real time, or faster),
/// and returns the acks.
async fn ingest_paced(
    server: &uavnavd::RunningServer,
    envelopes: Vec<pb::SensorEnvelope>,
    every: Duration,
) -> Vec<pb::IngestAck> {
    use futures::StreamExt;
    let n = envelopes.len();
    let mut c = client(server).await;
    let paced = futures::stream::iter(envelopes).then(move |e| async move {
        tokio::time::sleep(every).await;
        e
    });
    let mut acks_in = c.ingest(paced).await.unwrap().into_inner();
    let mut acks = Vec::with_capacity(n);
    while let Some(a) = acks_in.message().await.unwrap() {
        acks.push(a);
        if acks.len() == n {
            break;
        }
    }
    acks
}

fn status(a: &pb::IngestAck) -> pb::IngestStatus {
    pb::IngestStatus::try_from(a.status).unwrap()
}

/// Poses published so far (the echo engine makes one per fused IMU sample).
fn poses(server: &uavnavd::RunningServer) -> u64 {
    server.metrics().poses.get()
}

/// Waits until the published poses stop growing and returns their count.
async fn settled_poses(server: &uavnavd::RunningServer) -> u64 {
    let mut last = u64::MAX;
    loop {
        tokio::time::sleep(Duration::from_millis(200)).await;
        let now = poses(server);
        if now == last {
            return now;
        }
        last = now;
    }
}

/// Row 3: three IMU samples stamped 9.9 s ahead of a running stream. Before: the stream's own
/// data then arrived "late" (3,192 of 3,841 poses lost). After: the forged samples are refused
/// and nothing of the stream is lost.
#[tokio::test]
async fn far_future_samples_do_not_make_the_stream_late() {
    let server = start(test_config()).await;
    let mut c = client(&server).await;
    let t0 = 1000 * S;
    let mut envs = stream("v", 1, t0, 2000);
    let at = 250; // after 1000 samples (5 s)
    let t_forged = t0 + 1000 * DT + 9_900_000_000;
    envs.insert(
        at,
        imu_env(
            "v",
            10_000,
            (0..3).map(|k| imu(t_forged + k * DT)).collect(),
        ),
    );
    let acks = ingest(&mut c, envs).await.unwrap();
    let forged = acks.iter().find(|a| a.sequence == 10_000).unwrap();
    assert_eq!(status(forged), pb::IngestStatus::OutOfRange, "{forged:?}");
    let refused: Vec<_> = acks
        .iter()
        .filter(|a| a.sequence != 10_000 && status(a) != pb::IngestStatus::Accepted)
        .collect();
    assert!(
        refused.is_empty(),
        "the stream's own data refused: {refused:?}"
    );
    assert_eq!(
        settled_poses(&server).await,
        2000,
        "every sample of the stream fused"
    );
    server.shutdown().await.unwrap();
}

/// Row 3: one sample at t = i64::MAX before the vehicle starts. Before: 0 poses until eviction.
/// After: the stream's samples are refused until they have come for `clock_resync_s` (and at least
/// `clock_resync_samples` of them), then the vehicle is reset and taken back at the stream's time
/// (counted). The stream comes at 4x real time, 4 samples per 5 ms.
#[tokio::test]
async fn a_first_sample_at_i64_max_is_outvoted_by_the_stream() {
    let cfg = resync_config();
    let server = start(cfg.clone()).await;
    let mut envs = vec![imu_env("v", 1, vec![imu(i64::MAX)])];
    envs.extend(stream("v", 2, 1000 * S, 2000));
    let acks = ingest_paced(&server, envs, Duration::from_millis(5)).await;
    let refused = acks
        .iter()
        .skip(1)
        .filter(|a| status(a) != pb::IngestStatus::Accepted)
        .count();
    // At least `clock_resync_samples` samples (3 envelopes), and 0.1 s of a stream sent 4 samples
    // per 5 ms or slower: at most 21 envelopes (timers run late, not early).
    assert!(
        (3..=21).contains(&refused),
        "{refused} envelopes of the stream refused"
    );
    let n = settled_poses(&server).await;
    eprintln!("i64::MAX first: {n} poses of 2000, {refused} envelopes refused before the resync");
    assert!(n >= 2000 - 4 * 21, "{n} poses of 2000");
    let metrics = server.metrics().encode();
    assert!(
        metrics.contains("uavnav_clock_resyncs_total{direction=\"back\"} 1"),
        "{metrics}"
    );
    server.shutdown().await.unwrap();
}

/// Row 3 / 10: a drone whose clock restarts (it rebooted: its time goes back an hour and runs
/// on). Before: refused as LATE until a reset or eviction. After: taken back, counted. A burst of
/// old data (a client resending what it sent) is refused as LATE and resets nothing.
#[tokio::test]
async fn a_restarted_clock_is_taken_back_but_not_resent_data() {
    // The default `clock_resync_s` (0.5 s) for the burst: its envelopes come within milliseconds.
    let burst = start(test_config()).await;
    let mut envs = stream("v", 1, 3600 * S, 1000);
    // Resent, in a burst: the first 500 samples again.
    envs.extend(stream("v", 500, 3600 * S, 500));
    envs.extend(stream("v", 1000, 3600 * S + 1000 * DT, 1000));
    let mut c = client(&burst).await;
    let acks = ingest(&mut c, envs).await.unwrap();
    let late = acks
        .iter()
        .filter(|a| status(a) == pb::IngestStatus::Late)
        .count();
    assert_eq!(late, 125, "the resent envelopes, and only them");
    assert_eq!(settled_poses(&burst).await, 2000);
    let h = burst.registry().get("v").unwrap();
    assert_eq!(
        uavnavd::vehicle::VehicleStats::get(&h.shared.stats.resyncs),
        0
    );
    burst.shutdown().await.unwrap();

    let server = start(resync_config()).await;
    let mut c = client(&server).await;
    let acks = ingest(&mut c, stream("v", 1, 3600 * S, 2000))
        .await
        .unwrap();
    assert!(acks.iter().all(|a| status(a) == pb::IngestStatus::Accepted));
    let h = server.registry().get("v").unwrap();
    let resyncs = || uavnavd::vehicle::VehicleStats::get(&h.shared.stats.resyncs);
    // The reboot: the clock starts again at 10 s, in (4x) real time.
    let acks = ingest_paced(
        &server,
        stream("v", 5000, 10 * S, 1000),
        Duration::from_millis(5),
    )
    .await;
    let late = acks
        .iter()
        .filter(|a| status(a) != pb::IngestStatus::Accepted)
        .count();
    assert!((3..=21).contains(&late), "{late} envelopes refused");
    assert_eq!(resyncs(), 1);
    // Lost: the new stream's first 0.1 s, and the old stream's last reorder window (20 ms, 4
    // samples), dropped with the old stream at the reset.
    let n = settled_poses(&server).await;
    eprintln!("restarted clock: {n} poses of 3000, {late} envelopes refused before the resync");
    assert!(n >= 3000 - 4 * 21 - 4, "{n} poses of 3000");
    server.shutdown().await.unwrap();
}

/// Row 4 (the ack; the memory is measured in `amplification.rs`): an IMU batch above the limit is
/// refused in its ack, with the reason counted, and the stream goes on.
#[tokio::test]
async fn an_oversize_imu_batch_is_refused_in_its_ack_and_counted() {
    let server = start(test_config()).await;
    let mut c = client(&server).await;
    let big = (0..20_000).map(|k| imu(S + k * DT)).collect();
    let acks = ingest(
        &mut c,
        vec![
            imu_env("v", 1, big),
            imu_env("v", 2, vec![imu(S), imu(S + DT)]),
        ],
    )
    .await
    .unwrap();
    assert_eq!(status(&acks[0]), pb::IngestStatus::ResourceExhausted);
    assert!(acks[0].reason.contains("more than 10000"), "{acks:?}");
    assert_eq!(status(&acks[1]), pb::IngestStatus::Accepted, "{acks:?}");
    let metrics = server.metrics().encode();
    assert!(
        metrics.contains(
            "uavnav_inputs_refused_total{transport=\"grpc\",kind=\"imu\",reason=\"too_large\"} 1"
        ),
        "{metrics}"
    );
    server.shutdown().await.unwrap();
}

/// A configuration refused with the field named.
async fn refused_config(server: &uavnavd::RunningServer, config: pb::VehicleConfig) -> String {
    let mut c = client(server).await;
    let st = c
        .configure_vehicle(pb::ConfigureVehicleRequest {
            vehicle_id: "v".into(),
            config: Some(config),
        })
        .await
        .unwrap_err();
    assert_eq!(st.code(), tonic::Code::InvalidArgument, "{st:?}");
    st.message().to_owned()
}

/// Row 5: a camera above the service's maximum resolution is refused at configuration, naming
/// the limit's key; frames whose header announces another size are refused before any decoding
/// (a PNG bomb: a small file announcing a huge image).
#[tokio::test]
async fn cameras_and_images_above_the_limits_are_refused_by_their_header() {
    let server = start(test_config()).await;
    let mut cfg = vehicle_config(true);
    let cam = cfg.camera.as_mut().unwrap();
    (cam.width_px, cam.height_px) = (8192, 8192);
    (cam.cx_px, cam.cy_px) = (4096.0, 4096.0);
    let msg = refused_config(&server, cfg).await;
    assert!(msg.contains("config.camera"), "{msg}");
    assert!(msg.contains("vision.max_camera_width_px"), "{msg}");
    let cam = cfg.camera.as_mut().unwrap();
    (cam.width_px, cam.height_px) = (4096, 2048); // within each side, above the pixels
    (cam.cx_px, cam.cy_px) = (2048.0, 1024.0);
    let msg = refused_config(&server, cfg).await;
    assert!(msg.contains("vision.max_camera_pixels"), "{msg}");

    // A 640x480 camera; PNG frames announcing 8192x8192 (a bomb's header) and a bad IHDR.
    let mut c = client(&server).await;
    let png = |w: u32, h: u32, depth: u8, colour: u8| {
        let mut d = vec![
            0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1A, b'\n', 0, 0, 0, 13,
        ];
        d.extend(b"IHDR");
        d.extend(w.to_be_bytes());
        d.extend(h.to_be_bytes());
        d.extend([depth, colour, 0, 0, 0, 0, 0, 0, 0]);
        d.resize(600, 0);
        d
    };
    let frame = |seq, t, data: Vec<u8>| {
        let mut e = camera_env("v", seq, t, data);
        if let Some(pb::sensor_envelope::Payload::Camera(f)) = e.payload.as_mut() {
            f.image.as_mut().unwrap().format = "png".into();
        }
        e
    };
    let acks = ingest(
        &mut c,
        vec![
            config_env("v", 1, true),
            imu_env("v", 2, vec![imu(S)]),
            frame(3, S + DT, png(8192, 8192, 16, 6)),
            frame(4, S + 2 * DT, png(640, 480, 16, 3)),
            frame(5, S + 3 * DT, png(640, 480, 8, 0)),
        ],
    )
    .await
    .unwrap();
    let (a3, a4, a5) = (&acks[2], &acks[3], &acks[4]);
    assert_eq!(status(a3), pb::IngestStatus::ResourceExhausted, "{a3:?}");
    assert!(a3.reason.contains("vision.max_camera_width_px"), "{a3:?}");
    assert_eq!(status(a4), pb::IngestStatus::InvalidArgument, "{a4:?}");
    assert!(a4.reason.contains("corrupt png header"), "{a4:?}");
    assert_eq!(status(a5), pb::IngestStatus::Accepted, "{a5:?}");
    let metrics = server.metrics().encode();
    assert!(
        metrics.contains(
            "uavnav_inputs_refused_total{transport=\"grpc\",kind=\"camera\",reason=\"too_large\"} 1"
        ),
        "{metrics}"
    );
    server.shutdown().await.unwrap();
}

/// Row 5: the cameras of all vehicles together fit `vision.max_total_camera_pixels` (the global
/// bound of the vision front ends' memory): one camera too many is refused, and a vehicle that
/// drops its camera, or is evicted, gives its pixels back.
#[tokio::test]
async fn the_cameras_of_all_vehicles_share_one_pixel_budget() {
    let mut config = test_config();
    config.vision.max_total_camera_pixels = 2 * 640 * 480;
    config.vision.max_camera_pixels = 640 * 480;
    config.vehicles.idle_evict_s = 0.3;
    let server = start(config).await;
    let mut c = client(&server).await;
    let configure = |id: &str, camera: bool| pb::ConfigureVehicleRequest {
        vehicle_id: id.into(),
        config: Some(vehicle_config(camera)),
    };
    c.configure_vehicle(configure("a", true)).await.unwrap();
    c.configure_vehicle(configure("b", true)).await.unwrap();
    // The same configuration again costs nothing more.
    c.configure_vehicle(configure("b", true)).await.unwrap();
    let st = c.configure_vehicle(configure("c", true)).await.unwrap_err();
    assert_eq!(st.code(), tonic::Code::ResourceExhausted, "{st:?}");
    assert!(
        st.message().contains("vision.max_total_camera_pixels"),
        "{st:?}"
    );
    assert!(
        server.registry().get("c").is_none(),
        "the refused vehicle was created"
    );
    // Without a camera, c fits; a drops its camera and c gets one.
    c.configure_vehicle(configure("c", false)).await.unwrap();
    c.configure_vehicle(configure("a", false)).await.unwrap();
    c.configure_vehicle(configure("c", true)).await.unwrap();
    // An evicted vehicle gives its pixels back.
    assert!(
        eventually(std::time::Duration::from_secs(10), || server
            .registry()
            .get("b")
            .is_none())
        .await
    );
    c.configure_vehicle(configure("d", true)).await.unwrap();
    server.shutdown().await.unwrap();
}

/// Row 5 / 8: a JPEG whose header is good but whose body does not decode. Before: acknowledged
/// ACCEPTED and counted nowhere. After: still ACCEPTED (the decode runs after the ack), then
/// counted in the vehicle's health (`rejected`) and in `/metrics` with the reason. Runs the
/// product engine (the real vision front end).
#[tokio::test]
async fn a_corrupt_frame_body_is_counted_with_its_reason() {
    let server = uavnavd::Server::start(test_config()).await.unwrap();
    let mut c = client(&server).await;
    let acks = ingest(
        &mut c,
        vec![
            config_env("v", 1, true),
            imu_env("v", 2, vec![imu(S), imu(S + DT)]),
            camera_env("v", 3, S + 2 * DT, camera_jpeg_header()),
            imu_env("v", 4, (3..60).map(|k| imu(S + k * DT)).collect()),
        ],
    )
    .await
    .unwrap();
    assert!(
        acks.iter().all(|a| status(a) == pb::IngestStatus::Accepted),
        "{acks:?}"
    );
    let metrics = server.metrics().clone();
    assert!(
        eventually(Duration::from_secs(10), || metrics.encode().contains(
            "uavnav_vision_frames_rejected_total{reason=\"corrupt_image\"} 1"
        ))
        .await,
        "{}",
        metrics.encode()
    );
    let reg = server.registry().clone();
    assert!(
        eventually(Duration::from_secs(3), || {
            reg.get("v")
                .and_then(|h| h.shared.health())
                .and_then(|h| h.counters)
                .is_some_and(|k| k.rejected == 1)
        })
        .await
    );
    server.shutdown().await.unwrap();
}

/// Sends one raw HTTP/2 gRPC request (headers and a body of gRPC frames as given) and returns
/// the final `grpc-status` and `grpc-message`.
async fn raw_request(
    server: &uavnavd::RunningServer,
    path: &str,
    encoding: &str,
    body: Vec<u8>,
) -> (String, String) {
    let mut channel =
        tonic::transport::Endpoint::from_shared(format!("http://{}", server.grpc_addr))
            .unwrap()
            .connect()
            .await
            .unwrap();
    let req = http::Request::builder()
        .method("POST")
        .uri(format!("http://{}{path}", server.grpc_addr))
        .header("content-type", "application/grpc")
        .header("te", "trailers")
        .header("grpc-encoding", encoding)
        .body(tonic::body::Body::new(String::from_utf8(body).unwrap()))
        .unwrap();
    std::future::poll_fn(|cx| channel.poll_ready(cx))
        .await
        .unwrap();
    let resp = channel.call(req).await.unwrap();
    let grpc = |h: &http::HeaderMap| {
        h.get("grpc-status").map(|s| {
            let m = h
                .get("grpc-message")
                .map(|m| m.to_str().unwrap().to_owned())
                .unwrap_or_default();
            (s.to_str().unwrap().to_owned(), m)
        })
    };
    if let Some(s) = grpc(resp.headers()) {
        return s;
    }
    let mut body = resp.into_body();
    loop {
        let frame = std::future::poll_fn(|cx| std::pin::Pin::new(&mut body).poll_frame(cx))
            .await
            .expect("trailers")
            .unwrap();
        if let Some(s) = frame.trailers_ref().and_then(grpc) {
            return s;
        }
    }
}

/// One gRPC frame marked compressed, whose bytes are not gzip.
fn bad_gzip_frame() -> Vec<u8> {
    let junk = b"this is not gzip data at all";
    let mut f = vec![1];
    f.extend((junk.len() as u32).to_be_bytes());
    f.extend(junk);
    f
}

/// Row 8: bad compressed data. Before: INTERNAL. After: INVALID_ARGUMENT, counted by reason, on
/// the Ingest stream and on a unary call.
#[tokio::test]
async fn bad_gzip_is_invalid_argument_and_counted() {
    let server = start(test_config()).await;
    let (code, msg) = raw_request(
        &server,
        "/uavnav.v1.UavNav/Ingest",
        "gzip",
        bad_gzip_frame(),
    )
    .await;
    assert_eq!(code, "3", "{msg}");
    let (code, msg) = raw_request(
        &server,
        "/uavnav.v1.UavNav/GetPose",
        "gzip",
        bad_gzip_frame(),
    )
    .await;
    assert_eq!(code, "3", "{msg}");
    let metrics = server.metrics().encode();
    assert!(
        metrics.contains(
            "uavnav_inputs_refused_total{transport=\"grpc\",kind=\"malformed\",reason=\"compression\"} 1"
        ),
        "{metrics}"
    );
    server.shutdown().await.unwrap();
}

/// Row 8: an oversize message ends the stream with RESOURCE_EXHAUSTED (tonic: OUT_OF_RANGE), and
/// is now counted in `/metrics` too.
#[tokio::test]
async fn an_oversize_message_is_counted() {
    let server = start(test_config()).await;
    // A frame header announcing 17 MiB (the limit is 16 MiB): refused as soon as it is read.
    let mut frame = vec![0];
    frame.extend((17u32 << 20).to_be_bytes());
    frame.extend(b"0123456789");
    let (code, msg) = raw_request(&server, "/uavnav.v1.UavNav/Ingest", "identity", frame).await;
    assert_eq!(code, "8", "{msg}");
    let metrics = server.metrics().encode();
    assert!(
        metrics.contains(
            "uavnav_inputs_refused_total{transport=\"grpc\",kind=\"malformed\",reason=\"too_large\"} 1"
        ),
        "{metrics}"
    );
    server.shutdown().await.unwrap();
}

/// A watch selecting more vehicle ids than the limit is refused before the ids are decoded (an
/// empty id is 2 bytes on the wire, 24 decoded).
#[tokio::test]
async fn a_watch_of_too_many_ids_is_refused() {
    let server = start(test_config()).await;
    let mut c = client(&server).await;
    let st = c
        .watch_poses(pb::WatchRequest {
            vehicle_ids: vec![String::new(); 10_001],
            ..Default::default()
        })
        .await
        .unwrap_err();
    assert_eq!(st.code(), tonic::Code::InvalidArgument, "{st:?}");
    assert!(st.message().contains("vehicle_ids: 10001 ids"), "{st:?}");
    server.shutdown().await.unwrap();
}

/// A change that spoils a configuration.
type Spoil = Box<dyn Fn(&mut pb::VehicleConfig)>;

/// Row 9: implausible configurations are refused with the field named. Before: a lever arm or a
/// noise density of 1e300 was accepted and the vehicle's poses had a NaN latitude and σ = 0.
#[tokio::test]
async fn implausible_configurations_name_the_field() {
    let server = start(test_config()).await;
    let cases: Vec<(&str, Spoil)> = vec![
        (
            "config.gnss.lever_arm_body_m.x",
            Box::new(|c| {
                c.gnss
                    .as_mut()
                    .unwrap()
                    .lever_arm_body_m
                    .as_mut()
                    .unwrap()
                    .x = 1e300
            }),
        ),
        (
            "config.imu.gyro_noise_density",
            Box::new(|c| c.imu.as_mut().unwrap().gyro_noise_density = 1e300),
        ),
        (
            "config.imu.accel_random_walk",
            Box::new(|c| c.imu.as_mut().unwrap().accel_random_walk = 50.0),
        ),
        (
            "config.imu.rate_hz",
            Box::new(|c| c.imu.as_mut().unwrap().rate_hz = 1e-300),
        ),
        (
            "config.imu.gyro_bias_sigma_radps",
            Box::new(|c| c.imu.as_mut().unwrap().gyro_bias_sigma_radps = -1e-3),
        ),
        (
            "config.imu.accel_bias_sigma_mps2",
            Box::new(|c| c.imu.as_mut().unwrap().accel_bias_sigma_mps2 = f64::NAN),
        ),
        (
            "config.gnss.rate_hz",
            Box::new(|c| c.gnss.as_mut().unwrap().rate_hz = 1e9),
        ),
        (
            "config.camera.fx_px",
            Box::new(|c| c.camera.as_mut().unwrap().fx_px = 1e-300),
        ),
        (
            "config.camera.cx_px",
            Box::new(|c| c.camera.as_mut().unwrap().cx_px = 1e5),
        ),
        (
            "config.camera.k1",
            Box::new(|c| {
                let cam = c.camera.as_mut().unwrap();
                cam.distortion_model = pb::DistortionModel::RadialTangential as i32;
                cam.k1 = 1e300;
            }),
        ),
        (
            "config.camera.body_from_cam.translation_m.z",
            Box::new(|c| {
                let cam = c.camera.as_mut().unwrap();
                let t = cam.body_from_cam.as_mut().unwrap();
                t.translation_m.as_mut().unwrap().z = -1e6;
            }),
        ),
        (
            "config.gnss.delay_s",
            Box::new(|c| c.gnss.as_mut().unwrap().delay_s = 1e300),
        ),
    ];
    for (field, spoil) in cases {
        let mut cfg = vehicle_config(true);
        spoil(&mut cfg);
        let msg = refused_config(&server, cfg).await;
        assert!(msg.starts_with(field), "{field}: {msg}");
    }
    // Also on the Ingest stream, where a refusal is an ack, counted by reason.
    let mut cfg = vehicle_config(false);
    cfg.gnss
        .as_mut()
        .unwrap()
        .lever_arm_body_m
        .as_mut()
        .unwrap()
        .y = -1e300;
    let env = pb::SensorEnvelope {
        vehicle_id: "w".into(),
        sequence: 1,
        payload: Some(pb::sensor_envelope::Payload::Config(cfg)),
    };
    let mut c = client(&server).await;
    let acks = ingest(&mut c, vec![env]).await.unwrap();
    assert_eq!(status(&acks[0]), pb::IngestStatus::InvalidArgument);
    assert!(
        acks[0].reason.starts_with("config.gnss.lever_arm_body_m.y"),
        "{acks:?}"
    );
    assert!(server.registry().get("w").is_none(), "no vehicle made");
    let metrics = server.metrics().encode();
    assert!(
        metrics.contains(
            "uavnav_inputs_refused_total{transport=\"grpc\",kind=\"config\",reason=\"out_of_range\"} 1"
        ),
        "{metrics}"
    );
    server.shutdown().await.unwrap();
}
