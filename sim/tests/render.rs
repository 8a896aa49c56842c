//! The renderer: texture at low and high altitude, sky, JPEG round trip.
#![allow(clippy::unwrap_used)]

use nalgebra::{UnitQuaternion, Vector3};
use uavnav_core::{CameraModel, Distortion, ImageFormat, Lla, LocalFrame};
use uavnav_sim::render::SKY_GRAY;
use uavnav_sim::{Flight, RayTable, Scenario, Terrain, render_gray};

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
            p1: 0.0,
            p2: 0.0,
        },
    }
}

/// Std dev and mean absolute horizontal gradient of an image, gray levels.
fn texture_stats(img: &image::GrayImage) -> (f64, f64) {
    let px: Vec<f64> = img.pixels().map(|p| f64::from(p.0[0])).collect();
    let mean = px.iter().sum::<f64>() / px.len() as f64;
    let sd = (px.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / px.len() as f64).sqrt();
    let w = img.width() as usize;
    let grads: Vec<f64> = px
        .chunks(w)
        .flat_map(|r| r.windows(2).map(|p| (p[1] - p[0]).abs()))
        .collect();
    (sd, grads.iter().sum::<f64>() / grads.len() as f64)
}

fn nadir() -> UnitQuaternion<f64> {
    // Level body heading north; camera z = down, x = east.
    UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2)
}

#[test]
fn ground_has_texture_at_50_and_500_m() {
    let origin = Lla::from_deg(41.1, 14.2, 100.0);
    let frame = LocalFrame::new(origin);
    let terrain = Terrain::new(origin, 100.0, 5);
    let rays = RayTable::new(&camera());
    for (h, east) in [(50.0, 0.0), (500.0, 1234.0)] {
        let img = render_gray(
            &terrain,
            &rays,
            &frame,
            &Vector3::new(300.0, east, -h),
            &nadir(),
            None,
        );
        let (sd, grad) = texture_stats(&img);
        eprintln!("{h} m: sd {sd:.1}, mean |grad| {grad:.2}");
        assert!(sd > 8.0, "{h} m: std dev {sd}");
        assert!(grad > 1.0, "{h} m: gradient {grad}");
        assert!(
            img.pixels().all(|p| f32::from(p.0[0]) != SKY_GRAY.round()),
            "{h} m: sky below"
        );
    }
}

#[test]
fn sky_and_underground_give_the_sky_value() {
    let origin = Lla::from_deg(41.1, 14.2, 100.0);
    let frame = LocalFrame::new(origin);
    let terrain = Terrain::new(origin, 100.0, 5);
    let rays = RayTable::new(&camera());
    let up = UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0) * nadir();
    let sky = SKY_GRAY.round() as u8;
    let img = render_gray(
        &terrain,
        &rays,
        &frame,
        &Vector3::new(0.0, 0.0, -200.0),
        &up,
        None,
    );
    assert!(img.pixels().all(|p| p.0[0] == sky));
    let img = render_gray(
        &terrain,
        &rays,
        &frame,
        &Vector3::new(0.0, 0.0, 20.0),
        &nadir(),
        None,
    );
    assert!(img.pixels().all(|p| p.0[0] == sky));
    // Looking at the horizon: top half sky, bottom half ground, no panic.
    // Camera looking north: z = north, x = east, y = down.
    let m = nalgebra::Matrix3::new(0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    let horizon =
        UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(m));
    let img = render_gray(
        &terrain,
        &rays,
        &frame,
        &Vector3::new(0.0, 0.0, -200.0),
        &horizon,
        None,
    );
    let (top, bottom) = (img.get_pixel(160, 5).0[0], img.get_pixel(160, 235).0[0]);
    assert!(top == sky && bottom != sky, "top {top} bottom {bottom}");
}

#[test]
fn flight_frames_are_jpeg_with_texture() {
    let mut sc = Scenario::from_toml_str(include_str!("../../scenarios/smoke.toml")).unwrap();
    sc.duration_s = 2.0;
    let flight = Flight::new(&sc).unwrap();
    let frame = flight.render_frame(3).unwrap();
    assert_eq!(frame.format, ImageFormat::Jpeg);
    assert_eq!(ImageFormat::sniff(&frame.data), Some(ImageFormat::Jpeg));
    assert_eq!(frame.t_ns, flight.camera_times_ns()[3]);
    let img = image::load_from_memory(&frame.data).unwrap().to_luma8();
    assert_eq!((img.width(), img.height()), (640, 480));
    let (sd, grad) = texture_stats(&img);
    assert!(sd > 8.0 && grad > 1.0, "sd {sd} grad {grad}");
    assert!(flight.render_frame(10_000).is_err());
}

#[test]
fn terrain_is_fixed_to_the_ground() {
    // The same ground point seen from two positions has the same texture coordinates.
    let origin = Lla::from_deg(41.1, 14.2, 100.0);
    let frame = LocalFrame::new(origin);
    let terrain = Terrain::new(origin, 100.0, 5);
    let other = LocalFrame::new(Lla::from_deg(41.11, 14.21, 300.0));
    let p = Vector3::new(500.0, -300.0, 0.0);
    let lla = frame.ned_to_lla(&p);
    let q = other.lla_to_ned(&lla);
    let (a, b) = (
        terrain.texture_coords(&frame, &p),
        terrain.texture_coords(&other, &q),
    );
    assert!((a.0 - b.0).abs() < 1e-6 && (a.1 - b.1).abs() < 1e-6);
}
