//! # uavnavd
//!
//! The fleet estimation service: one process ingests IMU, GNSS and camera streams of many UAVs over
//! gRPC and Zenoh, runs one estimator per vehicle, and publishes pose and health streams.
//!
//! | module | responsibility |
//! |---|---|
//! | [`config`] | defaults → TOML file → `UAVNAV_*` environment → CLI flags |
//! | [`server`] | [`Server::start`]: binds the ports, wires everything, graceful shutdown |
//! | [`service`] | the transport-neutral facade the adapters call: authorization per request and message, then ingest or the registry |
//! | [`transport`] | the adapters: they move bytes and call [`service`]; no domain logic |
//! | [`transport::conn`] | every TCP listener's accept loop: connection limits, idle timeout, TLS handshakes, the file-descriptor budget |
//! | [`transport::grpc`] | the tonic `uavnav.v1.UavNav` service |
//! | [`transport::zenoh`] | the embedded Zenoh session: inputs, outputs, queryables, liveliness |
//! | [`transport::zenoh_stats`] | what Zenoh dropped on congested links, read from its runtime into `/metrics` |
//! | [`transport::http`] | `/metrics`, `/livez`, `/readyz` |
//! | [`ingest`] | the transport-neutral ingest path (validate, gate, route, count) |
//! | [`allocator`] | the allocator options of a long-running service (the binaries re-execute once with them), and the collection of an idle worker's heap |
//! | [`budget`] | the worst-case resident memory of a configuration (`--memory-budget`) |
//! | [`ingest::validate`] | field-by-field input checks with precise statuses |
//! | [`ingest::gate`] | the ingest time gate: late, duplicate, backwards, future, clock resync |
//! | [`vehicle`] | the vehicles; its root is the shared face of a vehicle ([`vehicle::shared`]): counters, the time gate's state, latest pose/health |
//! | [`vehicle::registry`] | vehicle id → actor handle; creation on first data, removal on eviction |
//! | [`vehicle::actor`] | one task per vehicle owning its engine; bounded queues, reorder, overload policy |
//! | [`vehicle::reorder`] | the bounded timestamp reorder window |
//! | [`vehicle::engine`] | the seam to the estimator ([`vehicle::engine::Engine`]) |
//! | [`vehicle::runner_engine`] | the product engine (the estimator runner) |
//! | [`vehicle::vision_pool`] | bounded OS-thread pool for vision work |
//! | [`output`] | what leaves the vehicles |
//! | [`output::hub`] | broadcast fan-out of poses and health |
//! | (crate `uavnav-liveview`) | the Foxglove live view (WebSocket): pose, path, GNSS fix and camera per vehicle |
//! | [`output::health`] | per-vehicle health reports |
//! | [`output::record`] | recording of accepted inputs and poses to rotating MCAP files |
//! | [`metrics`] | Prometheus metrics |
//! | [`process`] | the process's own CPU time and resident memory, for `/metrics` |
//! | [`security`] | TLS (reloadable), principals and grants, the Zenoh access control, the exposure check |
//! | [`shutdown`] | signals and the drain order |
//! | [`logging`] | `tracing` subscriber setup |
//!
//! The modules that moved into `transport/`, `ingest/`, `vehicle/` and `output/` stay reachable at
//! their former paths (`uavnavd::engine`, `uavnavd::registry`, `uavnavd::zenoh_io`, ...) through
//! the re-exports below.

pub mod allocator;
pub mod budget;
pub mod config;
pub mod ingest;
pub mod logging;
pub mod metrics;
pub mod output;
pub mod process;
pub mod security;
pub mod server;
pub mod service;
pub mod shutdown;
pub mod transport;
pub mod vehicle;

/// Re-exported at its former path (`uavnavd::validate`), from before `ingest/`.
pub use ingest::validate;
/// Re-exported at their former paths (`uavnavd::hub`, ...), from before `output/`.
pub use output::{health, hub, record};
/// Re-exported at its former path and name (`uavnavd::zenoh_io`), from before `transport/`.
pub use transport::zenoh as zenoh_io;
/// Re-exported at their former paths (`uavnavd::conn`, ...), from before `transport/`.
pub use transport::{conn, grpc, http, zenoh_stats};
/// Re-exported at their former paths (`uavnavd::engine`, `uavnavd::registry`, ...), from before
/// `vehicle/`.
pub use vehicle::{actor, engine, registry, reorder, runner_engine, vision_pool};

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
        .on_thread_park(|| {
            allocator::collect_on_park();
        })
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
