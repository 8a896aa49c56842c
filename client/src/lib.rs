//! # uavnav-client
//!
//! The library a ground-station backend adds to talk to the uavnav fleet estimation service
//! (`uavnavd`): a typed async client with the same API over gRPC and (feature `zenoh`, on by
//! default) Zenoh — stream sensors in, watch poses and health, list, configure and reset
//! vehicles — and (feature `recording`, on by default) a reader of uavnav MCAP recordings. It
//! depends on the wire contract (`uavnav-proto`) and the transports only: none of the service,
//! the simulator, the estimator or the `uavnav` CLI (crate `uavnav-cli`).
//!
//! | module | what it holds |
//! |---|---|
//! | [`endpoint`] | [`Endpoint`]: `grpc://HOST:PORT`, `grpcs://HOST:PORT`, `zenoh[/ENDPOINT[,ENDPOINT…]]`, `discard` URLs, parsed in one place |
//! | [`security`] | [`TlsOptions`], the bearer-token interceptor, Zenoh TLS settings, the no-token-in-clear rule |
//! | [`error`] | [`ClientError`]: what failed, with the operation and the transport's reason (refusals: `Unauthenticated`, `PermissionDenied`) |
//! | [`backoff`] | [`Backoff`]: reconnection delays (exponential, capped) |
//! | [`client`] | [`Client`]: connect, list, get pose, configure, reset, watch poses/health, ingest |
//! | [`ingest`] | [`Ingest`] / [`IngestSender`]: a vehicle's sensor stream into the service, with counted acks |
//! | [`watch`] | [`Watch`], [`Selector`]: pose and health subscriptions that resume after failures |
//! | [`grpc`] | the gRPC backend (tonic `uavnav.v1.UavNav` client) |
//! | `zenoh_backend` | the Zenoh backend (feature `zenoh`; key expressions of [`keys`]) |
//! | [`keys`] | the service's Zenoh key expressions (re-exported from `uavnav_proto::keys`) |
//! | `recording` | feature `recording`: an MCAP recording (`uavnav record`, uavnavd's recorder, `uavnav convert`) as wire messages in log-time order |
//! | [`pb`] | the `uavnav.v1` wire messages (re-exported from `uavnav_proto::v1`) |
//!
//! Over Zenoh there is no acknowledgement and no reset: [`Client::reset`] returns
//! [`ClientError::Unsupported`], and [`Client::configure`] publishes on the vehicle's `config` key
//! without learning whether the vehicle was created. Built without the `zenoh` feature, a `zenoh…`
//! endpoint still parses, and [`Client::connect`] to it returns [`ClientError::Unsupported`].
//!
//! A service reached over a network is secured ([`security`]): `grpcs://HOST:PORT` or Zenoh
//! `tls/HOST:PORT` locators with [`ConnectOptions::tls`] (the deployment's CA, and this ground
//! station's certificate for mutual TLS), and a bearer token ([`ConnectOptions::token`]) sent on
//! every gRPC request. The service's refusals are [`ClientError::Unauthenticated`] and
//! [`ClientError::PermissionDenied`], never retried; an ingest ack `PERMISSION_DENIED` is counted
//! with its reason ([`IngestStats::permission_denied`]).
//!
//! `examples/feed_recording.rs` streams a recording into a running service and prints the poses
//! it gets back, with this crate alone.

pub mod backoff;
pub mod client;
pub mod endpoint;
pub mod error;
pub mod grpc;
pub mod ingest;
#[cfg(feature = "recording")]
pub mod recording;
pub mod security;
pub mod watch;
#[cfg(feature = "zenoh")]
pub mod zenoh_backend;
#[cfg(feature = "zenoh")]
pub mod zenoh_keeper;

pub use backoff::Backoff;
pub use client::{Client, ConnectOptions};
pub use endpoint::Endpoint;
pub use error::ClientError;
pub use ingest::{Ingest, IngestSender, IngestStats};
pub use security::TlsOptions;
pub use uavnav_proto::keys;
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
