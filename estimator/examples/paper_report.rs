//! Runs the paper scenarios through both profiles with and without (oracle) vision and prints the
//! accuracy table. The egomotion is synthesized from the simulator truth (a test oracle: ~0.01°
//! rotation, ~1° direction noise, 40 ms latency) until the vision crate is wired in.
//!
//! `CARGO_TARGET_DIR=/work/target-estimator cargo run --release -p uavnav-estimator --example paper_report [scenario…]`
//! (`ORACLE_ROT_DEG`, `ORACLE_DIR_DEG`, `ORACLE_METRIC_REL` change the oracle's noise).
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap
#![allow(clippy::disallowed_methods)] // a timing tool: it measures wall time on purpose

#[path = "../tests/common/mod.rs"]
mod common;

use common::{Oracle, RunCfg, outages_ns, run, scenario};
use uavnav_core::FilterProfile;
use uavnav_report::accuracy::AccuracyReport;
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
        // ORACLE_ROT_DEG / ORACLE_DIR_DEG / ORACLE_METRIC_REL change the oracle's noise, to see
        // how the filter's attitude depends on the quality of the egomotion.
        let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
        let mut oracle = Oracle::default();
        if let Some(v) = env("ORACLE_ROT_DEG") {
            oracle.rot_sigma_rad = v.to_radians();
        }
        if let Some(v) = env("ORACLE_DIR_DEG") {
            oracle.dir_sigma_rad = v.to_radians();
        }
        oracle.metric_rel_sigma = env("ORACLE_METRIC_REL");
        for (label, cfg) in [
            (
                "eskf, GNSS+video",
                RunCfg::new(FilterProfile::Eskf, true, Some(oracle)),
            ),
            (
                "eskf, GNSS only",
                RunCfg::new(FilterProfile::Eskf, true, None),
            ),
            (
                "paper, GNSS+video",
                RunCfg::new(FilterProfile::Paper, true, Some(oracle)),
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
