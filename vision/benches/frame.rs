//! Decode + track + solve per 640×480 JPEG frame (target ≤ 2.0 ms median on one core).
//!
//! Frames: see `common/mod.rs` (synthetic ground from 150 m, ~3 m per frame, JPEG quality 90,
//! run back and forth with the IMU/terrain prior of each pair). Also prints the per-stage
//! medians and the median of the per-frame totals from the front end's own stage clock: on a
//! shared machine criterion's times include preemption by other processes, these medians mostly
//! do not.
//!
//! `nice -n 10 cargo bench -p uavnav-vision --bench frame`
#![allow(clippy::disallowed_methods)] // a timing tool: it measures wall time on purpose
#![allow(clippy::unwrap_used)]

mod common;

use std::time::Instant;

use common::{camera, schedule, sequence};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Isometry3;
use uavnav_core::ImageFormat;
use uavnav_vision::{FrontEnd, Method, SolveParams, VisionParams};

fn bench_frame(c: &mut Criterion) {
    let seq = sequence(12);
    let sched = schedule(&seq);
    for (label, method) in [("auto", Method::Auto), ("essential", Method::Essential)] {
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
        let mut i = 0usize;
        let mut stages: Vec<[u64; 4]> = Vec::new();
        let mut ok = 0usize;
        c.bench_function(&format!("frame_640x480_jpeg_{label}"), |b| {
            b.iter(|| {
                let (k, p) = &sched[i % sched.len()];
                let r = fe.process(i as i64, ImageFormat::Jpeg, &seq.jpegs[*k], p);
                i += 1;
                let t = r.timings;
                stages.push([
                    t.decode_us,
                    t.track_us,
                    t.solve_us,
                    t.decode_us + t.track_us + t.solve_us,
                ]);
                ok += usize::from(r.outcome.is_ok());
                r.tracked
            })
        });
        let med = |j: usize| {
            let mut v: Vec<u64> = stages.iter().map(|s| s[j]).collect();
            v.sort_unstable();
            v.get(v.len() / 2).copied().unwrap_or(0)
        };
        println!(
            "{label}: {} frames, {ok} measurements; stage medians: decode {} µs, track {} µs, solve {} µs; per-frame total median {} µs",
            stages.len(),
            med(0),
            med(1),
            med(2),
            med(3)
        );
    }
    let mut dec = uavnav_vision::decode::LumaDecoder::new(640, 480);
    c.bench_function("decode_640x480_jpeg_luma", |b| {
        b.iter(|| dec.decode(ImageFormat::Jpeg, &seq.jpegs[3]).map(|y| y[0]))
    });
}

criterion_group!(benches, bench_frame);
criterion_main!(benches);
