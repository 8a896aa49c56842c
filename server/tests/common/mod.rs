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
use uavnavd::engine::{Engine, EngineError, EngineFactory, EngineHealth, EngineStep, VisionResult};
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
    fn push(&mut self, event: SensorEvent) -> Result<EngineStep, EngineError> {
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
                    Box::new(t_ns) as VisionResult
                }));
            }
        }
        Ok(step)
    }

    fn finish_frame(&mut self, done: VisionResult) -> EngineStep {
        if done.downcast::<i64>().is_ok() {
            self.frames += 1;
        }
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
    fn create(&self, _config: &VehicleConfig) -> Box<dyn Engine> {
        Box::new(EchoEngine::default())
    }
}

/// Builds [`EchoEngine`]s that report what they were given to one [`Seen`].
#[derive(Debug, Default)]
pub struct SeeingFactory(pub Arc<Seen>);

impl EngineFactory for SeeingFactory {
    fn create(&self, _config: &VehicleConfig) -> Box<dyn Engine> {
        Box::new(EchoEngine {
            seen: Some(Arc::clone(&self.0)),
            ..EchoEngine::default()
        })
    }
}

/// A config for tests: loopback, port 0, no Zenoh, fast health.
pub fn test_config() -> Config {
    let mut c = Config::default();
    c.grpc.addr = "127.0.0.1:0".parse().unwrap();
    c.http.addr = "127.0.0.1:0".parse().unwrap();
    c.zenoh.enabled = false;
    c.zenoh.multicast_scouting = false;
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

/// A level IMU sample at `t_ns`.
pub fn imu(t_ns: i64) -> pb::ImuSample {
    pb::ImuSample {
        t_ns,
        accel_z_mps2: -9.81,
        ..Default::default()
    }
}

/// An IMU envelope.
pub fn imu_env(id: &str, seq: u64, samples: Vec<pb::ImuSample>) -> pb::SensorEnvelope {
    pb::SensorEnvelope {
        vehicle_id: id.into(),
        sequence: seq,
        payload: Some(pb::sensor_envelope::Payload::Imu(pb::ImuBatch { samples })),
    }
}

/// A plausible GNSS fix.
pub fn fix(t_ns: i64) -> pb::GnssFix {
    pb::GnssFix {
        t_ns,
        latitude_deg: 45.0,
        longitude_deg: 7.0,
        altitude_m: 300.0,
        sigma_horizontal_m: 1.0,
        sigma_vertical_m: 2.0,
        vel_north_mps: Some(0.0),
        vel_east_mps: Some(0.0),
        vel_down_mps: Some(0.0),
        sigma_velocity_mps: Some(0.1),
        fix_type: pb::FixType::Fix3d as i32,
        num_satellites: 10,
    }
}

/// A GNSS envelope.
pub fn gnss_env(id: &str, seq: u64, f: pb::GnssFix) -> pb::SensorEnvelope {
    pb::SensorEnvelope {
        vehicle_id: id.into(),
        sequence: seq,
        payload: Some(pb::sensor_envelope::Payload::Gnss(f)),
    }
}

/// A vehicle configuration, with a 640x480 camera when `camera`.
pub fn vehicle_config(camera: bool) -> pb::VehicleConfig {
    pb::VehicleConfig {
        imu: Some(pb::ImuConfig {
            rate_hz: 200.0,
            gyro_noise_density: 1e-4,
            gyro_random_walk: 2e-6,
            accel_noise_density: 1e-3,
            accel_random_walk: 1e-4,
        }),
        gnss: Some(pb::GnssConfig {
            rate_hz: 5.0,
            lever_arm_body_m: Some(pb::Vector3::default()),
            ..Default::default()
        }),
        camera: camera.then(|| pb::CameraConfig {
            camera_id: 0,
            rate_hz: 10.0,
            width_px: 640,
            height_px: 480,
            fx_px: 500.0,
            fy_px: 500.0,
            cx_px: 320.0,
            cy_px: 240.0,
            distortion_model: pb::DistortionModel::None as i32,
            body_from_cam: Some(pb::RigidTransform {
                rotation: Some(pb::Quaternion {
                    w: 1.0,
                    ..Default::default()
                }),
                translation_m: Some(pb::Vector3::default()),
            }),
            ..Default::default()
        }),
        terrain_elevation_m: 0.0,
        profile: pb::FilterProfile::Eskf as i32,
        mag: None,
        baro: None,
        // the service tests feed the simulator's fixed-wing flights
        airframe: pb::Airframe::FixedWing as i32,
    }
}

/// A magnetometer sample (a mid-latitude Earth field, tesla).
pub fn mag(t_ns: i64) -> pb::MagSample {
    pb::MagSample {
        t_ns,
        field_x_t: 2.2e-5,
        field_y_t: 0.1e-5,
        field_z_t: 4.1e-5,
    }
}

/// A barometer sample.
pub fn baro(t_ns: i64) -> pb::BaroSample {
    pb::BaroSample {
        t_ns,
        pressure_pa: 97_700.0,
        temperature_degc: Some(21.5),
    }
}

/// A magnetometer envelope.
pub fn mag_env(id: &str, seq: u64, m: pb::MagSample) -> pb::SensorEnvelope {
    pb::SensorEnvelope {
        vehicle_id: id.into(),
        sequence: seq,
        payload: Some(pb::sensor_envelope::Payload::Mag(m)),
    }
}

/// A barometer envelope.
pub fn baro_env(id: &str, seq: u64, b: pb::BaroSample) -> pb::SensorEnvelope {
    pb::SensorEnvelope {
        vehicle_id: id.into(),
        sequence: seq,
        payload: Some(pb::sensor_envelope::Payload::Baro(b)),
    }
}

/// A config envelope.
pub fn config_env(id: &str, seq: u64, camera: bool) -> pb::SensorEnvelope {
    pb::SensorEnvelope {
        vehicle_id: id.into(),
        sequence: seq,
        payload: Some(pb::sensor_envelope::Payload::Config(vehicle_config(camera))),
    }
}

/// A minimal JPEG header (SOI + SOF0 with the given size + EOI): enough for header validation.
pub fn jpeg_header(width: u16, height: u16) -> Vec<u8> {
    let mut d = vec![0xFF, 0xD8, 0xFF, 0xC0, 0x00, 0x0B, 8];
    d.extend(height.to_be_bytes());
    d.extend(width.to_be_bytes());
    d.extend([1, 1, 0x11, 0, 0xFF, 0xD9]);
    d
}

/// A camera envelope carrying `data` as JPEG.
pub fn camera_env(id: &str, seq: u64, t_ns: i64, data: Vec<u8>) -> pb::SensorEnvelope {
    pb::SensorEnvelope {
        vehicle_id: id.into(),
        sequence: seq,
        payload: Some(pb::sensor_envelope::Payload::Camera(pb::CameraFrame {
            t_ns,
            camera_id: 0,
            image: Some(foxglove::messages::CompressedImage {
                timestamp: None,
                frame_id: "cam0".into(),
                data: data.into(),
                format: "jpeg".into(),
            }),
        })),
    }
}

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

/// Waits until `f` holds, polling (at most `timeout`).
pub async fn eventually<F: FnMut() -> bool>(timeout: Duration, mut f: F) -> bool {
    let end = tokio::time::Instant::now() + timeout;
    while tokio::time::Instant::now() < end {
        if f() {
            return true;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    f()
}

/// The first `seconds` of a shipped scenario (`scenarios/{name}.toml`), every sensor, in time
/// order, with its vehicle configuration.
pub fn sim_flight(name: &str, seconds: f64) -> (VehicleConfig, Vec<SensorEvent>) {
    let path = format!("{}/../scenarios/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(path).unwrap();
    let scenario = uavnav_sim::scenario::Scenario::from_toml_str(&text).unwrap();
    let flight = uavnav_sim::flight::Flight::new(&scenario).unwrap();
    let mut events = Vec::new();
    let mut t_end = None;
    for e in flight.events() {
        let e = e.unwrap();
        let end = *t_end.get_or_insert(e.t_ns() + (seconds * 1e9) as i64);
        if e.t_ns() > end {
            break;
        }
        events.push(e);
    }
    (flight.vehicle_config(), events)
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
