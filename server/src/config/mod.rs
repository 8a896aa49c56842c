//! Service configuration: defaults, then a TOML file, then `UAVNAV_*` environment variables, then
//! command-line flags (clap). Unknown TOML keys are rejected with the key's name.
//!
//! The shipped `server/uavnavd.toml` lists every key with its default; keep the two in sync (a test
//! parses that file and compares it with [`Config::default`]).
//!
//! | module | holds |
//! |---|---|
//! | this file | [`Config`], its loading (file, environment, flags) and the command line |
//! | `sections` | the sections' keys, documented, with their defaults |
//! | `check` | [`Config::check`]: values that cannot work, refused with the key named |

use std::ffi::OsString;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use clap::Parser;
use serde::Deserialize;

mod check;
mod sections;

pub use sections::{
    FoxgloveConfig, GrpcConfig, HealthConfig, HttpConfig, LogConfig, RecordConfig, VehiclesConfig,
    VisionConfig, ZenohConfig,
};

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
