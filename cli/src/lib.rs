//! # uavnav-cli
//!
//! The `uavnav` command-line tool (`src/bin/uavnav/`, one file per subcommand) and the engines
//! behind its online subcommands, kept in this library part so that the tests (`tests/`) use them
//! directly. The client library itself is the separate crate `uavnav-client` (what a
//! ground-station backend adds); this crate adds the simulator, the estimator, the datasets, the
//! report and the in-process service of `demo` on top of it.
//!
//! | module | what it holds |
//! |---|---|
//! | [`schedule`] | sensor events → timed wire messages (IMU batching, speed, time offsets) |
//! | [`load`] | the load generator and its latency/throughput measurement (coordinated-omission correct) |
//! | [`report`] | the load test report: ghz-like JSON and the text table |
//! | [`posefmt`] | wire poses → the `uavnav estimate` CSV columns and TUM lines |
//!
//! | binary module (`src/bin/uavnav/`) | subcommand |
//! |---|---|
//! | `demo` | the main job: an in-process uavnavd fed a simulated flight over gRPC and Zenoh, with an accuracy table |
//! | `simulate`, `convert`, `estimate` (+ `estimate_report`), `vision` | offline: simulation, dataset conversion, estimation and its report, vision front end |
//! | `replay`, `watch`, `record` | online: stream a recording in, print/record poses (and the Foxglove live view), record a service's traffic |
//! | `vehicles`, `health`, `configure`, `reset` | fleet management |
//! | `loadtest` | N vehicles at real rates against a service (or the discard sink) |
//! | `common`, `endpoint` | exit codes and error classes; service URLs and connecting |

pub mod load;
pub mod posefmt;
pub mod report;
pub mod schedule;
