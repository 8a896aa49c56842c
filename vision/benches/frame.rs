//! Decode + track + solve per 640×480 JPEG frame (target ≤ 2.0 ms median on one core).
//!
//! Frames: a synthetic ground texture seen from 150 m by a downward camera moving ~3 m per frame,
//! encoded as JPEG (quality 90). The front end runs the frames back and forth (so the sequence
//! never jumps) with the IMU/terrain prior of each pair. Also prints the per-stage medians.

#![allow(clippy::unwrap_used)]

use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};
use uavnav_core::{CameraModel, Distortion, ImageFormat, MotionPrior};
use uavnav_vision::synthetic::{Texture, render_ground};
use uavnav_vision::{FrontEnd, Method, SolveParams, VisionParams};

fn camera() -> CameraModel {
    CameraModel {
        width: 640,
        height: 480,
        fx: 500.0,
        fy: 500.0,
        cx: 319.5,
        cy: 239.5,
        distortion: Distortion::RadTan {
            k1: -0.1,
            k2: 0.02,
            p1: 0.0002,
            p2: -0.0001,
        },
    }
}

fn pose(k: f64) -> Isometry3<f64> {
    let base = UnitQuaternion::from_basis_unchecked(&[Vector3::y(), -Vector3::x(), Vector3::z()]);
    let q =
        UnitQuaternion::from_euler_angles(0.02 * (0.5 * k).sin(), 0.01 * k.cos(), 0.2 + 0.004 * k)
            * base;
    Isometry3::from_parts(Translation3::new(3.0 * k, 0.5 * k, -150.0), q)
}

struct Sequence {
    jpegs: Vec<Vec<u8>>,
    poses: Vec<Isometry3<f64>>,
}

fn sequence(n: usize) -> Sequence {
    let cam = camera();
    let tex = Texture::new(21);
    let poses: Vec<_> = (0..n).map(|k| pose(k as f64)).collect();
    let jpegs = poses
        .iter()
        .map(|p| {
            let img = image::GrayImage::from_raw(640, 480, render_ground(&tex, &cam, p, 1.5))
                .expect("size");
            let mut out = Vec::new();
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
                .encode_image(&img)
                .expect("encode");
            out
        })
        .collect();
    Sequence { jpegs, poses }
}

fn prior(a: &Isometry3<f64>, b: &Isometry3<f64>) -> MotionPrior {
    let rel = b.inverse() * a;
    MotionPrior {
        cam1_from_cam0: Some(rel.rotation),
        rot_sigma_rad: 1e-3,
        ground_normal_cam0: Some(Unit::new_normalize(a.rotation.inverse() * Vector3::z())),
        ground_distance_m: Some(150.0),
        t_cam1_m: Some(rel.translation.vector),
    }
}

/// Frame order 0,1,…,n−1,n−2,…,1,0,1,… and the prior of each step.
fn schedule(seq: &Sequence) -> Vec<(usize, MotionPrior)> {
    let n = seq.poses.len();
    let mut order: Vec<usize> = (0..n).collect();
    order.extend((1..n - 1).rev());
    let mut out = Vec::new();
    for (i, &k) in order.iter().enumerate() {
        let prev = order[(i + order.len() - 1) % order.len()];
        out.push((k, prior(&seq.poses[prev], &seq.poses[k])));
    }
    out
}

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
        let mut stages: Vec<[u64; 3]> = Vec::new();
        let mut ok = 0usize;
        c.bench_function(&format!("frame_640x480_jpeg_{label}"), |b| {
            b.iter(|| {
                let (k, p) = &sched[i % sched.len()];
                let r = fe.process(i as i64, ImageFormat::Jpeg, &seq.jpegs[*k], p);
                i += 1;
                stages.push([r.timings.decode_us, r.timings.track_us, r.timings.solve_us]);
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
            "{label}: {} frames, {ok} measurements; stage medians: decode {} µs, track {} µs, solve {} µs",
            stages.len(),
            med(0),
            med(1),
            med(2)
        );
    }
    let mut dec = uavnav_vision::decode::LumaDecoder::new(640, 480);
    c.bench_function("decode_640x480_jpeg_luma", |b| {
        b.iter(|| dec.decode(ImageFormat::Jpeg, &seq.jpegs[3]).map(|y| y[0]))
    });
}

criterion_group!(benches, bench_frame);
criterion_main!(benches);
