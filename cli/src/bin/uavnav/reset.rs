//! `uavnav reset --vehicle ID [--from URL]`: restart a vehicle's estimator (gRPC only).

use crate::common::CliResult;
use crate::endpoint::{DEFAULT_URL, SecurityArgs, block_on, client_err, connect};

/// Arguments of `uavnav reset`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// Service URL, grpc://HOST:PORT or grpcs://HOST:PORT (reset exists over gRPC only).
    #[arg(long, env = "UAVNAV_SERVICE", default_value = DEFAULT_URL)]
    pub from: String,
    /// TLS and token.
    #[command(flatten)]
    pub security: SecurityArgs,
    /// The vehicle to reset (unknown vehicle = exit 2).
    #[arg(long)]
    pub vehicle: String,
}

/// Runs the command; prints `reset VEHICLE` on success.
pub fn run(args: Args) -> CliResult {
    block_on(async move {
        let client = connect(&args.from, &args.security).await?;
        client.reset(&args.vehicle).await.map_err(client_err)?;
        println!("reset {}", args.vehicle);
        Ok(())
    })
}
