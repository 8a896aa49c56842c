//! # uavnavd
//!
//! The fleet estimation service: one process ingests IMU, GNSS and camera streams of many UAVs over
//! gRPC and Zenoh, runs one estimator per vehicle, and publishes pose and health streams.
//!
//! | module | responsibility |
//! |---|---|
//! | [`config`] | defaults → TOML file → `UAVNAV_*` environment → CLI flags |
//! | [`server`] | [`Server::start`]: binds the ports, wires everything, graceful shutdown |
//! | [`registry`] | vehicle id → actor handle; creation on first data, removal on eviction |
//! | [`actor`] | one task per vehicle owning its engine; bounded queues, reorder, overload policy |
//! | [`vehicle`] | the shared face of a vehicle: counters, ingest time gate, latest pose/health |
//! | [`reorder`] | the bounded timestamp reorder window |
//! | [`engine`] | the seam to the estimator ([`engine::Engine`]) |
//! | [`runner_engine`] | the product engine (the estimator runner) |
//! | [`vision_pool`] | bounded OS-thread pool for vision work |
//! | [`service`] | the transport-neutral facade the adapters call: authorization per request and message, then ingest or the registry |
//! | [`ingest`] | the transport-neutral ingest path (validate, gate, route, count) |
//! | [`validate`] | field-by-field input checks with precise statuses |
//! | [`conn`] | every TCP listener's accept loop: connection limits, idle timeout, TLS handshakes, the file-descriptor budget |
//! | [`grpc`] | the tonic `uavnav.v1.UavNav` service |
//! | [`zenoh_io`] | the embedded Zenoh session: inputs, outputs, queryables, liveliness |
//! | [`budget`] | the worst-case resident memory of a configuration (`--memory-budget`) |
//! | [`zenoh_stats`] | what Zenoh dropped on congested links, read from its runtime into `/metrics` |
//! | [`hub`] | broadcast fan-out of poses and health |
//! | (crate `uavnav-liveview`) | the Foxglove live view (WebSocket): pose, path, GNSS fix and camera per vehicle |
//! | [`health`] | per-vehicle health reports |
//! | [`metrics`] | Prometheus metrics |
//! | [`record`] | recording of accepted inputs and poses to rotating MCAP files |
//! | [`http`] | `/metrics`, `/livez`, `/readyz` |
//! | [`security`] | TLS (reloadable), principals and grants, the Zenoh access control, the exposure check |
//! | [`shutdown`] | signals and the drain order |
//! | [`logging`] | `tracing` subscriber setup |

pub mod actor;
pub mod budget;
pub mod config;
pub mod conn;
pub mod engine;
pub mod grpc;
pub mod health;
pub mod http;
pub mod hub;
pub mod ingest;
pub mod logging;
pub mod metrics;
pub mod record;
pub mod registry;
pub mod reorder;
pub mod runner_engine;
pub mod security;
pub mod server;
pub mod service;
pub mod shutdown;
pub mod validate;
pub mod vehicle;
pub mod vision_pool;
pub mod zenoh_io;
pub mod zenoh_stats;

use std::process::ExitCode;

pub use config::Config;
pub use server::{RunningServer, Server};

/// The `uavnavd` binary: parse the configuration, serve until SIGTERM/SIGINT, drain, exit 0.
pub fn run() -> ExitCode {
    let config = match Config::load(std::env::args_os(), |k| std::env::var(k).ok()) {
        Ok(c) => c,
        Err(config::ConfigError::Cli(e)) => {
            let _ = e.print();
            return if e.use_stderr() {
                ExitCode::from(2)
            } else {
                ExitCode::SUCCESS
            };
        }
        Err(e) => {
            eprintln!("uavnavd: {e}");
            return ExitCode::from(2);
        }
    };
    if std::env::args_os().any(|a| a == "--memory-budget") {
        println!("{}", budget::MemoryBudget::of(&config));
        return ExitCode::SUCCESS;
    }
    logging::init(&config.log);
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("uavnavd: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    let result = runtime.block_on(async {
        let server = Server::start(config).await?;
        server.run_until_signal().await
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!(error = format!("{e:#}"), "uavnavd failed");
            eprintln!("uavnavd: {e:#}");
            ExitCode::FAILURE
        }
    }
}
