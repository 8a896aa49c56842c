//! `uavnav vehicles [--from URL] [--prefix P] [--json]`: the vehicles a service knows.

use uavnav_client::unix_now_ns;

use crate::common::{CliError, CliResult};
use crate::endpoint::{DEFAULT_URL, SecurityArgs, block_on, client_err, connect, mode_name};

/// Arguments of `uavnav vehicles`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// Service URL (grpc://HOST:PORT, grpcs://HOST:PORT, zenoh, zenoh/tcp/HOST:PORT, zenoh/tls/HOST:PORT).
    #[arg(long, env = "UAVNAV_SERVICE", default_value = DEFAULT_URL)]
    pub from: String,
    /// TLS and token.
    #[command(flatten)]
    pub security: SecurityArgs,
    /// Only vehicles whose id starts with this.
    #[arg(long, default_value = "")]
    pub prefix: String,
    /// One JSON object per line instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Runs the command: a table `vehicle_id mode last_t_s input_age_s configured` on stdout.
pub fn run(args: Args) -> CliResult {
    block_on(async move {
        let client = connect(&args.from, &args.security).await?;
        let list = client
            .list_vehicles(&args.prefix)
            .await
            .map_err(client_err)?;
        let now = unix_now_ns();
        if !args.json {
            println!(
                "{:<24} {:<20} {:>16} {:>12} {:>10}",
                "vehicle_id", "mode", "last_t_s", "input_age_s", "configured"
            );
        }
        for v in &list {
            let age_s = if v.last_input_wall_ns > 0 {
                (now - v.last_input_wall_ns) as f64 * 1e-9
            } else {
                f64::NAN
            };
            let t_s = v.last_t_ns as f64 * 1e-9;
            if args.json {
                let line = serde_json::json!({
                    "vehicle_id": v.vehicle_id, "mode": mode_name(v.mode), "last_t_s": t_s,
                    "input_age_s": if age_s.is_finite() { Some(age_s) } else { None }, "configured": v.configured,
                });
                println!("{line}");
            } else {
                println!(
                    "{:<24} {:<20} {:>16.3} {:>12.3} {:>10}",
                    v.vehicle_id,
                    mode_name(v.mode),
                    t_s,
                    age_s,
                    v.configured
                );
            }
        }
        eprintln!("uavnav: {} vehicles at {}", list.len(), client.endpoint());
        client.close().await;
        Ok::<(), CliError>(())
    })
}
