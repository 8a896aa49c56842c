//! Render speed: one 640×480 frame of the paper scenario (ray cast + texture + noise), its JPEG
//! encoding, and the whole `render_frame` path. `cargo bench -p uavnav-sim --bench render`.
#![allow(clippy::unwrap_used)]

use criterion::{Criterion, criterion_group, criterion_main};
use uavnav_sim::{Flight, Scenario, encode_jpeg};

fn bench(c: &mut Criterion) {
    let mut sc =
        Scenario::from_toml_str(include_str!("../../scenarios/paper-small-lever.toml")).unwrap();
    sc.duration_s = 30.0;
    let flight = Flight::new(&sc).unwrap();
    let _ = flight.render_frame(0).unwrap(); // builds the ray table
    let mut g = c.benchmark_group("render_640x480");
    g.sample_size(20);
    g.bench_function("render_gray_frame (all threads)", |b| {
        b.iter(|| flight.render_gray_frame(250, true).unwrap())
    });
    let img = flight.render_gray_frame(250, true).unwrap();
    g.bench_function("encode_jpeg q90", |b| {
        b.iter(|| encode_jpeg(&img, 90).unwrap())
    });
    g.bench_function("render_frame (render + JPEG, all threads)", |b| {
        b.iter(|| flight.render_frame(250).unwrap())
    });
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    g.bench_function("render_frame (one thread)", |b| {
        b.iter(|| pool.install(|| flight.render_frame(250).unwrap()))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
