//! CPU-time helper for a loaded machine (criterion's wall clock suffers when cores are shared):
//! `/usr/bin/time -f %U target/release/examples/speed MODE REPEATS` with MODE = sim | eskf | eskf-video | paper;
//! (user time of MODE − user time of `sim`) / (REPEATS × samples) is the per-sample cost.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

#[path = "../tests/common/mod.rs"]
mod common;

use common::{Oracle, RunCfg, run, scenario};
use uavnav_core::FilterProfile;
use uavnav_sim::Flight;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mode = args.first().cloned().unwrap_or_else(|| "eskf".into());
    let repeats: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(5);
    let s = scenario("paper-small-lever", None);
    let flight = Flight::new(&s).expect("flight");
    let cfg = match mode.as_str() {
        "sim" => return println!("{} IMU samples", flight.imu().len()),
        "eskf" => RunCfg::new(FilterProfile::Eskf, true, None),
        "eskf-video" => RunCfg::new(FilterProfile::Eskf, true, Some(Oracle::default())),
        _ => RunCfg::new(FilterProfile::Paper, true, None),
    };
    let mut n = 0;
    for _ in 0..repeats {
        n += run(&flight, &cfg).len();
    }
    println!(
        "{n} outputs over {repeats} runs of {} IMU samples",
        flight.imu().len()
    );
}
