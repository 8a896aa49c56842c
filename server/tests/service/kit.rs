//! The test kit's own promises (`uavnav-tests`), checked here rather than by a test build of the
//! kit's library, which linked the whole service once more for this one test.

use uavnav_core::CameraConfig;
use uavnav_tests::pb;
use uavnav_tests::wire::{camera_config, vehicle_config};

/// The wire camera is the literal the service tests were written against (a change here
/// changes what every camera test configures).
#[test]
fn the_wire_camera_is_640x480_at_500_px() {
    let c = vehicle_config(true).camera.unwrap();
    assert_eq!((c.camera_id, c.width_px, c.height_px), (0, 640, 480));
    assert_eq!(
        (c.fx_px, c.fy_px, c.cx_px, c.cy_px),
        (500.0, 500.0, 320.0, 240.0)
    );
    assert_eq!(c.distortion_model, pb::DistortionModel::None as i32);
    assert_eq!(c.rate_hz, 10.0);
    let mount = c.body_from_cam.as_ref().unwrap();
    assert_eq!(mount.rotation.as_ref().unwrap().w, 1.0);
    assert_eq!(mount.translation_m.as_ref(), Some(&pb::Vector3::default()));
    let back = CameraConfig::try_from(&c).unwrap();
    assert_eq!(back, camera_config());
    assert!(vehicle_config(false).camera.is_none());
}
