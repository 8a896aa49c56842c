//! # uavnav-client
//!
//! A typed async client of the uavnav fleet estimation service (`uavnavd`), with the same API over
//! gRPC and over Zenoh, plus the engines behind the `uavnav` CLI's online subcommands (load test,
//! replay scheduling, recording).
//!
//! | module | what it holds |
//! |---|---|
//! | [`endpoint`] | [`Endpoint`]: `grpc://HOST:PORT`, `zenoh[/ENDPOINT[,ENDPOINT…]]`, `discard` URLs, parsed in one place |
//! | [`error`] | [`ClientError`]: what failed, with the operation and the transport's reason |
//! | [`backoff`] | [`Backoff`]: reconnection delays (exponential, capped) |
//! | [`client`] | [`Client`]: connect, list, get pose, configure, reset, watch poses/health, ingest |
//! | [`ingest`] | [`Ingest`] / [`IngestSender`]: a vehicle's sensor stream into the service, with counted acks |
//! | [`watch`] | [`Watch`], [`Selector`]: pose and health subscriptions that resume after failures |
//! | [`grpc`] | the gRPC backend (tonic `uavnav.v1.UavNav` client) |
//! | [`zenoh_backend`] | the Zenoh backend (key expressions of [`keys`]) |
//! | [`keys`] | the Zenoh key expressions of the service |
//! | [`schedule`] | sensor events → timed wire messages (IMU batching, speed, time offsets) |
//! | [`load`] | the load generator and its latency/throughput measurement (coordinated-omission correct) |
//! | [`report`] | the load test report: ghz-like JSON and the text table |
//! | [`posefmt`] | wire poses → the `uavnav estimate` CSV columns and TUM lines |
//!
//! Over Zenoh there is no acknowledgement and no reset: [`Client::reset`] returns
//! [`ClientError::Unsupported`], and [`Client::configure`] publishes on the vehicle's `config` key
//! without learning whether the vehicle was created.

pub mod backoff;
pub mod client;
pub mod endpoint;
pub mod error;
pub mod grpc;
pub mod ingest;
pub mod keys;
pub mod load;
pub mod posefmt;
pub mod report;
pub mod schedule;
pub mod watch;
pub mod zenoh_backend;

pub use backoff::Backoff;
pub use client::{Client, ConnectOptions};
pub use endpoint::Endpoint;
pub use error::ClientError;
pub use ingest::{Ingest, IngestSender, IngestStats};
pub use uavnav_proto::v1 as pb;
pub use watch::{Selector, Watch};

/// Result of client operations.
pub type Result<T, E = ClientError> = std::result::Result<T, E>;

/// The wall clock as UNIX nanoseconds (for `ingest_wall_ns` comparisons and health ages).
pub fn unix_now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as i64)
        .unwrap_or(0)
}
