//! # uavnav-liveview
//!
//! Foxglove live view: a Foxglove WebSocket server (the `foxglove` crate's) that shows each
//! vehicle's pose, path, GNSS fix, magnetometer vector and camera image while they stream (the
//! barometer is not shown: Foxglove has no schema for a scalar pressure, and a Plot panel of the
//! recording's `/uavnav/{id}/baro` topic shows it). `uavnavd --foxglove-addr`
//! feeds it from the service (every input transport, every pose); `uavnav watch --foxglove` feeds
//! it from what a client watches.
//!
//! Topics per vehicle `{id}` (open the Foxglove app, "Open connection", `ws://HOST:PORT`):
//!
//! | topic | schema | content |
//! |---|---|---|
//! | `/vehicle/{id}/pose` | `foxglove.PoseInFrame` | the estimate (`nav_from_body`) in frame `ned` |
//! | `/vehicle/{id}/path` | `foxglove.PosesInFrame` | its path: one pose per [`PATH_SPACING_NS`] of sensor time, the last [`PATH_MAX_POSES`] |
//! | `/vehicle/{id}/estimate_fix` | `foxglove.LocationFix` | the estimate for the Map panel |
//! | `/vehicle/{id}/gnss` | `foxglove.LocationFix` | GNSS fixes as received (without velocity when the receiver gives none) |
//! | `/vehicle/{id}/mag` | `foxglove.Vector3` | magnetometer samples as received, µT, magnetometer frame (for a Plot panel; the schema has no timestamp, so log time = wall clock at publication) |
//! | `/vehicle/{id}/camera` | `foxglove.CompressedImage` | camera frames as received (JPEG/PNG) |
//!
//! Frame `ned` is one local NED frame for the whole view, at the first position it sees, so the
//! 3D panel places the vehicles of a fleet relative to each other. An estimate without a position
//! (attitude only: a vehicle running without GNSS) still turns on `/vehicle/{id}/pose`, drawn at
//! the vehicle's last drawn position or, before it has one, at the frame's origin; it adds
//! nothing to the path or the map fix. Message timestamps are sensor
//! times; log times are the wall clock at publication (what a live view plots against).
//!
//! The view is a task that owns the scene; [`LiveTap`] is the cloneable, non-blocking handle the
//! ingest path and the watchers use. When the view falls behind, messages are dropped (never the
//! estimation) and counted in [`LiveTap::dropped`] and by the owner's `on_drop` callback (the
//! service's `uavnav_foxglove_dropped_total`).
//!
//! This crate is the only one of the workspace that compiles the `foxglove` WebSocket server.

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use foxglove::messages::{
    CompressedImage, LocationFix, Pose, PoseInFrame, PosesInFrame, Vector3 as FoxVector3,
};
use foxglove::{Channel, Context, WebSocketServer, WebSocketServerHandle};
use tokio::sync::mpsc;
use uavnav_core::{Lla, LocalFrame};
use uavnav_proto::compact::{Pose as CompactPose, PoseBatch};
use uavnav_proto::foxglove_conv;
use uavnav_proto::v1 as pb;

/// Sensor time between two poses of a vehicle's path, ns.
pub const PATH_SPACING_NS: i64 = 500_000_000;
/// Poses kept in a vehicle's path (500 s at [`PATH_SPACING_NS`]).
pub const PATH_MAX_POSES: usize = 1000;
/// Messages queued between the producers and the view task.
pub const QUEUE_DEPTH: usize = 4096;

/// Why the live view could not start.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// The WebSocket server did not start (address in use, bad host...).
    #[error("Foxglove WebSocket server on {addr}: {reason}")]
    Start {
        /// The address asked for.
        addr: String,
        /// The server's reason.
        reason: String,
    },
    /// The address is not `HOST:PORT`.
    #[error("Foxglove address {0:?}: expected HOST:PORT (e.g. 127.0.0.1:8765)")]
    BadAddr(String),
}

/// What the view shows next.
#[derive(Debug)]
enum LiveMsg {
    Poses(Arc<PoseBatch>),
    Gnss(Arc<str>, pb::GnssFix),
    Mag(Arc<str>, pb::MagSample),
    Camera(Arc<str>, pb::CameraFrame),
}

/// Called with the number of messages just dropped (e.g. to count them in a metric).
pub type OnDrop = Arc<dyn Fn(u64) + Send + Sync>;

/// The cloneable handle producers use: every call is a non-blocking send.
#[derive(Clone)]
pub struct LiveTap {
    tx: mpsc::Sender<LiveMsg>,
    dropped: Arc<AtomicU64>,
    on_drop: OnDrop,
}

impl std::fmt::Debug for LiveTap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveTap")
            .field("dropped", &self.dropped())
            .finish_non_exhaustive()
    }
}

impl LiveTap {
    fn send(&self, m: LiveMsg) {
        if self.tx.try_send(m).is_err() {
            self.count_dropped(1);
        }
    }

    /// Shows one pose estimate (a complete wire message, `vehicle_id` set).
    pub fn pose(&self, p: pb::PoseEstimate) {
        self.poses(Arc::new(PoseBatch {
            vehicle_id: p.vehicle_id.as_str().into(),
            poses: vec![CompactPose::from_wire(&p)],
            first_seq: 0,
        }));
    }

    /// Shows a batch of pose estimates.
    pub fn poses(&self, b: Arc<PoseBatch>) {
        self.send(LiveMsg::Poses(b));
    }

    /// Shows a GNSS fix of `vehicle_id`.
    pub fn gnss(&self, vehicle_id: &str, f: &pb::GnssFix) {
        self.send(LiveMsg::Gnss(vehicle_id.into(), *f));
    }

    /// Shows a magnetometer sample of `vehicle_id`.
    pub fn mag(&self, vehicle_id: &str, m: &pb::MagSample) {
        self.send(LiveMsg::Mag(vehicle_id.into(), *m));
    }

    /// Shows a camera frame of `vehicle_id`.
    pub fn camera(&self, vehicle_id: &str, f: &pb::CameraFrame) {
        self.send(LiveMsg::Camera(vehicle_id.into(), f.clone()));
    }

    /// Counts `n` messages lost before they reached the tap (e.g. a lagging pose feed).
    pub fn count_dropped(&self, n: u64) {
        self.dropped.fetch_add(n, Ordering::Relaxed);
        (self.on_drop)(n);
    }

    /// Messages dropped because the view was behind (or stopped).
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// A running live view.
pub struct LiveView {
    server: WebSocketServerHandle,
    tap: LiveTap,
    task: tokio::task::JoinHandle<Scene>,
}

impl std::fmt::Debug for LiveView {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveView")
            .field("port", &self.server.port())
            .finish_non_exhaustive()
    }
}

impl LiveView {
    /// Starts the WebSocket server on `addr` (`HOST:PORT`; port 0 picks a free port) and the view
    /// task, on the current tokio runtime. Messages it drops are counted in [`LiveTap::dropped`]
    /// and reported to `on_drop` (e.g. the service's `uavnav_foxglove_dropped_total`).
    pub async fn start(addr: &str, on_drop: OnDrop) -> Result<LiveView, LiveError> {
        let (host, port) = split_addr(addr)?;
        let ctx = Context::new();
        let server = WebSocketServer::new()
            .name("uavnav")
            .bind(host, port)
            .context(&ctx)
            .start()
            .await
            .map_err(|e| LiveError::Start {
                addr: addr.to_owned(),
                reason: e.to_string(),
            })?;
        let (tx, rx) = mpsc::channel(QUEUE_DEPTH);
        let tap = LiveTap {
            tx,
            dropped: Arc::new(AtomicU64::new(0)),
            on_drop,
        };
        let task = tokio::spawn(run(Scene::new(ctx), rx));
        Ok(LiveView { server, tap, task })
    }

    /// The port the server listens on.
    pub fn port(&self) -> u16 {
        self.server.port()
    }

    /// A handle to feed the view.
    pub fn tap(&self) -> LiveTap {
        self.tap.clone()
    }

    /// Stops the server once the queued messages are shown; returns how many vehicles were shown.
    pub async fn stop(self) -> usize {
        let LiveView { server, tap, task } = self;
        drop(tap);
        // Producers may still hold taps: give the task a moment, then stop regardless.
        let shown = match tokio::time::timeout(std::time::Duration::from_secs(2), task).await {
            Ok(Ok(scene)) => scene.vehicles.len(),
            _ => 0,
        };
        server.stop().wait().await;
        shown
    }
}

fn split_addr(addr: &str) -> Result<(String, u16), LiveError> {
    let bad = || LiveError::BadAddr(addr.to_owned());
    let (host, port) = addr.rsplit_once(':').ok_or_else(bad)?;
    let port: u16 = port.parse().map_err(|_| bad())?;
    let host = host.trim_start_matches('[').trim_end_matches(']');
    if host.is_empty() {
        return Err(bad());
    }
    Ok((host.to_owned(), port))
}

async fn run(mut scene: Scene, mut rx: mpsc::Receiver<LiveMsg>) -> Scene {
    while let Some(m) = rx.recv().await {
        match m {
            LiveMsg::Poses(b) => {
                for p in &b.poses {
                    scene.pose(&b.vehicle_id, p);
                }
            }
            LiveMsg::Gnss(id, f) => scene.gnss(&id, &f),
            LiveMsg::Mag(id, m) => scene.mag(&id, &m),
            LiveMsg::Camera(id, f) => scene.camera(&id, f),
        }
    }
    scene
}

/// One vehicle's channels and path.
struct VehicleView {
    pose: Channel<PoseInFrame>,
    path: Channel<PosesInFrame>,
    estimate_fix: Channel<LocationFix>,
    gnss: Channel<LocationFix>,
    mag: Channel<FoxVector3>,
    camera: Channel<CompressedImage>,
    path_poses: VecDeque<Pose>,
    last_path_t_ns: Option<i64>,
    /// Where the last pose with a position was drawn (NED, m): an attitude-only pose goes there.
    last_ned_m: Option<[f64; 3]>,
}

/// What the view task owns: the channels of every vehicle seen and the shared NED frame.
struct Scene {
    ctx: Arc<Context>,
    frame: Option<LocalFrame>,
    vehicles: HashMap<Arc<str>, VehicleView>,
}

impl Scene {
    fn new(ctx: Arc<Context>) -> Self {
        Self {
            ctx,
            frame: None,
            vehicles: HashMap::new(),
        }
    }

    fn vehicle(&mut self, id: &str) -> &mut VehicleView {
        if !self.vehicles.contains_key(id) {
            let topic = |leaf: &str| format!("/vehicle/{id}/{leaf}");
            let ctx = &self.ctx;
            let v = VehicleView {
                pose: ctx.channel_builder(topic("pose")).build(),
                path: ctx.channel_builder(topic("path")).build(),
                estimate_fix: ctx.channel_builder(topic("estimate_fix")).build(),
                gnss: ctx.channel_builder(topic("gnss")).build(),
                mag: ctx.channel_builder(topic("mag")).build(),
                camera: ctx.channel_builder(topic("camera")).build(),
                path_poses: VecDeque::new(),
                last_path_t_ns: None,
                last_ned_m: None,
            };
            self.vehicles.insert(id.into(), v);
        }
        self.vehicles
            .get_mut(id)
            .unwrap_or_else(|| unreachable!("inserted above"))
    }

    fn pose(&mut self, id: &str, p: &CompactPose) {
        let Some(lla) = p.position.as_ref().and_then(|g| Lla::try_from(g).ok()) else {
            self.attitude_only(id, p);
            return;
        };
        let frame = *self.frame.get_or_insert_with(|| LocalFrame::new(lla));
        let v = self.vehicle(id);
        if v.estimate_fix.has_sinks() {
            v.estimate_fix.log(&estimate_fix(p, &lla));
        }
        let due = v
            .last_path_t_ns
            .is_none_or(|t| p.t_ns.saturating_sub(t) >= PATH_SPACING_NS);
        // Poses come at IMU rate: convert one only when someone watches it or the path keeps it.
        if !due && !v.pose.has_sinks() {
            return;
        }
        let Ok(pose) = foxglove_conv::pose_in_frame(&p.to_wire(id), &frame) else {
            return;
        };
        v.last_ned_m = pose
            .pose
            .as_ref()
            .and_then(|q| q.position.as_ref())
            .map(|x| [x.x, x.y, x.z]);
        v.pose.log(&pose);
        if due && let Some(inner) = pose.pose {
            v.last_path_t_ns = Some(p.t_ns);
            if v.path_poses.len() == PATH_MAX_POSES {
                v.path_poses.pop_front();
            }
            v.path_poses.push_back(inner);
            if v.path.has_sinks() {
                v.path.log(&PosesInFrame {
                    timestamp: pose.timestamp,
                    frame_id: pose.frame_id.clone(),
                    poses: v.path_poses.iter().cloned().collect(),
                });
            }
        }
    }

    /// A pose without a position: its attitude, drawn where the vehicle was last drawn (or at
    /// the origin). One without an attitude either (initialising) has nothing to draw.
    fn attitude_only(&mut self, id: &str, p: &CompactPose) {
        let v = self.vehicle(id);
        if !v.pose.has_sinks() {
            return;
        }
        let at = v.last_ned_m.unwrap_or_default();
        if let Ok(pose) = foxglove_conv::attitude_in_frame(&p.to_wire(id), at) {
            v.pose.log(&pose);
        }
    }

    fn gnss(&mut self, id: &str, f: &pb::GnssFix) {
        // The ingest path validated it already; a client-side view may see anything.
        if let Ok(fix) = foxglove_conv::location_fix_from_wire(f) {
            self.vehicle(id).gnss.log(&fix);
        }
    }

    fn mag(&mut self, id: &str, m: &pb::MagSample) {
        // µT: the Plot panel's axis then reads 20-60 for the Earth's field instead of 2e-5.
        const UT_PER_T: f64 = 1e6;
        self.vehicle(id).mag.log(&FoxVector3 {
            x: m.field_x_t * UT_PER_T,
            y: m.field_y_t * UT_PER_T,
            z: m.field_z_t * UT_PER_T,
        });
    }

    fn camera(&mut self, id: &str, f: pb::CameraFrame) {
        let Some(mut img) = f.image else { return };
        img.timestamp = foxglove_conv::timestamp(f.t_ns);
        if img.frame_id.is_empty() {
            img.frame_id = foxglove_conv::camera_frame_id(f.camera_id);
        }
        self.vehicle(id).camera.log(&img);
    }
}

/// The estimate as a map fix, with its horizontal and vertical σ when the pose carries them.
fn estimate_fix(p: &CompactPose, lla: &Lla) -> LocationFix {
    let sigma = p.sigma_pos_ned_m.as_ref();
    let (n, e, d) = sigma.map_or((0.0, 0.0, 0.0), |s| (s.x, s.y, s.z));
    LocationFix {
        timestamp: foxglove_conv::timestamp(p.t_ns),
        frame_id: foxglove_conv::NED_FRAME_ID.to_owned(),
        latitude: lla.lat_rad.to_degrees(),
        longitude: lla.lon_rad.to_degrees(),
        altitude: lla.alt_m,
        // ENU diagonal: east, north, up.
        position_covariance: vec![e * e, 0.0, 0.0, 0.0, n * n, 0.0, 0.0, 0.0, d * d],
        position_covariance_type:
            foxglove::messages::location_fix::PositionCovarianceType::DiagonalKnown as i32,
        heading: None,
        velocity: None,
        color: None,
        metadata: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses() {
        assert_eq!(
            split_addr("127.0.0.1:8765").ok(),
            Some(("127.0.0.1".to_owned(), 8765))
        );
        assert_eq!(split_addr("[::]:0").ok(), Some(("::".to_owned(), 0)));
        assert!(split_addr("8765").is_err());
        assert!(split_addr(":8765").is_err());
        assert!(split_addr("host:port").is_err());
    }
}
