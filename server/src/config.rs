//! Service configuration: defaults, then a TOML file, then `UAVNAV_*` environment variables, then
//! command-line flags (clap). Unknown TOML keys are rejected with the key's name.
//!
//! The shipped `server/uavnavd.toml` lists every key with its default; keep the two in sync (a test
//! parses that file and compares it with [`Config::default`]).

use std::ffi::OsString;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use clap::Parser;
use serde::Deserialize;

/// Errors from loading the configuration.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The config file could not be read.
    #[error("cannot read config file {path}: {source}")]
    Read {
        /// File path.
        path: PathBuf,
        /// I/O error.
        source: std::io::Error,
    },
    /// The TOML was malformed or had an unknown key (the message names it).
    #[error("invalid config file {path}: {message}")]
    Parse {
        /// File path.
        path: PathBuf,
        /// The parser's message (names the offending key).
        message: String,
    },
    /// An environment variable had an unusable value.
    #[error("invalid environment variable {name}={value}: {message}")]
    Env {
        /// Variable name.
        name: String,
        /// Its value.
        value: String,
        /// Why it was rejected.
        message: String,
    },
    /// A value is out of its allowed range.
    #[error("invalid configuration: {0}")]
    Invalid(String),
    /// Command-line parsing failed (includes `--help`).
    #[error("{0}")]
    Cli(#[from] clap::Error),
}

/// Zenoh session mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum ZenohMode {
    /// Peer (default): talks directly to other peers and routers.
    Peer,
    /// Client of a router.
    Client,
    /// Router: other peers and clients may route through this process.
    Router,
}

impl ZenohMode {
    /// The Zenoh config name of the mode.
    pub fn as_str(self) -> &'static str {
        match self {
            ZenohMode::Peer => "peer",
            ZenohMode::Client => "client",
            ZenohMode::Router => "router",
        }
    }
}

impl std::str::FromStr for ZenohMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "peer" => Ok(ZenohMode::Peer),
            "client" => Ok(ZenohMode::Client),
            "router" => Ok(ZenohMode::Router),
            other => Err(format!(
                "unknown zenoh mode '{other}' (expected peer, client or router)"
            )),
        }
    }
}

/// The whole service configuration.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// gRPC endpoint.
    pub grpc: GrpcConfig,
    /// HTTP endpoint (metrics and probes).
    pub http: HttpConfig,
    /// Embedded Zenoh session.
    pub zenoh: ZenohConfig,
    /// Per-vehicle actors.
    pub vehicles: VehiclesConfig,
    /// Vision worker pool.
    pub vision: VisionConfig,
    /// Health publishing.
    pub health: HealthConfig,
    /// Logging.
    pub log: LogConfig,
    /// Foxglove live view.
    pub foxglove: FoxgloveConfig,
    /// Recording of accepted inputs and output poses to MCAP files.
    pub record: RecordConfig,
    /// TLS, principals and grants.
    pub security: crate::security::SecurityConfig,
}

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

/// Command-line flags. Every flag overrides the file and the environment.
#[derive(Debug, Clone, Default, Parser)]
#[command(
    name = "uavnavd",
    version,
    about = "uavnav fleet estimation service (gRPC + Zenoh)"
)]
pub struct Cli {
    /// TOML config file (also `UAVNAV_CONFIG`).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// gRPC listen address [default: 127.0.0.1:50051].
    #[arg(long, value_name = "ADDR")]
    pub grpc_addr: Option<SocketAddr>,
    /// HTTP listen address for /metrics, /livez, /readyz [default: 127.0.0.1:9464].
    #[arg(long, value_name = "ADDR")]
    pub http_addr: Option<SocketAddr>,
    /// Zenoh session mode [default: peer].
    #[arg(long, value_enum, value_name = "MODE")]
    pub zenoh_mode: Option<ZenohMode>,
    /// Zenoh endpoint to listen on (repeatable) [default: tcp/127.0.0.1:7447; tls/HOST:PORT with
    /// [security.tls]].
    #[arg(long, value_name = "ENDPOINT")]
    pub zenoh_listen: Vec<String>,
    /// Zenoh endpoint to connect to (repeatable).
    #[arg(long, value_name = "ENDPOINT")]
    pub zenoh_connect: Vec<String>,
    /// Zenoh JSON5 config file used as the session's base configuration.
    #[arg(long, value_name = "FILE")]
    pub zenoh_config: Option<PathBuf>,
    /// Disable the Zenoh transport.
    #[arg(long)]
    pub no_zenoh: bool,
    /// JSON log lines.
    #[arg(long)]
    pub log_json: bool,
    /// Serve a Foxglove live view (WebSocket) on this address, e.g. 127.0.0.1:8765 [default: off].
    #[arg(long, value_name = "HOST:PORT")]
    pub foxglove_addr: Option<String>,
    /// Record every accepted input and every pose to rotating MCAP files in this directory
    /// (see [record] in the config file for rotation and retention) [default: off].
    #[arg(long, value_name = "DIR")]
    pub record_dir: Option<PathBuf>,
    /// Allow listeners without TLS off loopback (security.insecure): anyone on the network can
    /// then read and forge traffic. Said loudly at startup.
    #[arg(long)]
    pub insecure: bool,
    /// Serve gRPC server reflection (grpc.reflection) [default: off].
    #[arg(long)]
    pub grpc_reflection: bool,
    /// Print the worst-case resident memory of the configuration, term by term, and exit.
    #[arg(long)]
    pub memory_budget: bool,
}

/// Environment variables read by [`Config::load`], with the key each overrides.
pub const ENV_VARS: &[(&str, &str)] = &[
    ("UAVNAV_CONFIG", "(config file path)"),
    ("UAVNAV_GRPC_ADDR", "grpc.addr"),
    ("UAVNAV_HTTP_ADDR", "http.addr"),
    ("UAVNAV_ZENOH_ENABLED", "zenoh.enabled"),
    ("UAVNAV_ZENOH_MODE", "zenoh.mode"),
    ("UAVNAV_ZENOH_LISTEN", "zenoh.listen (comma-separated)"),
    ("UAVNAV_ZENOH_CONNECT", "zenoh.connect (comma-separated)"),
    ("UAVNAV_ZENOH_CONFIG", "zenoh.config_file"),
    ("UAVNAV_ZENOH_INSTANCE", "zenoh.instance"),
    ("UAVNAV_LOG_JSON", "log.json"),
    ("UAVNAV_LOG", "log.filter"),
    ("UAVNAV_FOXGLOVE_ADDR", "foxglove.addr"),
    ("UAVNAV_RECORD_DIR", "record.directory"),
    ("UAVNAV_INSECURE", "security.insecure"),
];

impl Config {
    /// Parses a TOML document (unknown keys are errors naming the key).
    pub fn from_toml(text: &str, path: &Path) -> Result<Self, ConfigError> {
        toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
    }

    /// Reads and parses a TOML file.
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml(&text, path)
    }

    /// Defaults → file (`--config` or `UAVNAV_CONFIG`) → environment → flags.
    ///
    /// `env` looks a variable up (pass `|k| std::env::var(k).ok()` in production) so tests need not
    /// touch the process environment.
    pub fn load<I, T>(args: I, env: impl Fn(&str) -> Option<String>) -> Result<Self, ConfigError>
    where
        I: IntoIterator<Item = T>,
        T: Into<OsString> + Clone,
    {
        let cli = Cli::try_parse_from(args)?;
        let file = cli
            .config
            .clone()
            .or_else(|| env("UAVNAV_CONFIG").map(PathBuf::from));
        let mut cfg = match file {
            Some(path) => Self::from_file(&path)?,
            None => Self::default(),
        };
        cfg.apply_env(&env)?;
        cfg.apply_cli(&cli);
        cfg.check()?;
        Ok(cfg)
    }

    /// Applies the `UAVNAV_*` variables listed in [`ENV_VARS`].
    pub fn apply_env(&mut self, env: &impl Fn(&str) -> Option<String>) -> Result<(), ConfigError> {
        fn parse<T: std::str::FromStr>(name: &str, value: String) -> Result<T, ConfigError>
        where
            T::Err: std::fmt::Display,
        {
            value.parse::<T>().map_err(|e| ConfigError::Env {
                name: name.into(),
                value,
                message: e.to_string(),
            })
        }
        let list = |v: String| {
            v.split(',')
                .map(|s| s.trim().to_string())
                .filter(|s| !s.is_empty())
                .collect()
        };
        if let Some(v) = env("UAVNAV_GRPC_ADDR") {
            self.grpc.addr = parse("UAVNAV_GRPC_ADDR", v)?;
        }
        if let Some(v) = env("UAVNAV_HTTP_ADDR") {
            self.http.addr = parse("UAVNAV_HTTP_ADDR", v)?;
        }
        if let Some(v) = env("UAVNAV_ZENOH_ENABLED") {
            self.zenoh.enabled = parse("UAVNAV_ZENOH_ENABLED", v)?;
        }
        if let Some(v) = env("UAVNAV_ZENOH_MODE") {
            self.zenoh.mode = parse("UAVNAV_ZENOH_MODE", v)?;
        }
        if let Some(v) = env("UAVNAV_ZENOH_LISTEN") {
            self.zenoh.listen = list(v);
        }
        if let Some(v) = env("UAVNAV_ZENOH_CONNECT") {
            self.zenoh.connect = list(v);
        }
        if let Some(v) = env("UAVNAV_ZENOH_CONFIG") {
            self.zenoh.config_file = Some(PathBuf::from(v));
        }
        if let Some(v) = env("UAVNAV_ZENOH_INSTANCE") {
            self.zenoh.instance = v;
        }
        if let Some(v) = env("UAVNAV_LOG_JSON") {
            self.log.json = parse("UAVNAV_LOG_JSON", v)?;
        }
        if let Some(v) = env("UAVNAV_LOG") {
            self.log.filter = v;
        }
        if let Some(v) = env("UAVNAV_FOXGLOVE_ADDR") {
            self.foxglove.addr = Some(v).filter(|a| !a.is_empty());
        }
        if let Some(v) = env("UAVNAV_RECORD_DIR") {
            self.record.directory = Some(PathBuf::from(v)).filter(|d| !d.as_os_str().is_empty());
        }
        if let Some(v) = env("UAVNAV_INSECURE") {
            self.security.insecure = parse("UAVNAV_INSECURE", v)?;
        }
        Ok(())
    }

    /// Applies the flags that were given.
    pub fn apply_cli(&mut self, cli: &Cli) {
        if let Some(a) = cli.grpc_addr {
            self.grpc.addr = a;
        }
        if let Some(a) = cli.http_addr {
            self.http.addr = a;
        }
        if let Some(m) = cli.zenoh_mode {
            self.zenoh.mode = m;
        }
        if !cli.zenoh_listen.is_empty() {
            self.zenoh.listen = cli.zenoh_listen.clone();
        }
        if !cli.zenoh_connect.is_empty() {
            self.zenoh.connect = cli.zenoh_connect.clone();
        }
        if let Some(f) = &cli.zenoh_config {
            self.zenoh.config_file = Some(f.clone());
        }
        if cli.no_zenoh {
            self.zenoh.enabled = false;
        }
        if cli.log_json {
            self.log.json = true;
        }
        if let Some(a) = &cli.foxglove_addr {
            self.foxglove.addr = Some(a.clone());
        }
        if let Some(d) = &cli.record_dir {
            self.record.directory = Some(d.clone());
        }
        if cli.insecure {
            self.security.insecure = true;
        }
        if cli.grpc_reflection {
            self.grpc.reflection = true;
        }
    }

    /// Rejects values that cannot work.
    pub fn check(&self) -> Result<(), ConfigError> {
        let bad = |m: &str| Err(ConfigError::Invalid(m.to_string()));
        if self.grpc.max_message_bytes < 8 << 20 {
            return bad("grpc.max_message_bytes must be at least 8 MiB (1080p JPEG frames)");
        }
        if self.grpc.ack_buffer == 0
            || self.vehicles.input_queue == 0
            || self.vehicles.camera_queue == 0
        {
            return bad(
                "grpc.ack_buffer, vehicles.input_queue and vehicles.camera_queue must be > 0",
            );
        }
        let v = &self.vehicles;
        if v.input_queue_bytes < 64 << 10
            || v.input_queue_bytes > u32::MAX as usize
            || v.input_bytes < v.input_queue_bytes
        {
            return bad(
                "vehicles.input_queue_bytes must be within 64 KiB..4 GiB and vehicles.input_bytes at least as large",
            );
        }
        let g = &self.grpc;
        if g.arrival_bytes < 3 * g.max_message_bytes as u64 {
            return bad(
                "grpc.arrival_bytes must be at least 3 × grpc.max_message_bytes (one compressed message of the largest size)",
            );
        }
        let seconds = |x: f64| x.is_finite() && x > 0.0 && x <= 86_400.0;
        if g.max_connections == 0
            || self.http.max_connections == 0
            || g.max_streams_per_connection == 0
            || g.max_streams == 0
        {
            return bad(
                "grpc.max_connections, grpc.max_streams_per_connection, grpc.max_streams and http.max_connections must be > 0",
            );
        }
        if g.max_streams_per_peer == 0 {
            return bad("grpc.max_streams_per_peer must be > 0");
        }
        if !(seconds(g.idle_timeout_s)
            && seconds(self.http.idle_timeout_s)
            && seconds(self.http.header_timeout_s))
        {
            return bad(
                "grpc.idle_timeout_s, http.idle_timeout_s and http.header_timeout_s must be in (0, 86400]",
            );
        }
        if !(g.keepalive_interval_s == 0.0 || seconds(g.keepalive_interval_s))
            || !seconds(g.keepalive_timeout_s)
        {
            return bad(
                "grpc.keepalive_interval_s must be 0 (off) or in (0, 86400], grpc.keepalive_timeout_s in (0, 86400]",
            );
        }
        if g.keepalive_interval_s > 0.0
            && g.idle_timeout_s <= g.keepalive_interval_s + g.keepalive_timeout_s
        {
            return bad(
                "grpc.idle_timeout_s must exceed grpc.keepalive_interval_s + grpc.keepalive_timeout_s (a live idle client answers pings only that often)",
            );
        }
        let v = &self.vehicles;
        if !(v.reorder_window_ms >= 0.0 && v.reorder_window_ms <= 10_000.0) {
            return bad("vehicles.reorder_window_ms must be in [0, 10000]");
        }
        if !(v.idle_evict_s > 0.0 && v.max_future_s > 0.0) || v.max_vehicles == 0 {
            return bad(
                "vehicles.idle_evict_s, vehicles.max_future_s and vehicles.max_vehicles must be > 0",
            );
        }
        if !(v.max_future_s.is_finite() && v.max_future_s <= 86_400.0) {
            return bad("vehicles.max_future_s must be at most 86400 (a day)");
        }
        if v.clock_resync_samples < 2 {
            return bad("vehicles.clock_resync_samples must be at least 2");
        }
        if !(v.clock_resync_s >= 0.0 && v.clock_resync_s <= 3600.0) {
            return bad("vehicles.clock_resync_s must be in [0, 3600]");
        }
        let vis = &self.vision;
        if v.camera_queue_bytes < vis.max_image_bytes || vis.queue_bytes < vis.max_image_bytes {
            return bad(
                "vehicles.camera_queue_bytes and vision.queue_bytes must hold at least one frame of vision.max_image_bytes",
            );
        }
        if vis.max_camera_width_px == 0
            || vis.max_camera_height_px == 0
            || vis.max_camera_pixels == 0
            || vis.max_total_camera_pixels < vis.max_camera_pixels
            || vis.max_camera_width_px > 16_384
            || vis.max_camera_height_px > 16_384
        {
            return bad(
                "vision.max_camera_width_px and vision.max_camera_height_px must be in [1, 16384], vision.max_camera_pixels > 0 and at most vision.max_total_camera_pixels",
            );
        }
        if !(self.zenoh.stalled_link_ms >= 0.0 && self.zenoh.stalled_link_ms <= 10_000.0) {
            return bad("zenoh.stalled_link_ms must be in [0, 10000]");
        }
        if !(self.zenoh.repeat_health_per_s >= 0.0 && self.zenoh.repeat_health_per_s <= 1e6) {
            return bad("zenoh.repeat_health_per_s must be in [0, 1e6]");
        }
        if !(1..=100_000).contains(&self.zenoh.max_sessions) {
            return bad("zenoh.max_sessions must be in [1, 100000]");
        }
        if self.health.period_ms == 0 {
            return bad("health.period_ms must be > 0");
        }
        let r = &self.record;
        if r.rotate_bytes == 0 || r.retain_bytes == 0 || r.queue_bytes == 0 {
            return bad(
                "record.rotate_bytes, record.retain_bytes and record.queue_bytes must be > 0",
            );
        }
        if !(r.rotate_s > 0.0 && r.rotate_s.is_finite()) {
            return bad("record.rotate_s must be > 0");
        }
        crate::security::Authorizer::new(&self.security.principals)
            .map_err(|e| ConfigError::Invalid(e.to_string()))?;
        crate::security::exposure(self).map_err(ConfigError::Invalid)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_file_equals_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("uavnavd.toml");
        let cfg = Config::from_file(&path).unwrap();
        assert_eq!(cfg, Config::default());
    }

    #[test]
    fn docker_config_parses_and_is_valid() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docker/uavnavd.toml");
        let cfg = Config::from_file(&path).unwrap();
        cfg.check().unwrap();
    }

    #[test]
    fn unknown_key_is_named() {
        let err =
            Config::from_toml("[grpc]\nadress = \"1.2.3.4:5\"\n", Path::new("x.toml")).unwrap_err();
        assert!(err.to_string().contains("adress"), "{err}");
    }
}
