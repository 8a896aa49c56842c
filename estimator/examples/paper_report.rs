//! Runs the paper scenarios through both profiles with and without (oracle) vision and prints the
//! accuracy table. The egomotion is synthesized from the simulator truth (a test oracle: ~0.01°
//! rotation, ~1° direction noise, 40 ms latency) until the vision crate is wired in.
//!
//! `CARGO_TARGET_DIR=/work/target-estimator cargo run --release -p uavnav-estimator --example paper_report [scenario…]`
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

#[path = "../tests/common/mod.rs"]
mod common;

use common::{Oracle, RunCfg, outages_ns, run, scenario};
use uavnav_core::FilterProfile;
use uavnav_estimator::accuracy::AccuracyReport;
use uavnav_sim::Flight;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let names: Vec<String> = if args.is_empty() {
        vec!["paper-small-lever".into(), "paper-big-lever".into()]
    } else {
        args
    };
    println!("{}", AccuracyReport::markdown_header());
    for name in names {
        let s = scenario(&name, None);
        let flight = Flight::new(&s).expect("scenario simulates");
        let outages = outages_ns(&s);
        for (label, cfg) in [
            (
                "eskf, GNSS+video",
                RunCfg::new(FilterProfile::Eskf, true, Some(Oracle::default())),
            ),
            (
                "eskf, GNSS only",
                RunCfg::new(FilterProfile::Eskf, true, None),
            ),
            (
                "paper, GNSS+video",
                RunCfg::new(FilterProfile::Paper, true, Some(Oracle::default())),
            ),
            (
                "paper, GNSS only",
                RunCfg::new(FilterProfile::Paper, true, None),
            ),
        ] {
            let t = std::time::Instant::now();
            let outs = run(&flight, &cfg);
            let el = t.elapsed().as_secs_f64();
            let r = AccuracyReport::compute(
                &format!("{name}: {label}"),
                &outs,
                flight.truth(),
                &outages,
            );
            println!(
                "{}  <!-- {:.2} s, {} outputs -->",
                r.markdown_row(),
                el,
                outs.len()
            );
            if std::env::var("REPORT_JSON").is_ok() {
                println!("{}", r.to_json());
            }
        }
    }
}
