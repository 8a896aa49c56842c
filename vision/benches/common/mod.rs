//! The benchmark's frame sequence, shared by `benches/frame.rs` and `examples/stage_profile.rs`:
//! a synthetic ground texture seen from 150 m by a downward camera moving ~3 m per frame,
//! encoded as JPEG (quality 90), run back and forth with the IMU/terrain prior of each pair.

#![allow(dead_code)] // each user takes what it needs

use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};
use uavnav_core::{CameraModel, Distortion, MotionPrior};
use uavnav_vision::synthetic::{Texture, render_ground};

pub fn camera() -> CameraModel {
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

pub fn pose(k: f64) -> Isometry3<f64> {
    let base = UnitQuaternion::from_basis_unchecked(&[Vector3::y(), -Vector3::x(), Vector3::z()]);
    let q =
        UnitQuaternion::from_euler_angles(0.02 * (0.5 * k).sin(), 0.01 * k.cos(), 0.2 + 0.004 * k)
            * base;
    Isometry3::from_parts(Translation3::new(3.0 * k, 0.5 * k, -150.0), q)
}

pub struct Sequence {
    pub jpegs: Vec<Vec<u8>>,
    pub poses: Vec<Isometry3<f64>>,
}

pub fn sequence(n: usize) -> Sequence {
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

pub fn prior(a: &Isometry3<f64>, b: &Isometry3<f64>) -> MotionPrior {
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
pub fn schedule(seq: &Sequence) -> Vec<(usize, MotionPrior)> {
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
