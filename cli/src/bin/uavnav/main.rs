//! `uavnav`: the uavnav command-line tool.
//!
//! One file per subcommand; `main` only parses and dispatches. Results go to stdout (or `--out`),
//! diagnostics to stderr. Exit codes (also in `--help`):
//! - 0: success;
//! - 1: the command failed at run time (I/O, service unreachable, ...);
//! - 2: bad usage or bad input (a malformed dataset, scenario or argument; TLS or token settings
//!   that cannot be used; credentials or grants the service refuses), with a one-line reason;
//! - 3: the command ran but a checked target was missed (e.g. `loadtest` fell behind real time).

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod certs;
mod certs_der;
mod common;
mod convert;
mod demo;
mod estimate;
mod estimate_report;
mod simulate;
mod vision;
// online subcommands (issue 6); their TLS and token options are in `endpoint`

mod configure;
mod endpoint;
mod health;
mod loadtest;
mod machine_ref;
mod record;
mod replay;
mod reset;
mod service_cpu;
mod vehicles;
mod watch;

const EXIT_CODES: &str = "Exit codes: 0 success; 1 run-time failure (I/O, service unreachable); \
2 bad usage or bad input (one-line reason on stderr), including TLS or token settings that cannot \
be used and credentials or grants the service refuses; 3 a checked target was missed.";

/// uavnav: position and attitude of UAVs from IMU, GNSS and camera.
#[derive(Debug, Parser)]
#[command(name = "uavnav", version, about, after_help = EXIT_CODES)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The main job: an in-process uavnavd fed a simulated flight over gRPC and Zenoh, with an accuracy table.
    Demo(demo::Args),
    /// Simulate a flight from a scenario file into an ASL folder or an MCAP recording.
    Simulate(simulate::Args),
    /// Convert a dataset between the ASL folder layout and MCAP (or a flight log .BIN/.ulg/.tlog into either).
    Convert(convert::Args),
    /// Estimate poses offline from an ASL folder, an MCAP recording or a flight log (.BIN, .ulg, .tlog).
    Estimate(estimate::Args),
    /// Run the vision front end on consecutive frame pairs and write the egomotion per pair.
    Vision(vision::Args),
    /// Stream a recording (or N copies) into a service at real time or faster.
    Replay(replay::Args),
    /// Print or record the poses (and health) a service publishes.
    Watch(watch::Args),
    /// Record what a service receives and publishes as MCAP (replayable).
    Record(record::Args),
    /// List the vehicles a service knows.
    Vehicles(vehicles::Args),
    /// Check a service and print vehicles' health.
    Health(health::Args),
    /// Create a vehicle or replace its configuration.
    Configure(configure::Args),
    /// Restart a vehicle's estimator.
    Reset(reset::Args),
    /// Drive N vehicles at real rates and measure latency, throughput and errors.
    Loadtest(loadtest::Args),
    /// Make a private CA, service and ground-station certificates, and bearer tokens.
    Certs(certs::Args),
}

/// mimalloc, as in `uavnavd`: the load generator and the in-process service of `demo` allocate a
/// few small buffers per message.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    run()
}

fn run() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(a) => demo::run(a),
        Command::Simulate(a) => simulate::run(a),
        Command::Convert(a) => convert::run(a),
        Command::Estimate(a) => estimate::run(a),
        Command::Vision(a) => vision::run(a),
        Command::Replay(a) => replay::run(a),
        Command::Watch(a) => watch::run(a),
        Command::Record(a) => record::run(a),
        Command::Vehicles(a) => vehicles::run(a),
        Command::Health(a) => health::run(a),
        Command::Configure(a) => configure::run(a),
        Command::Reset(a) => reset::run(a),
        Command::Loadtest(a) => loadtest::run(a),
        Command::Certs(a) => certs::run(a),
    };
    common::finish(result)
}
