//! The configuration's sections other than security: what each key means and its default
//! (`server/uavnavd.toml` lists them all with their defaults).

use std::net::SocketAddr;
use std::path::PathBuf;

use serde::Deserialize;

use super::ZenohMode;

/// Recording settings: every accepted input and every pose, to rotating MCAP files.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecordConfig {
    /// Directory of the recordings; absent = no recording (the default).
    pub directory: Option<PathBuf>,
    /// A file is closed and the next one started once this many message bytes (encoded, before
    /// compression) are in it.
    pub rotate_bytes: u64,
    /// A file is closed and the next one started after this many seconds, s.
    pub rotate_s: f64,
    /// Total bytes of recordings kept in the directory; the oldest files are deleted first.
    pub retain_bytes: u64,
    /// Bytes the queue to the writer may hold; beyond, records are dropped (counted), never
    /// waited for.
    pub queue_bytes: u64,
}

impl Default for RecordConfig {
    fn default() -> Self {
        Self {
            directory: None,
            rotate_bytes: 256 << 20,
            rotate_s: 600.0,
            retain_bytes: 10 << 30,
            queue_bytes: 64 << 20,
        }
    }
}

/// Foxglove live view settings (a Foxglove WebSocket server showing every vehicle).
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct FoxgloveConfig {
    /// Listen address `HOST:PORT` of the live view; absent = no live view (the default).
    pub addr: Option<String>,
}

/// gRPC endpoint settings.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GrpcConfig {
    /// Listen address (`127.0.0.1:50051`; port 0 picks a free port). Off loopback it needs
    /// `[security.tls]` or `security.insecure`.
    pub addr: SocketAddr,
    /// Largest accepted (decoded) message, bytes. Sized for 1080p JPEG frames.
    pub max_message_bytes: usize,
    /// Ingest acknowledgements buffered per stream before the stream stops reading (flow control);
    /// at most `transport::response_queue::RESPONSE_QUEUE_BYTES` of them whatever this says.
    pub ack_buffer: usize,
    /// Serve gRPC server reflection (lets any caller list the API; off by default).
    pub reflection: bool,
    /// Connections open at once (TLS handshakes included); beyond, new ones are closed at once
    /// and counted (`uavnav_connections_refused_total{reason="limit"}`).
    pub max_connections: usize,
    /// A connection whose peer sent nothing for this long is closed, s. Must exceed the
    /// keepalive interval plus its timeout, so that a live idle peer (answering pings) stays.
    pub idle_timeout_s: f64,
    /// HTTP/2 keepalive: the service pings each connection this often, s (0: off).
    pub keepalive_interval_s: f64,
    /// A ping not answered within this closes the connection (a link that died without a
    /// reset), s.
    pub keepalive_timeout_s: f64,
    /// Streams one connection may have open at once (HTTP/2 `max_concurrent_streams`).
    pub max_streams_per_connection: u32,
    /// Streams open at once on all connections together; beyond, a new call is answered at
    /// once with RESOURCE_EXHAUSTED and counted (`uavnav_grpc_streams_refused_total`). Each open
    /// stream holds up to `budget::GRPC_STREAM_BYTES` (288 KiB) whatever it carries, so this,
    /// not `max_connections × max_streams_per_connection`, bounds the streams' memory
    /// ([`crate::transport::stream_limit`]). At least 1.
    pub max_streams: usize,
    /// Of those, streams one peer IP address may have open at once (all its connections
    /// together); beyond, a new call from it is answered with RESOURCE_EXHAUSTED and counted
    /// (`uavnav_grpc_streams_peer_refused_total`), so that one host cannot take every slot and
    /// lock the other clients out. A ground station feeding a whole fleet from one address needs
    /// few: the client library spreads its vehicles over a handful of ingest streams. At least
    /// 1; a value above `max_streams` leaves only that total.
    pub max_streams_per_peer: usize,
    /// Bytes all streams' arriving messages may hold together (receive buffers and decoded
    /// copies: twice a message's length, plus `2 × max_message_bytes` for a compressed one). A
    /// message that does not fit ends its stream with RESOURCE_EXHAUSTED
    /// ([`crate::transport::arrivals`]). At least `3 × max_message_bytes`.
    pub arrival_bytes: u64,
}

impl Default for GrpcConfig {
    fn default() -> Self {
        Self {
            addr: SocketAddr::from(([127, 0, 0, 1], 50051)),
            max_message_bytes: 16 << 20,
            ack_buffer: 256,
            reflection: false,
            max_connections: 1024,
            idle_timeout_s: 120.0,
            keepalive_interval_s: 20.0,
            keepalive_timeout_s: 20.0,
            max_streams_per_connection: 32,
            max_streams: 4096,
            max_streams_per_peer: 3072,
            arrival_bytes: 1 << 30,
        }
    }
}

/// HTTP endpoint settings.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HttpConfig {
    /// Listen address for `/metrics`, `/livez`, `/readyz` (loopback by default; off loopback it
    /// needs `[security.tls]` or `security.insecure`, and with principals `/metrics` needs a
    /// grant of `metrics`).
    pub addr: SocketAddr,
    /// Connections open at once; beyond, new ones are closed at once and counted.
    pub max_connections: usize,
    /// A connection whose peer sent nothing for this long is closed, s.
    pub idle_timeout_s: f64,
    /// Time a client has to send a request's headers (HTTP/1; slow senders are cut off), s.
    pub header_timeout_s: f64,
}

impl Default for HttpConfig {
    fn default() -> Self {
        Self {
            addr: SocketAddr::from(([127, 0, 0, 1], 9464)),
            max_connections: 64,
            idle_timeout_s: 30.0,
            header_timeout_s: 10.0,
        }
    }
}

/// Embedded Zenoh session settings.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ZenohConfig {
    /// Run the Zenoh transport at all.
    pub enabled: bool,
    /// Session mode.
    pub mode: ZenohMode,
    /// Endpoints to listen on.
    pub listen: Vec<String>,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// A Zenoh JSON5 config file used as the base; `mode`, `listen`, `connect`,
    /// `multicast_scouting`, `stalled_link_ms` and `max_sessions` are applied on top.
    pub config_file: Option<PathBuf>,
    /// Multicast scouting (discovering peers on the LAN). Tests turn it off.
    pub multicast_scouting: bool,
    /// Instance name in the `uavnav/v1/service/{instance}` liveliness token ("" = host-pid).
    pub instance: String,
    /// How long a pose or health report waits for room in a subscriber link's full send queue
    /// before that link is taken as stalled and loses what it cannot take (until it drains), ms.
    /// Long enough that a healthy link on a busy machine never loses a sample; the other links
    /// are never held (Zenoh's `congestion_control/drop/wait_before_drop`).
    pub stalled_link_ms: f64,
    /// Health reports that only repeat a quiet vehicle's previous one (nothing but the clocks
    /// changed), published per second for the whole fleet while someone subscribes to health;
    /// beyond it they are skipped (counted in `uavnav_zenoh_health_repeats_skipped_total`).
    /// Every report that says something new is published. A watcher learns that a vehicle is
    /// there from its liveliness token; this bounds what an idle fleet's reminders cost however
    /// many vehicles it has. 0 publishes no repeats.
    pub repeat_health_per_s: f64,
    /// Zenoh transports (peers, clients, routers linked to this session) open at once; beyond,
    /// Zenoh refuses new ones (its `transport/unicast/max_sessions`). Each link holds up to
    /// `budget::ZENOH_LINK_BYTES` (4 MiB) of buffers and one file descriptor, so this bounds
    /// both in the memory budget and the descriptor check. A fleet's drones link to the
    /// session through a router, or a few each; Zenoh's own default is 1,000.
    pub max_sessions: usize,
}

impl Default for ZenohConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            mode: ZenohMode::Peer,
            listen: vec!["tcp/127.0.0.1:7447".to_string()],
            connect: Vec::new(),
            config_file: None,
            multicast_scouting: true,
            instance: String::new(),
            stalled_link_ms: 50.0,
            repeat_health_per_s: 100.0,
            max_sessions: 256,
        }
    }
}

/// Per-vehicle actor settings.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VehiclesConfig {
    /// An actor with no input for this long is evicted, s.
    pub idle_evict_s: f64,
    /// Inputs are fused in timestamp order within this window; older data is counted late, ms.
    pub reorder_window_ms: f64,
    /// A sample more than this far ahead of the vehicle's stream time is refused, s (plus the
    /// wall time since the stream last moved: a stream resuming after a silence is taken back).
    /// Also the most a forged sample can move the stream time ahead in one step.
    pub max_future_s: f64,
    /// A run of this many consecutive IMU samples, consistent among themselves, refused for
    /// being more than `max_future_s` away from the stream time (either way) means the vehicle's
    /// clock jumped (a rebooted drone, a replay started over): the vehicle is reset and taken
    /// back at the new time (counted in `uavnav_clock_resyncs_total`)...
    pub clock_resync_samples: u32,
    /// ...once the run has lasted this much wall time, s (a burst of retransmitted old data is
    /// not a restarted clock: a new stream comes in real time).
    pub clock_resync_s: f64,
    /// Capacity of each actor's sensor queue (IMU/GNSS batches); full = back-pressure, never shed.
    pub input_queue: usize,
    /// Decoded bytes of sensor data (IMU, GNSS, magnetometer, barometer) one vehicle may have
    /// queued; beyond, its senders wait (back-pressure, never shed).
    pub input_queue_bytes: usize,
    /// Decoded bytes of sensor data queued at all vehicles together; beyond, senders wait.
    pub input_bytes: usize,
    /// Camera frames one vehicle may have queued; beyond, new frames are shed (counted).
    pub camera_queue: usize,
    /// Compressed camera bytes one vehicle may have queued; beyond, new frames are shed.
    pub camera_queue_bytes: usize,
    /// Most vehicles served at once; more are refused with ResourceExhausted.
    pub max_vehicles: usize,
}

impl Default for VehiclesConfig {
    fn default() -> Self {
        Self {
            idle_evict_s: 300.0,
            reorder_window_ms: 20.0,
            max_future_s: 1.0,
            clock_resync_samples: 10,
            clock_resync_s: 0.5,
            input_queue: 256,
            input_queue_bytes: 4 << 20,
            input_bytes: 256 << 20,
            camera_queue: 32,
            camera_queue_bytes: 16 << 20,
            max_vehicles: 10_000,
        }
    }
}

/// Vision worker pool settings.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VisionConfig {
    /// Worker threads (0 = one per core).
    pub workers: usize,
    /// Jobs waiting beyond the running ones; when full, frames are shed (counted).
    pub queue: usize,
    /// Compressed camera bytes queued at all vehicles together; beyond, new frames are shed.
    pub queue_bytes: usize,
    /// Largest accepted compressed image, bytes.
    pub max_image_bytes: usize,
    /// Largest camera width a vehicle may configure, px.
    pub max_camera_width_px: u32,
    /// Largest camera height a vehicle may configure, px.
    pub max_camera_height_px: u32,
    /// Largest camera resolution a vehicle may configure, pixels (width × height): the vision
    /// front end's memory per camera vehicle and the decode memory per job grow with it.
    pub max_camera_pixels: u64,
    /// Pixels of all configured cameras together (the sum of width × height over camera
    /// vehicles): the global bound of the vision front ends' memory. A configuration that would
    /// exceed it is refused (RESOURCE_EXHAUSTED).
    pub max_total_camera_pixels: u64,
}

impl Default for VisionConfig {
    fn default() -> Self {
        Self {
            workers: 0,
            queue: 16,
            queue_bytes: 256 << 20,
            max_image_bytes: 12 << 20,
            max_camera_width_px: 4096,
            max_camera_height_px: 4096,
            max_camera_pixels: 4 << 20,
            max_total_camera_pixels: 64 << 20,
        }
    }
}

impl VisionConfig {
    /// The worker count after resolving 0 to the number of cores.
    pub fn effective_workers(&self) -> usize {
        if self.workers > 0 {
            self.workers
        } else {
            std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1)
        }
    }
}

/// Health publishing settings.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HealthConfig {
    /// Per-vehicle health publication period, ms (an idle vehicle: once in ten periods).
    pub period_ms: u64,
}

impl Default for HealthConfig {
    fn default() -> Self {
        Self { period_ms: 1000 }
    }
}

/// Logging settings.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LogConfig {
    /// JSON lines instead of human-readable logs.
    pub json: bool,
    /// `tracing` filter directive (overridden by `RUST_LOG`).
    pub filter: String,
}

impl Default for LogConfig {
    fn default() -> Self {
        Self {
            json: false,
            filter: "info".to_string(),
        }
    }
}
