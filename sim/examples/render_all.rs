//! Renders every camera frame of a scenario in memory (JPEG included) and prints the wall time.
//!
//! `cargo run --release -p uavnav-sim --example render_all -- [SCENARIO.toml] [--save DIR N]`
//! (`--save` also writes every N-th frame into DIR as JPEG and PNG, to look at them).
#![allow(clippy::disallowed_methods)] // a timing tool: it measures wall time on purpose

use std::time::Instant;

use rayon::prelude::*;
use uavnav_sim::{Flight, Scenario};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args
        .first()
        .cloned()
        .unwrap_or_else(|| "scenarios/paper-small-lever.toml".into());
    let save = match args.iter().position(|a| a == "--save") {
        Some(i) => Some((
            args.get(i + 1).ok_or("--save DIR N")?.clone(),
            args.get(i + 2).ok_or("--save DIR N")?.parse::<usize>()?,
        )),
        None => None,
    };
    let text = std::fs::read_to_string(&path)?;
    let scenario = Scenario::from_toml_str(&text).map_err(|e| format!("{path}: {e}"))?;
    let t = Instant::now();
    let flight = Flight::new(&scenario)?;
    let sim_s = t.elapsed().as_secs_f64();
    let n = flight.camera_times_ns().len();
    let t = Instant::now();
    let cpu0 = cpu_time_s();
    let bytes: usize = (0..n)
        .into_par_iter()
        .map(|i| flight.render_frame(i).map(|f| f.data.len()))
        .collect::<Result<Vec<_>, _>>()?
        .iter()
        .sum();
    let render_s = t.elapsed().as_secs_f64();
    let cpu_s = cpu_time_s().zip(cpu0).map(|(b, a)| b - a);
    println!(
        "{path}: simulate {sim_s:.2} s; {n} frames rendered + JPEG in {render_s:.2} s on {} threads ({:.1} ms/frame wall, {:.0} KiB/frame)",
        rayon::current_num_threads(),
        1e3 * render_s / n.max(1) as f64,
        bytes as f64 / 1024.0 / n.max(1) as f64
    );
    if let Some(cpu_s) = cpu_s {
        println!(
            "process CPU time while rendering: {cpu_s:.1} s ({:.1} ms/frame)",
            1e3 * cpu_s / n.max(1) as f64
        );
    }
    if let Some((dir, every)) = save {
        std::fs::create_dir_all(&dir)?;
        for i in (0..n).step_by(every.max(1)) {
            std::fs::write(
                format!("{dir}/frame_{i:05}.jpg"),
                &flight.render_frame(i)?.data,
            )?;
            flight
                .render_gray_frame(i, true)?
                .save(format!("{dir}/frame_{i:05}.png"))?;
        }
    }
    Ok(())
}

/// User + system CPU time of this process, s (Linux `/proc/self/stat`), to measure render cost
/// independently of other load on the machine.
fn cpu_time_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}
