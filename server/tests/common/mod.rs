//! Shared test helpers: an in-process server on port 0, a scripted engine, message builders.
//!
//! The scripted engine is test-only plumbing: it emits one pose per IMU sample at the latest GNSS
//! position, so transport tests can check routing, ordering and counting without the estimator.
#![allow(dead_code)]

use std::sync::Arc;
use std::time::Duration;

use uavnav_core::{GnssFix, SensorEvent, VehicleConfig};
use uavnav_proto::v1 as pb;
use uavnav_proto::v1::uav_nav_client::UavNavClient;
use uavnavd::engine::{
    BoxedEngine, Engine, EngineError, EngineFactory, EngineHealth, EngineStep, boxed,
};
use uavnavd::{Config, RunningServer, Server};

/// What echo engines were given, shared with the test that made their factory.
#[derive(Debug, Default)]
pub struct Seen {
    /// Magnetometer samples, in the order the engines got them.
    pub mag: std::sync::Mutex<Vec<uavnav_core::MagSample>>,
    /// Barometer samples.
    pub baro: std::sync::Mutex<Vec<uavnav_core::BaroSample>>,
    /// GNSS fixes.
    pub gnss: std::sync::Mutex<Vec<GnssFix>>,
}

/// Emits a pose per IMU sample (position = last GNSS fix), runs a trivial vision job per frame.
/// (Unlike the real runner it does not hold inputs behind a vision job.)
#[derive(Debug, Default)]
pub struct EchoEngine {
    last_fix: Option<GnssFix>,
    frames: u32,
    t_ns: i64,
    seen: Option<Arc<Seen>>,
}

impl Engine for EchoEngine {
    /// The frame's time.
    type Vision = i64;

    fn push(&mut self, event: SensorEvent) -> Result<EngineStep<i64>, EngineError> {
        let mut step = EngineStep::default();
        match event {
            SensorEvent::Imu(s) => {
                self.t_ns = s.t_ns;
                let position = self.last_fix.map(|f| pb::GeodeticPosition {
                    latitude_deg: f.lat_deg,
                    longitude_deg: f.lon_deg,
                    altitude_m: f.alt_m,
                });
                let mode = self.mode();
                step.poses.push(uavnavd::hub::Pose {
                    t_ns: s.t_ns,
                    position,
                    nav_from_body: Some(pb::Quaternion {
                        w: 1.0,
                        ..Default::default()
                    }),
                    mode,
                    ..Default::default()
                });
            }
            SensorEvent::Gnss(f) => {
                self.last_fix = Some(f);
                if let Some(seen) = &self.seen {
                    seen.gnss.lock().unwrap().push(f);
                }
            }
            SensorEvent::Mag(m) => {
                if let Some(seen) = &self.seen {
                    seen.mag.lock().unwrap().push(m);
                }
            }
            SensorEvent::Baro(b) => {
                if let Some(seen) = &self.seen {
                    seen.baro.lock().unwrap().push(b);
                }
            }
            SensorEvent::Camera(frame) => {
                let t_ns = frame.t_ns;
                step.work = Some(Box::new(move || {
                    std::thread::sleep(Duration::from_millis(2));
                    t_ns
                }));
            }
        }
        Ok(step)
    }

    fn finish_frame(&mut self, _t_ns: i64) -> EngineStep<i64> {
        self.frames += 1;
        EngineStep::default()
    }

    fn health(&self) -> EngineHealth {
        EngineHealth {
            mode: self.mode(),
            t_ns: self.t_ns,
            vision: (self.frames > 0).then_some(pb::VisionQuality {
                tracked: self.frames,
                ..Default::default()
            }),
            ..EngineHealth::default()
        }
    }

    fn reset(&mut self) {
        *self = Self {
            seen: self.seen.take(),
            ..Self::default()
        };
    }
}

impl EchoEngine {
    fn mode(&self) -> pb::EstimatorMode {
        if self.last_fix.is_some() {
            pb::EstimatorMode::Nominal
        } else {
            pb::EstimatorMode::Initialising
        }
    }
}

/// Builds [`EchoEngine`]s.
#[derive(Debug)]
pub struct EchoFactory;

impl EngineFactory for EchoFactory {
    fn create(&self, _config: &VehicleConfig) -> BoxedEngine {
        boxed(EchoEngine::default())
    }
}

/// Builds [`EchoEngine`]s that report what they were given to one [`Seen`].
#[derive(Debug, Default)]
pub struct SeeingFactory(pub Arc<Seen>);

impl EngineFactory for SeeingFactory {
    fn create(&self, _config: &VehicleConfig) -> BoxedEngine {
        boxed(EchoEngine {
            seen: Some(Arc::clone(&self.0)),
            ..EchoEngine::default()
        })
    }
}

/// A config for tests: loopback, port 0, no Zenoh (the kit's), fast health.
pub fn test_config() -> Config {
    let mut c = uavnav_tests::service::loopback_config();
    c.health.period_ms = 100;
    c.vision.workers = 1;
    c
}

/// Starts the service with the echo engine.
pub async fn start(config: Config) -> RunningServer {
    Server::start_with(config, Arc::new(EchoFactory))
        .await
        .unwrap()
}

/// A gRPC client of the server.
pub async fn client(server: &RunningServer) -> UavNavClient<tonic::transport::Channel> {
    UavNavClient::connect(format!("http://{}", server.grpc_addr))
        .await
        .unwrap()
        .max_decoding_message_size(64 << 20)
        .max_encoding_message_size(64 << 20)
}

#[allow(unused_imports)] // each test binary uses a different part
pub use uavnav_tests::flight::sim_flight;
#[allow(unused_imports)]
pub use uavnav_tests::net::eventually;
#[allow(unused_imports)]
pub use uavnav_tests::service::listen_zenoh;
#[allow(unused_imports)]
pub use uavnav_tests::wire::*;

/// Sends `envelopes` on one Ingest stream and returns the acks (or the stream's final status).
pub async fn ingest(
    client: &mut UavNavClient<tonic::transport::Channel>,
    envelopes: Vec<pb::SensorEnvelope>,
) -> Result<Vec<pb::IngestAck>, tonic::Status> {
    let n = envelopes.len();
    let mut stream = client
        .ingest(futures::stream::iter(envelopes))
        .await?
        .into_inner();
    let mut acks = Vec::with_capacity(n);
    while let Some(ack) = stream.message().await? {
        acks.push(ack);
        if acks.len() == n {
            break;
        }
    }
    Ok(acks)
}

/// The offline estimate of `events` (the runner inline, as `uavnav estimate` runs it), as wire poses.
pub fn offline_poses(config: &VehicleConfig, events: &[SensorEvent]) -> Vec<pb::PoseEstimate> {
    let mut runner = uavnav_runner::VehicleRunner::new(
        config.clone(),
        uavnav_runner::RunnerParams::default(),
        None,
    );
    let mut poses = Vec::new();
    for e in events {
        if let Ok(p) = runner.push_inline(e.clone()) {
            poses.extend(p.iter().map(uavnavd::runner_engine::pose_to_wire));
        }
    }
    poses
}

/// A codec that sends raw encoded bytes (malformed protobuf, hand-built oversize batches: the
/// client allocates nothing per sample) and decodes the replies as Ingest acks.
#[derive(Debug, Clone, Default)]
pub struct RawCodec;
#[derive(Debug)]
pub struct RawEncoder;
#[derive(Debug)]
pub struct AckDecoder;

impl tonic::codec::Codec for RawCodec {
    type Encode = Vec<u8>;
    type Decode = pb::IngestAck;
    type Encoder = RawEncoder;
    type Decoder = AckDecoder;
    fn encoder(&mut self) -> RawEncoder {
        RawEncoder
    }
    fn decoder(&mut self) -> AckDecoder {
        AckDecoder
    }
}

impl tonic::codec::Encoder for RawEncoder {
    type Item = Vec<u8>;
    type Error = tonic::Status;
    fn encode(
        &mut self,
        item: Vec<u8>,
        dst: &mut tonic::codec::EncodeBuf<'_>,
    ) -> Result<(), tonic::Status> {
        use bytes::BufMut;
        dst.put_slice(&item);
        Ok(())
    }
}

impl tonic::codec::Decoder for AckDecoder {
    type Item = pb::IngestAck;
    type Error = tonic::Status;
    fn decode(
        &mut self,
        src: &mut tonic::codec::DecodeBuf<'_>,
    ) -> Result<Option<pb::IngestAck>, tonic::Status> {
        <pb::IngestAck as prost::Message>::decode(src)
            .map(Some)
            .map_err(|e| tonic::Status::internal(e.to_string()))
    }
}

/// A raw gRPC client of `server`: encoded bodies in, acks out (with [`RawCodec`]), messages up to
/// 64 MiB, so that oversize and malformed bodies reach the service as they are.
pub async fn raw_grpc(server: &RunningServer) -> tonic::client::Grpc<tonic::transport::Channel> {
    let channel = tonic::transport::Endpoint::from_shared(format!("http://{}", server.grpc_addr))
        .unwrap()
        .connect()
        .await
        .unwrap();
    let mut grpc = tonic::client::Grpc::new(channel).max_encoding_message_size(64 << 20);
    grpc.ready().await.unwrap();
    grpc
}

/// The first ack of an `Ingest` stream carrying `body` (an encoded envelope), if any.
pub async fn raw_first_ack(server: &RunningServer, body: Vec<u8>) -> Option<pb::IngestAck> {
    let mut grpc = raw_grpc(server).await;
    let path = tonic::codegen::http::uri::PathAndQuery::from_static("/uavnav.v1.UavNav/Ingest");
    let request = tonic::Request::new(futures::stream::iter(vec![body]));
    let resp = grpc.streaming(request, path, RawCodec).await.ok()?;
    resp.into_inner().message().await.ok().flatten()
}

/// A Zenoh peer session that connects to `connect` only (no listener, no multicast scouting), so
/// parallel tests never meet.
pub async fn zenoh_peer(connect: &str) -> zenoh::Session {
    let mut c = zenoh::Config::default();
    c.insert_json5("mode", "\"peer\"").unwrap();
    c.insert_json5("listen/endpoints", "[]").unwrap();
    c.insert_json5("connect/endpoints", &format!("[\"{connect}\"]"))
        .unwrap();
    c.insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    zenoh::open(c).await.unwrap()
}

/// A raw HTTP/2 connection whose `WatchPoses` streams (all vehicles) the service has answered,
/// held without reading its socket any more: a peer that stops reading. Its windows are
/// 2³¹ − 1 bytes, so flow control never holds the service back; the service's own buffers do.
/// Dropping it closes the connection.
pub struct StalledWatch {
    _client: h2::client::SendRequest<bytes::Bytes>,
    _conn: h2::client::Connection<tokio::net::TcpStream, bytes::Bytes>,
    bodies: Vec<h2::RecvStream>,
}

impl StalledWatch {
    /// The streams the service answered.
    pub fn streams(&self) -> usize {
        self.bodies.len()
    }
}

/// Opens `streams` `WatchPoses` streams on one new connection to `addr` and stops reading once
/// they are answered (`None` if the connection failed).
pub async fn stalled_watch(addr: std::net::SocketAddr, streams: u32) -> Option<StalledWatch> {
    use prost::Message as _;
    let request = pb::WatchRequest {
        all: true,
        ..Default::default()
    }
    .encode_to_vec();
    let mut body = vec![0u8];
    body.extend_from_slice(&(request.len() as u32).to_be_bytes());
    body.extend_from_slice(&request);
    let body = bytes::Bytes::from(body);
    let tcp = tokio::net::TcpStream::connect(addr).await.ok()?;
    let (mut h2c, conn) = h2::client::Builder::new()
        .initial_window_size(i32::MAX as u32)
        .initial_connection_window_size(i32::MAX as u32)
        .handshake::<_, bytes::Bytes>(tcp)
        .await
        .ok()?;
    // Polled until the service has answered every stream, then held without polling.
    let (freeze, frozen) = tokio::sync::oneshot::channel::<()>();
    let driver = tokio::spawn(async move {
        let mut conn = conn;
        tokio::select! {
            _ = &mut conn => None,
            _ = frozen => Some(conn),
        }
    });
    let mut responses = Vec::new();
    for _ in 0..streams {
        let req = tonic::codegen::http::Request::builder()
            .method("POST")
            .uri(format!("http://{addr}/uavnav.v1.UavNav/WatchPoses"))
            .header("content-type", "application/grpc")
            .header("te", "trailers")
            .body(())
            .ok()?;
        h2c = h2c.clone().ready().await.ok()?;
        let (resp, mut send) = h2c.send_request(req, false).ok()?;
        let _ = send.send_data(body.clone(), true);
        responses.push(resp);
    }
    let mut bodies = Vec::new();
    for r in responses {
        if let Ok(Ok(resp)) = tokio::time::timeout(Duration::from_secs(5), r).await {
            bodies.push(resp.into_body());
        }
    }
    let _ = freeze.send(());
    let conn = driver.await.ok().flatten()?;
    Some(StalledWatch {
        _client: h2c,
        _conn: conn,
        bodies,
    })
}
