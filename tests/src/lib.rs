//! The workspace's test map (this crate holds no tests of its own yet).
//!
//! End-to-end tests sit next to the crate they exercise, so each runs against that crate's public
//! API and `cargo test --workspace` runs them all:
//! - `server/tests/`: uavnavd on port 0, in process — a simulated flight over gRPC and over Zenoh
//!   equals the offline estimate (`e2e_flight.rs`), every bad-input case (`bad_input.rs`), many
//!   vehicles and HTTP endpoints (`fleet.rs`), Zenoh keys/queryables/liveliness (`zenoh.rs`),
//!   shutdown drain and eviction (`shutdown.rs`), configuration precedence (`config_precedence.rs`);
//! - `client/tests/`: `library.rs` (the client library over gRPC and Zenoh), `cli.rs` (each online
//!   CLI subcommand against an in-process server, `watch --foxglove` included), `loadtest.rs` (the
//!   load generator against the service and the discard sink, the JSON report field by field),
//!   `recording.rs` (record → replay gives the same poses); helpers in `common/`;
//! - `runner/tests/`, `estimator/tests/`, `vision/tests/`, `dataset/tests/`, `sim/tests/`: the pure
//!   crates' scenario, property, Jacobian, golden and real-data tests;
//! - `docker/test.sh`: the compose deployment (run by `.ci/run` when a Docker engine is present).
