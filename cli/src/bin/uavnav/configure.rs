//! `uavnav configure --vehicle ID (--dataset PATH | --scenario FILE.toml) [--profile P] [--no-camera]`:
//! create a vehicle or replace its configuration, taken from a dataset or a simulator scenario.

use std::path::PathBuf;

use uavnav_client::pb;
use uavnav_core::{FilterProfile, VehicleConfig};

use crate::common::{CliError, CliResult};
use crate::endpoint::{DEFAULT_URL, SecurityArgs, block_on, client_err, connect};

/// Arguments of `uavnav configure`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["dataset", "scenario"])))]
pub struct Args {
    /// Service URL (grpc://HOST:PORT, grpcs://HOST:PORT, zenoh, zenoh/tcp/HOST:PORT, zenoh/tls/HOST:PORT).
    #[arg(long, env = "UAVNAV_SERVICE", default_value = DEFAULT_URL)]
    pub from: String,
    /// TLS and token.
    #[command(flatten)]
    pub security: SecurityArgs,
    /// The vehicle to configure.
    #[arg(long)]
    pub vehicle: String,
    /// Take the configuration of this dataset (ASL folder or MCAP recording).
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    /// Take the configuration of this simulator scenario.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Override the filter profile: `eskf` or `paper`.
    #[arg(long, value_parser = parse_profile)]
    pub profile: Option<FilterProfile>,
    /// Configure without the camera.
    #[arg(long)]
    pub no_camera: bool,
}

fn parse_profile(s: &str) -> Result<FilterProfile, String> {
    s.parse()
}

/// The configuration the arguments describe.
pub fn load_config(
    dataset: Option<&PathBuf>,
    scenario: Option<&PathBuf>,
) -> Result<VehicleConfig, CliError> {
    if let Some(path) = dataset {
        let ds = uavnav_dataset::Dataset::open(path).map_err(CliError::input)?;
        return Ok(ds.config().clone());
    }
    if let Some(path) = scenario {
        let s = crate::simulate::load_scenario(path)?;
        let flight = uavnav_sim::Flight::new(&s)
            .map_err(|e| CliError::input(anyhow::anyhow!("{}: {e}", path.display())))?;
        return Ok(flight.vehicle_config());
    }
    Err(CliError::input(anyhow::anyhow!(
        "give --dataset or --scenario"
    )))
}

/// Runs the command; prints `created VEHICLE`, `reconfigured VEHICLE` or (Zenoh) `published VEHICLE`.
pub fn run(args: Args) -> CliResult {
    let mut config = load_config(args.dataset.as_ref(), args.scenario.as_ref())?;
    if let Some(p) = args.profile {
        config.profile = p;
    }
    if args.no_camera {
        config.camera = None;
    }
    let wire = pb::VehicleConfig::from(&config);
    block_on(async move {
        let client = connect(&args.from, &args.security).await?;
        let created = client
            .configure(&args.vehicle, &wire)
            .await
            .map_err(client_err)?;
        match created {
            Some(true) => println!("created {}", args.vehicle),
            Some(false) => println!("reconfigured {}", args.vehicle),
            None => println!("published {}", args.vehicle),
        }
        client.close().await;
        Ok(())
    })
}
