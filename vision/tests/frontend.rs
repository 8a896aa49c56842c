//! Front-end scenarios on synthetic ground views: accuracy with and without the IMU/terrain
//! prior, and "no measurement" with a reason for unusable frames.

#![allow(clippy::unwrap_used)]

use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};
use uavnav_core::{CameraModel, Distortion, EgomotionSolver, ImageFormat, MotionPrior};
use uavnav_vision::synthetic::{Texture, render_ground};
use uavnav_vision::{FrontEnd, NoMeasurement, VisionParams, pair_error};

fn camera() -> CameraModel {
    CameraModel {
        width: 320,
        height: 240,
        fx: 250.0,
        fy: 250.0,
        cx: 159.5,
        cy: 119.5,
        distortion: Distortion::RadTan {
            k1: -0.05,
            k2: 0.01,
            p1: 0.0002,
            p2: -0.0001,
        },
    }
}

fn png(w: u32, h: u32, luma: Vec<u8>) -> Vec<u8> {
    let img = image::GrayImage::from_raw(w, h, luma).unwrap();
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .unwrap();
    out
}

fn jpeg(w: u32, h: u32, luma: Vec<u8>) -> Vec<u8> {
    let img = image::GrayImage::from_raw(w, h, luma).unwrap();
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 95)
        .encode_image(&img)
        .unwrap();
    out
}

/// Camera looking down (optical axis = world +z "down"), x right = east, at `alt` m.
fn pose(north: f64, east: f64, alt: f64, yaw: f64, tilt: f64) -> Isometry3<f64> {
    // cam axes in NED: x = east, y = south... use a rotation: z_cam → down, x_cam → east
    let base = UnitQuaternion::from_basis_unchecked(&[Vector3::y(), -Vector3::x(), Vector3::z()]);
    let q = UnitQuaternion::from_euler_angles(tilt, 0.5 * tilt, yaw) * base;
    Isometry3::from_parts(Translation3::new(north, east, -alt), q)
}

fn prior_for(a: &Isometry3<f64>, b: &Isometry3<f64>, alt: f64) -> MotionPrior {
    let rel = b.inverse() * a; // cam1_from_cam0
    let n_cam0 = a.rotation.inverse() * Vector3::z();
    let d = alt; // plane z = 0, camera at z = −alt
    MotionPrior {
        cam1_from_cam0: Some(rel.rotation),
        rot_sigma_rad: 1e-3,
        ground_normal_cam0: Some(Unit::new_normalize(n_cam0)),
        ground_distance_m: Some(d),
        t_cam1_m: Some(rel.translation.vector),
    }
}

#[test]
fn synthetic_flight_plane_and_essential() {
    let cam = camera();
    let tex = Texture::new(3);
    let alt = 150.0;
    let poses: Vec<Isometry3<f64>> = (0..6)
        .map(|k| {
            let k = f64::from(k);
            pose(
                4.0 * k,
                0.6 * k,
                alt + 0.2 * k,
                0.3 + 0.01 * k,
                0.02 * (k * 0.7).sin(),
            )
        })
        .collect();
    let frames: Vec<Vec<u8>> = poses
        .iter()
        .map(|p| jpeg(320, 240, render_ground(&tex, &cam, p, 2.0)))
        .collect();
    for (aid, label) in [(true, "aided"), (false, "unaided")] {
        let params = VisionParams {
            imu_aid: aid,
            ..VisionParams::default()
        };
        let mut fe = FrontEnd::new(&cam, Isometry3::identity(), params);
        let _ = fe.process(0, ImageFormat::Jpeg, &frames[0], &MotionPrior::default());
        for k in 1..frames.len() {
            let prior = prior_for(&poses[k - 1], &poses[k], alt + 0.2 * (k - 1) as f64);
            let res = fe.process(k as i64, ImageFormat::Jpeg, &frames[k], &prior);
            let ego = res
                .outcome
                .unwrap_or_else(|e| panic!("{label} pair {k}: {e}"));
            let rel = poses[k].inverse() * poses[k - 1];
            let err = pair_error(&ego, &rel.rotation, &rel.translation.vector);
            let (r, t) = (
                err.rot_err_rad.to_degrees(),
                err.t_dir_err_rad.unwrap().to_degrees(),
            );
            eprintln!(
                "{label} pair {k}: {:?} tracked {} inliers {} rot {r:.4}° dir {t:.3}°",
                ego.solver, ego.tracked, ego.inliers
            );
            assert_eq!(ego.solver, EgomotionSolver::Plane);
            assert!(r < 0.05, "{label} pair {k}: rotation err {r}°");
            assert!(t < 2.0, "{label} pair {k}: direction err {t}°");
            let tm = ego.t_cam1_m.unwrap();
            assert!((tm - rel.translation.vector).norm() < 0.1 * rel.translation.vector.norm());
        }
    }
}

#[test]
fn unusable_frames_give_a_reason() {
    let cam = camera();
    let tex = Texture::new(4);
    let good = render_ground(&tex, &cam, &pose(0.0, 0.0, 100.0, 0.0, 0.0), 2.0);
    let good2 = render_ground(&tex, &cam, &pose(1.0, 0.0, 100.0, 0.0, 0.0), 2.0);
    let mut blurred = good2.clone();
    for _ in 0..4 {
        box_blur(&mut blurred, 320, 240, 3);
    }
    let flat: Vec<u8> = (0..320 * 240).map(|i| 120 + (i % 3) as u8).collect();
    let good_jpeg = jpeg(320, 240, good2.clone());
    let cases: Vec<(&str, ImageFormat, Vec<u8>)> = vec![
        ("black", ImageFormat::Png, png(320, 240, vec![2; 320 * 240])),
        (
            "saturated",
            ImageFormat::Png,
            png(320, 240, vec![255; 320 * 240]),
        ),
        ("textureless", ImageFormat::Png, png(320, 240, flat)),
        ("blurred", ImageFormat::Png, png(320, 240, blurred)),
        (
            "decode_error",
            ImageFormat::Jpeg,
            good_jpeg[..good_jpeg.len() * 2 / 3].to_vec(),
        ),
        (
            "decode_error",
            ImageFormat::Png,
            vec![0x89, b'P', b'N', b'G', 1, 2, 3],
        ),
        (
            "size_mismatch",
            ImageFormat::Png,
            png(160, 120, vec![100; 160 * 120]),
        ),
    ];
    for (want, fmt, data) in cases {
        let mut fe = FrontEnd::new(&cam, Isometry3::identity(), VisionParams::default());
        let first = fe.process(
            0,
            ImageFormat::Png,
            &png(320, 240, good.clone()),
            &MotionPrior::default(),
        );
        assert_eq!(first.outcome, Err(NoMeasurement::NoReference));
        let res = fe.process(1, fmt, &data, &MotionPrior::default());
        let reason = res
            .outcome
            .as_ref()
            .err()
            .unwrap_or_else(|| panic!("{want}: got a measurement"));
        eprintln!("{want}: {reason}");
        assert_eq!(reason.tag(), want, "{reason}");
        // the reference is dropped: the next good frame starts again
        let next = fe.process(
            2,
            ImageFormat::Png,
            &png(320, 240, good2.clone()),
            &MotionPrior::default(),
        );
        assert_eq!(next.outcome, Err(NoMeasurement::NoReference));
    }
    // and the good pair itself measures
    let mut fe = FrontEnd::new(&cam, Isometry3::identity(), VisionParams::default());
    let _ = fe.process(
        0,
        ImageFormat::Png,
        &png(320, 240, good),
        &MotionPrior::default(),
    );
    assert!(
        fe.process(
            1,
            ImageFormat::Png,
            &png(320, 240, good2),
            &MotionPrior::default()
        )
        .outcome
        .is_ok()
    );
}

fn box_blur(img: &mut [u8], w: usize, h: usize, r: usize) {
    let src = img.to_vec();
    for y in 0..h {
        for x in 0..w {
            let (mut s, mut n) = (0u32, 0u32);
            for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                    s += u32::from(src[yy * w + xx]);
                    n += 1;
                }
            }
            img[y * w + x] = (s / n) as u8;
        }
    }
}
