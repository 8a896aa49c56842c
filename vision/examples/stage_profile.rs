//! Rough timing of the tracking sub-stages on synthetic 640×480 frames (developer aid).

use std::time::Instant;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use uavnav_core::{CameraModel, Distortion};
use uavnav_vision::klt::{KltParams, KltScratch, best_corner_in, track_point};
use uavnav_vision::pyramid::{Pyramid, frame_stats};
use uavnav_vision::synthetic::{Texture, render_ground};

fn main() {
    let cam = CameraModel {
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
    };
    let base = UnitQuaternion::from_basis_unchecked(&[Vector3::y(), -Vector3::x(), Vector3::z()]);
    let pose = |k: f64| {
        Isometry3::from_parts(
            Translation3::new(3.0 * k, 0.5 * k, -150.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.2) * base,
        )
    };
    let tex = Texture::new(21);
    let a = render_ground(&tex, &cam, &pose(0.0), 1.5);
    let b = render_ground(&tex, &cam, &pose(1.0), 1.5);
    let (mut pa, mut pb) = (Pyramid::default(), Pyramid::default());
    let n = 200;
    let t = Instant::now();
    for _ in 0..n {
        pa.build(&a, 640, 480, 3);
    }
    println!(
        "pyramid build: {:.1} µs",
        t.elapsed().as_secs_f64() * 1e6 / n as f64
    );
    pb.build(&b, 640, 480, 3);
    let t = Instant::now();
    for _ in 0..n {
        std::hint::black_box(frame_stats(&pa));
    }
    println!(
        "frame stats: {:.1} µs",
        t.elapsed().as_secs_f64() * 1e6 / n as f64
    );
    let t = Instant::now();
    let mut pts = Vec::new();
    for _ in 0..20 {
        pts.clear();
        for cy in 0..14 {
            for cx in 0..18 {
                let r = (
                    (cx * 35) >> 1,
                    ((cx + 1) * 35) >> 1,
                    (cy * 35) >> 1,
                    ((cy + 1) * 35) >> 1,
                );
                if let Some((p, _)) = best_corner_in(&pa.levels[1], r, 2, 20.0) {
                    pts.push([p[0] * 2.0, p[1] * 2.0]);
                }
            }
        }
    }
    println!(
        "corners (all 252 cells): {:.1} µs, {} found",
        t.elapsed().as_secs_f64() * 1e6 / 20.0,
        pts.len()
    );
    let params = KltParams::default();
    let mut s = KltScratch::default();
    let t = Instant::now();
    let mut ok = 0;
    for _ in 0..20 {
        ok = 0;
        for p in &pts {
            let g = [p[0] - 10.0, p[1] + 3.0];
            if let Some(q) = track_point(&pa, &pb, *p, g, None, 1, &params, &mut s)
                && track_point(&pb, &pa, q, *p, None, 1, &params, &mut s).is_some()
            {
                ok += 1;
            }
        }
    }
    println!(
        "KLT fwd+bwd, 2 levels, {} pts: {:.1} µs ({ok} ok)",
        pts.len(),
        t.elapsed().as_secs_f64() * 1e6 / 20.0
    );
    let t = Instant::now();
    for _ in 0..20 {
        for p in &pts {
            std::hint::black_box(
                cam.pixel_to_normalized(&nalgebra::Point2::new(f64::from(p[0]), f64::from(p[1]))),
            );
        }
    }
    println!(
        "undistort {} pts: {:.1} µs",
        pts.len(),
        t.elapsed().as_secs_f64() * 1e6 / 20.0
    );
}
