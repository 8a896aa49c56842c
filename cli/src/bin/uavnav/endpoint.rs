//! What the online subcommands share: the service URL argument, the async runtime, connecting,
//! and mapping client errors onto exit codes.

use std::future::Future;

use uavnav_client::{Client, ClientError, ConnectOptions, Endpoint};

use crate::common::{CliError, CliResult};

/// Default service URL of `--from` / `--to`.
pub const DEFAULT_URL: &str = "grpc://127.0.0.1:50051";

/// Runs an async command on a fresh multi-threaded runtime.
pub fn block_on<F: Future<Output = CliResult>>(f: F) -> CliResult {
    block_on_threads(0, f)
}

/// Like [`block_on`] on `threads` worker threads: 0 = one per core, 1 = a single-threaded
/// runtime (no cross-thread wake-ups).
pub fn block_on_threads<F: Future<Output = CliResult>>(threads: usize, f: F) -> CliResult {
    let rt = match threads {
        0 => tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build(),
        1 => tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build(),
        n => tokio::runtime::Builder::new_multi_thread()
            .worker_threads(n)
            .enable_all()
            .build(),
    }
    .map_err(|e| CliError::runtime(anyhow::anyhow!("cannot start the async runtime: {e}")))?;
    rt.block_on(f)
}

/// Parses a service URL (bad URL = exit 2).
pub fn parse(url: &str) -> Result<Endpoint, CliError> {
    url.parse::<Endpoint>().map_err(CliError::input)
}

/// Parses and connects (unreachable = exit 1).
pub async fn connect(url: &str) -> Result<Client, CliError> {
    let ep = parse(url)?;
    Client::connect(&ep, ConnectOptions::default())
        .await
        .map_err(client_err)
}

/// Maps a client error to its exit code: the caller's fault (bad id, unknown vehicle, refused
/// argument) = 2, anything else = 1.
pub fn client_err(e: ClientError) -> CliError {
    let input = match &e {
        ClientError::Endpoint { .. }
        | ClientError::InvalidId { .. }
        | ClientError::NotFound(_)
        | ClientError::Unsupported { .. } => true,
        ClientError::Rpc { code, .. } => matches!(
            code,
            tonic::Code::InvalidArgument
                | tonic::Code::NotFound
                | tonic::Code::FailedPrecondition
                | tonic::Code::OutOfRange
        ),
        _ => false,
    };
    if input {
        CliError::input(e)
    } else {
        CliError::runtime(e)
    }
}

/// Mode name as in the `estimate` CSV.
pub fn mode_name(m: i32) -> &'static str {
    use uavnav_client::pb::EstimatorMode;
    match EstimatorMode::try_from(m).unwrap_or(EstimatorMode::Unspecified) {
        EstimatorMode::Unspecified => "unknown",
        EstimatorMode::Initialising => "initialising",
        EstimatorMode::Nominal => "nominal",
        EstimatorMode::GnssDeniedVision => "gnss_denied_vision",
        EstimatorMode::InertialOnly => "inertial_only",
        EstimatorMode::Diverged => "diverged",
    }
}
