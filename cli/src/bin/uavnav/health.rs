//! `uavnav health [--from URL] [--vehicle ID]… [--all] [--wait S] [--follow] [--max-age S] [--json]`:
//! check the service and print vehicles' health.
//!
//! Without `--vehicle`/`--all` it only checks that the service answers (a container HEALTHCHECK).
//! With them it collects health reports for `--wait` seconds (or forever with `--follow`) and
//! prints the latest per vehicle. `--max-age S` makes it exit 3 when a selected vehicle's newest
//! input is older than S seconds, or unknown.

use std::collections::BTreeMap;
use std::time::Duration;

use uavnav_client::{Selector, pb, unix_now_ns};

use crate::common::{CliError, CliResult};
use crate::endpoint::{DEFAULT_URL, SecurityArgs, block_on, client_err, connect, mode_name};

/// Arguments of `uavnav health`.
#[derive(Debug, clap::Args)]
#[command(after_help = crate::EXIT_CODES)]
pub struct Args {
    /// Service URL (grpc://HOST:PORT, grpcs://HOST:PORT, zenoh, zenoh/tcp/HOST:PORT, zenoh/tls/HOST:PORT).
    #[arg(long, env = "UAVNAV_SERVICE", default_value = DEFAULT_URL)]
    pub from: String,
    /// TLS and token.
    #[command(flatten)]
    pub security: SecurityArgs,
    /// A vehicle to report (repeatable).
    #[arg(long)]
    pub vehicle: Vec<String>,
    /// Every vehicle.
    #[arg(long, conflicts_with = "vehicle")]
    pub all: bool,
    /// How long to collect health reports, s.
    #[arg(long, default_value_t = 1.5)]
    pub wait: f64,
    /// Print every report as it arrives, until interrupted.
    #[arg(long)]
    pub follow: bool,
    /// Exit 3 when a selected vehicle's newest input is older than this, s (or it is unknown).
    #[arg(long)]
    pub max_age: Option<f64>,
    /// JSON lines instead of a table.
    #[arg(long)]
    pub json: bool,
}

fn header() -> String {
    format!(
        "{:<20} {:<18} {:<8} {:<7} {:>7} {:>6} {:>6} {:>9} {:>9} {:>8} {:>6} {:>6} {:>7}",
        "vehicle_id",
        "mode",
        "heading",
        "compass",
        "imu_hz",
        "gnss_hz",
        "cam_hz",
        "p99_ms",
        "accepted",
        "rejected",
        "late",
        "shed",
        "dropped"
    )
}

fn line(h: &pb::VehicleHealth, json: bool) -> String {
    let r = h.input_rates.unwrap_or_default();
    let l = h.latency.unwrap_or_default();
    let c = h.counters.unwrap_or_default();
    let hd = h.heading.unwrap_or_default();
    let (heading, compass) = (heading_name(hd.source), magnetometer_name(hd.magnetometer));
    if json {
        return serde_json::json!({
            "vehicle_id": h.vehicle_id, "mode": mode_name(h.mode), "t_ns": h.t_ns, "wall_ns": h.wall_ns,
            "heading_source": heading, "magnetometer": compass,
            "magnetometer_disturbed": hd.magnetometer_disturbed, "yaw_resets": hd.yaw_resets,
            "magnetometer_calibration": calibration_name(hd.magnetometer_calibration),
            "magnetometer_offset_t": hd.magnetometer_offset_t.map(|v| [v.x, v.y, v.z]),
            "magnetometer_calibration_test_ratio": hd.magnetometer_calibration_test_ratio,
            "magnetometer_calibration_restarts": hd.magnetometer_calibration_restarts,
            "imu_noise_gyro_ratio": h.imu_noise.map(|n| n.gyro_ratio),
            "imu_noise_accel_ratio": h.imu_noise.map(|n| n.accel_ratio),
            "imu_hz": r.imu_hz, "gnss_hz": r.gnss_hz, "camera_hz": r.camera_hz,
            "latency_p50_s": l.p50_s, "latency_p99_s": l.p99_s, "latency_max_s": l.max_s,
            "accepted": c.accepted, "rejected": c.rejected, "late": c.late, "shed": c.shed, "dropped": c.dropped,
            "gnss_gate_rejections": c.gnss_gate_rejections, "vision_gate_rejections": c.vision_gate_rejections,
            "imu_clipped": c.imu_clipped, "imu_gaps_bridged": c.imu_gaps_bridged,
        })
        .to_string();
    }
    format!(
        "{:<20} {:<18} {:<8} {:<7} {:>7.1} {:>6.1} {:>6.1} {:>9.2} {:>9} {:>8} {:>6} {:>6} {:>7}",
        h.vehicle_id,
        mode_name(h.mode),
        heading,
        compass,
        r.imu_hz,
        r.gnss_hz,
        r.camera_hz,
        l.p99_s * 1e3,
        c.accepted,
        c.rejected,
        c.late,
        c.shed,
        c.dropped
    )
}

/// `VehicleHealth.heading.source` in a word.
fn heading_name(s: i32) -> &'static str {
    use uavnav_client::pb::HeadingSource as H;
    match H::try_from(s).unwrap_or(H::Unspecified) {
        H::Unspecified => "-",
        H::Unknown => "unknown",
        H::Magnetometer => "compass",
        H::YawEstimator => "yaw_bank",
        H::Course => "course",
    }
}

/// `VehicleHealth.heading.magnetometer_calibration` in a word.
fn calibration_name(s: i32) -> &'static str {
    use uavnav_client::pb::MagnetometerCalibration as C;
    match C::try_from(s).unwrap_or(C::Unspecified) {
        C::Unspecified => "-",
        C::Off => "off",
        C::Learning => "learning",
        C::Applied => "applied",
    }
}

/// `VehicleHealth.heading.magnetometer` in a word.
fn magnetometer_name(s: i32) -> &'static str {
    use uavnav_client::pb::MagnetometerState as M;
    match M::try_from(s).unwrap_or(M::Unspecified) {
        M::Unspecified => "-",
        M::Off => "off",
        M::Active => "active",
        M::StoppedDead => "dead",
        M::StoppedContradicted => "stopped",
    }
}

/// Runs the command.
pub fn run(args: Args) -> CliResult {
    block_on(async move {
        let client = connect(&args.from, &args.security).await?;
        let known = client.list_vehicles("").await.map_err(client_err)?;
        let sel = if args.all {
            Selector::all()
        } else {
            Selector::ids(args.vehicle.clone())
        };
        if sel.is_empty() {
            println!("ok: {} serving {} vehicles", client.endpoint(), known.len());
            return check_ages(&args, &known);
        }
        let mut watch = client.watch_health(sel).await.map_err(client_err)?;
        let mut latest: BTreeMap<String, pb::VehicleHealth> = BTreeMap::new();
        if args.follow && !args.json {
            println!("{}", header());
        }
        let deadline = tokio::time::sleep(Duration::from_secs_f64(args.wait.max(0.0)));
        tokio::pin!(deadline);
        loop {
            tokio::select! {
                _ = &mut deadline, if !args.follow => break,
                h = watch.next() => match h {
                    Some(Ok(h)) => {
                        if args.follow {
                            println!("{}", line(&h, args.json));
                        }
                        latest.insert(h.vehicle_id.clone(), h);
                    }
                    Some(Err(e)) => return Err(client_err(e)),
                    None => break,
                },
            }
        }
        if !args.json {
            println!("{}", header());
        }
        for h in latest.values() {
            println!("{}", line(h, args.json));
        }
        for id in &args.vehicle {
            if !latest.contains_key(id) {
                eprintln!(
                    "uavnav: no health report from '{id}' within {:.1} s",
                    args.wait
                );
            }
        }
        check_ages(&args, &known)
    })
}

/// `--max-age`: every selected vehicle must be known and fed recently.
fn check_ages(args: &Args, known: &[pb::VehicleSummary]) -> CliResult {
    let Some(max_age) = args.max_age else {
        return Ok(());
    };
    let now = unix_now_ns();
    let mut stale = Vec::new();
    let selected: Vec<&str> = if args.all || args.vehicle.is_empty() {
        known.iter().map(|v| v.vehicle_id.as_str()).collect()
    } else {
        args.vehicle.iter().map(String::as_str).collect()
    };
    for id in selected {
        match known.iter().find(|v| v.vehicle_id == id) {
            None => stale.push(format!("{id} is not known to the service")),
            Some(v) => {
                let age = (now - v.last_input_wall_ns) as f64 * 1e-9;
                if v.last_input_wall_ns <= 0 || age > max_age {
                    stale.push(format!("{id}: last input {age:.1} s ago (> {max_age} s)"));
                }
            }
        }
    }
    if stale.is_empty() {
        Ok(())
    } else {
        Err(CliError::Target(stale.join("; ")))
    }
}
