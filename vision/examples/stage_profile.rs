//! Per-stage timings of [`FrontEnd::process`] on the benchmark's frames (developer aid; the
//! criterion benchmark `benches/frame.rs` is the reference figure).
//!
//! `nice -n 10 cargo run --release -p uavnav-vision --example stage_profile -- [FRAMES] [essential]`
//!
//! Prints the median of each stage (wall clock, µs) and the mean CPU time of this thread per
//! frame (from `/proc/thread-self/schedstat`, Linux; less sensitive to other load on the machine
//! than the wall clock). Under `valgrind --tool=callgrind` with few frames it gives instruction
//! counts per function.
#![allow(clippy::disallowed_methods)] // a timing tool: it measures wall time on purpose

#[path = "../benches/common/mod.rs"]
mod common;

use std::time::Instant;

use common::{camera, schedule, sequence};
use nalgebra::Isometry3;
use uavnav_core::ImageFormat;
use uavnav_vision::{FrontEnd, Method, SolveParams, VisionParams};

/// CPU time this thread has run, ns (`None` off Linux).
fn thread_cpu_ns() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

fn median(mut v: Vec<u64>) -> u64 {
    v.sort_unstable();
    v.get(v.len() / 2).copied().unwrap_or(0)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let frames: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(600);
    let method = match args.next().as_deref() {
        Some("essential") => Method::Essential,
        _ => Method::Auto,
    };
    let seq = sequence(12);
    let sched = schedule(&seq);
    let params = VisionParams {
        solve: SolveParams {
            method,
            ..SolveParams::default()
        },
        ..VisionParams::default()
    };
    let mut fe = FrontEnd::new(&camera(), Isometry3::identity(), params);
    let origin = Instant::now();
    fe.set_clock(Box::new(move || origin.elapsed().as_micros() as u64));
    let mut rows: Vec<[u64; 7]> = Vec::with_capacity(frames);
    let (mut ok, mut tracked) = (0usize, 0usize);
    let cpu0 = thread_cpu_ns();
    let wall0 = Instant::now();
    for i in 0..frames {
        let (k, p) = &sched[i % sched.len()];
        let r = fe.process(i as i64, ImageFormat::Jpeg, &seq.jpegs[*k], p);
        let t = r.timings;
        rows.push([
            t.decode_us,
            t.track_us,
            t.solve_us,
            t.pyramid_us,
            t.klt_us,
            t.detect_us,
            t.decode_us + t.track_us + t.solve_us,
        ]);
        ok += usize::from(r.outcome.is_ok());
        tracked += r.tracked as usize;
    }
    let wall_us = wall0.elapsed().as_secs_f64() * 1e6 / frames as f64;
    let cpu_us = match (cpu0, thread_cpu_ns()) {
        (Some(a), Some(b)) => format!("{:.0}", (b - a) as f64 / 1e3 / frames as f64),
        _ => "n/a".into(),
    };
    let med = |j: usize| median(rows.iter().map(|r| r[j]).collect());
    println!(
        "{frames} frames ({method:?}), {ok} measurements, mean tracked {:.0}",
        tracked as f64 / frames as f64
    );
    println!(
        "median µs: decode {}  track {} (pyramid+checks {}, klt {}, detect {})  solve {}  total {}",
        med(0),
        med(1),
        med(3),
        med(4),
        med(5),
        med(2),
        med(6)
    );
    println!("mean per frame: wall {wall_us:.0} µs, thread CPU {cpu_us} µs");
}
