//! The workspace's test support and test map.
//!
//! Support (a dev-dependency of the crates whose tests use it; it depends on core, proto, sim,
//! dataset and the service — the service's own integration tests link the same `uavnavd` library, so the
//! dev-dependency cycle is harmless):
//!
//! | item | what it gives |
//! |---|---|
//! | [`shared_data`] | the shared real data beside the workspace, or why a test skips |
//! | [`wire`] | wire-message builders: IMU, GNSS, magnetometer, barometer samples, envelopes, the tests' camera ([`wire::camera_config`]) and a vehicle configuration, a minimal JPEG header |
//! | [`net`] | a free loopback port, `eventually` (poll a condition with a timeout) |
//! | [`service`] | an in-process `uavnavd` on loopback (gRPC/HTTP port 0, Zenoh on a free port) with its client URLs; the loopback configuration |
//! | [`flight`] | a shipped scenario's first seconds as sensor events with its vehicle configuration; the smoke flight as wire messages |
//! | [`recording`] | MCAP recordings written as the service's recorder and `uavnav record` write them (a simulated flight or given inputs); a recording's poses, a directory's recordings |
//! | [`pki`] | certificates made at test time: a CA, the service's, ground stations' (valid, expired, of a stranger CA), written as PEM files |
//! | [`paused`] | a paused-time harness: the service's vehicle actors without transports under tokio's paused clock (idle eviction, health periods) |
//!
//! Map:
//!
//! End-to-end tests sit next to the crate they exercise, so each runs against that crate's public
//! API and `cargo test --workspace` runs them all:
//! - `server/tests/`: uavnavd on port 0, in process — a simulated flight over gRPC and over Zenoh
//!   equals the offline estimate (`e2e_flight.rs`), every bad-input case (`bad_input.rs`), many
//!   vehicles and HTTP endpoints (`fleet.rs`), Zenoh keys/queryables/liveliness (`zenoh.rs`),
//!   shutdown drain and eviction (`shutdown.rs`), configuration precedence (`config_precedence.rs`),
//!   idle eviction and health periods to the tick on a paused clock (`actor_time.rs`), recording
//!   (`record.rs`), TLS, principals and grants on gRPC/HTTP (`security.rs`) and Zenoh
//!   (`zenoh_security.rs`), admission at the vehicle limit (`admission.rs`);
//! - `client/tests/`: `library.rs` (the client library over gRPC and Zenoh against an in-process
//!   server), `secure_service.rs` (the library against the TLS service), `recording_reader.rs` (the library's MCAP recording reader on files of the kit's
//!   recording builder and of the service's recorder); helpers in `common/`;
//! - `cli/tests/`: `cli.rs` (each online CLI subcommand against an in-process server, `watch
//!   --foxglove` included), `loadtest.rs` (the load generator against the service and the discard
//!   sink, the JSON report field by field), `recording.rs` (record → replay gives the same poses),
//!   `logs.rs` (flight logs through `convert` and `estimate`); helpers in `common/`;
//! - `runner/tests/`, `estimator/tests/`, `vision/tests/`, `dataset/tests/`, `sim/tests/`: the pure
//!   crates' scenario, property, Jacobian, golden and real-data tests;
//! - `docker/test.sh`: the compose deployment (run by `.ci/run` when a Docker engine is present).

pub mod flight;
pub mod net;
pub mod paused;
pub mod pki;
pub mod recording;
pub mod service;
pub mod wire;

pub use uavnav_proto::v1 as pb;

/// Where the shared real data is, or why a test skips (`uavnav-testdata`, which the pure crates'
/// tests use without this kit).
pub use uavnav_testdata::shared_data;
