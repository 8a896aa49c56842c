//! Conversions wire ↔ core: round trips (proptest) and one test per kind of bad input.

#![allow(clippy::unwrap_used)] // tests may unwrap

use std::sync::Arc;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use proptest::prelude::*;
use uavnav_core::{
    CameraConfig, CameraFrame, CameraModel, Distortion, FilterProfile, FixType, GnssConfig,
    GnssFix, ImageFormat, ImuConfig, ImuSample, Lla, TruthSample, VehicleConfig,
};
use uavnav_proto::{ConvertError, convert::sensors::imu_batch, v1};

const JPEG: &[u8] = &[0xFF, 0xD8, 0xFF, 0xE0, 0, 0x10];
const PNG: &[u8] = &[0x89, b'P', b'N', b'G', 0x0D, 0x0A];

fn fix(lat: f64, lon: f64, alt: f64, v: [f64; 3], s: [f64; 3], t_ns: i64, ft: FixType) -> GnssFix {
    GnssFix {
        t_ns,
        lat_deg: lat,
        lon_deg: lon,
        alt_m: alt,
        velocity: Some(uavnav_core::GnssVelocity::ned(Vector3::from(v), s[2])),
        sigma_h_m: s[0],
        sigma_v_m: s[1],
        fix_type: ft,
        num_sats: 9,
    }
}

fn camera_config(k: [f64; 4], rpy: [f64; 3], t: [f64; 3]) -> CameraConfig {
    CameraConfig {
        rate_hz: 10.0,
        model: CameraModel {
            width: 640,
            height: 480,
            fx: 500.0,
            fy: 501.0,
            cx: 319.5,
            cy: 239.5,
            distortion: Distortion::RadTan {
                k1: k[0],
                k2: k[1],
                p1: k[2],
                p2: k[3],
            },
        },
        body_from_cam: Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
        ),
    }
}

fn fix_types() -> impl Strategy<Value = FixType> {
    prop_oneof![
        Just(FixType::None),
        Just(FixType::Fix2d),
        Just(FixType::Fix3d),
        Just(FixType::Dgps),
        Just(FixType::RtkFloat),
        Just(FixType::RtkFixed)
    ]
}

proptest! {
    #[test]
    fn imu_round_trip(t in any::<i64>(), g in prop::array::uniform3(-30.0f64..30.0), a in prop::array::uniform3(-150.0f64..150.0)) {
        let s = ImuSample { t_ns: t, gyro_radps: Vector3::from(g), accel_mps2: Vector3::from(a) };
        prop_assert_eq!(ImuSample::try_from(&v1::ImuSample::from(&s)).unwrap(), s);
    }

    #[test]
    fn gnss_round_trip(lat in -90.0f64..=90.0, lon in -180.0f64..=180.0, alt in -500.0f64..20_000.0,
                       v in prop::array::uniform3(-300.0f64..300.0), s in prop::array::uniform3(0.001f64..100.0),
                       t in any::<i64>(), ft in fix_types()) {
        let f = fix(lat, lon, alt, v, s, t, ft);
        prop_assert_eq!(GnssFix::try_from(&v1::GnssFix::from(&f)).unwrap(), f);
    }

    #[test]
    fn vehicle_config_round_trip(k in prop::array::uniform4(-0.5f64..0.5), rpy in prop::array::uniform3(-3.0f64..3.0),
                                 t in prop::array::uniform3(-10.0f64..10.0), lever in prop::array::uniform3(-10.0f64..10.0),
                                 terrain in -400.0f64..5000.0, paper in any::<bool>(),
                                 gyro_bias in 0.0f64..0.1, accel_bias in 0.0f64..1.0) {
        let c = VehicleConfig {
            imu: ImuConfig { gyro_bias_sigma_radps: gyro_bias, accel_bias_sigma_mps2: accel_bias, ..ImuConfig::TACTICAL_MEMS },
            gnss: Some(GnssConfig { rate_hz: 5.0, lever_arm_body_m: Vector3::from(lever), delay_ns: 0, altitude_reference: if paper { uavnav_core::AltitudeReference::Msl } else { uavnav_core::AltitudeReference::Ellipsoid } }),
            mag: None,
            baro: None,
            camera: Some(camera_config(k, rpy, t)),
            terrain_elevation_m: terrain,
            profile: if paper { FilterProfile::Paper } else { FilterProfile::Eskf },
            airframe: if paper { uavnav_core::Airframe::FixedWing } else { uavnav_core::Airframe::Multirotor },
        };
        prop_assert_eq!(VehicleConfig::try_from(&v1::VehicleConfig::from(&c)).unwrap(), c);
    }

    #[test]
    fn truth_round_trip(p in prop::array::uniform3(-1e4f64..1e4), rpy in prop::array::uniform3(-3.0f64..3.0), t in any::<i64>()) {
        let s = TruthSample {
            t_ns: t,
            pos_ned_m: Vector3::from(p),
            nav_from_body: UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
            vel_ned_mps: Vector3::new(1.0, 2.0, 3.0),
            gyro_bias_radps: Vector3::new(1e-3, 0.0, -1e-3),
            accel_bias_mps2: Vector3::new(0.01, 0.02, 0.03),
        };
        // Bit-exact: recordings must not perturb quaternions by renormalising.
        prop_assert_eq!(TruthSample::try_from(&v1::TruthSample::from(&s)).unwrap(), s);
    }
}

#[test]
fn camera_frame_round_trip_and_foxglove_fields() {
    for (bytes, format) in [(JPEG, ImageFormat::Jpeg), (PNG, ImageFormat::Png)] {
        let f = CameraFrame {
            t_ns: 1_500_000_000,
            camera_id: 0,
            format,
            data: Arc::from(bytes),
        };
        let wire = v1::CameraFrame::from(&f);
        let image = wire.image.as_ref().unwrap();
        assert_eq!(image.format, format.as_str());
        assert_eq!(image.frame_id, "cam0");
        assert_eq!(image.timestamp.unwrap().sec(), 1);
        assert_eq!(CameraFrame::try_from(&wire).unwrap(), f);
    }
}

#[test]
fn minimal_config_defaults() {
    let wire = v1::VehicleConfig {
        imu: Some((&ImuConfig::default()).into()),
        ..Default::default()
    };
    let c = VehicleConfig::try_from(&wire).unwrap();
    assert_eq!(c, VehicleConfig::default());
}

#[test]
fn lla_round_trip() {
    let p = Lla::from_deg(47.1, 8.5, 500.0);
    let back = Lla::try_from(&v1::GeodeticPosition::from(&p)).unwrap();
    assert!((back.lat_rad - p.lat_rad).abs() < 1e-15 && back.alt_m == p.alt_m);
}

fn good_fix() -> v1::GnssFix {
    v1::GnssFix::from(&fix(
        45.0,
        7.0,
        300.0,
        [1.0, 2.0, 0.0],
        [1.5, 3.0, 0.1],
        0,
        FixType::Fix3d,
    ))
}

fn field_of<T: std::fmt::Debug>(r: Result<T, ConvertError>) -> (String, ConvertError) {
    let e = r.unwrap_err();
    (e.field().to_owned(), e)
}

#[test]
fn nan_and_inf_are_named() {
    let mut w = v1::ImuSample {
        t_ns: 1,
        ..Default::default()
    };
    w.gyro_y_radps = f64::NAN;
    let (field, e) = field_of(ImuSample::try_from(&w));
    assert_eq!(field, "gyro_y_radps");
    assert!(matches!(e, ConvertError::NotFinite { .. }), "{e}");

    let mut g = good_fix();
    g.vel_down_mps = Some(f64::INFINITY);
    assert_eq!(field_of(GnssFix::try_from(&g)).0, "vel_down_mps");
}

#[test]
fn out_of_range_lat_lon() {
    let mut g = good_fix();
    g.latitude_deg = 91.0;
    let (field, e) = field_of(GnssFix::try_from(&g));
    assert_eq!(field, "latitude_deg");
    assert!(e.to_string().contains("out of range"), "{e}");
    let mut g = good_fix();
    g.longitude_deg = -180.5;
    assert_eq!(field_of(GnssFix::try_from(&g)).0, "longitude_deg");
}

#[test]
fn negative_or_zero_sigma() {
    for s in [-1.0, 0.0] {
        let mut g = good_fix();
        g.sigma_vertical_m = s;
        assert_eq!(field_of(GnssFix::try_from(&g)).0, "sigma_vertical_m");
    }
}

#[test]
fn unknown_and_unspecified_enums() {
    let mut g = good_fix();
    g.fix_type = 0;
    assert!(matches!(
        GnssFix::try_from(&g),
        Err(ConvertError::UnknownEnum { value: 0, .. })
    ));
    g.fix_type = 99;
    assert!(matches!(
        GnssFix::try_from(&g),
        Err(ConvertError::UnknownEnum { value: 99, .. })
    ));
    let mut c = v1::VehicleConfig {
        imu: Some((&ImuConfig::default()).into()),
        ..Default::default()
    };
    c.profile = 7;
    assert_eq!(field_of(VehicleConfig::try_from(&c)).0, "profile");
    c.profile = 0;
    c.airframe = 9;
    assert_eq!(field_of(VehicleConfig::try_from(&c)).0, "airframe");
}

#[test]
fn empty_or_mislabelled_image() {
    let mut w = v1::CameraFrame::from(&CameraFrame {
        t_ns: 0,
        camera_id: 0,
        format: ImageFormat::Jpeg,
        data: Arc::from(JPEG),
    });
    w.image.as_mut().unwrap().data = Default::default();
    let (field, e) = field_of(CameraFrame::try_from(&w));
    assert_eq!(field, "image.data");
    assert!(e.to_string().contains("empty"), "{e}");
    w.image.as_mut().unwrap().data = foxglove::bytes::Bytes::from_static(PNG);
    assert!(
        field_of(CameraFrame::try_from(&w))
            .1
            .to_string()
            .contains("not a jpeg")
    );
    w.image.as_mut().unwrap().format = "webp".into();
    assert_eq!(field_of(CameraFrame::try_from(&w)).0, "image.format");
    w.image = None;
    assert!(matches!(
        CameraFrame::try_from(&w),
        Err(ConvertError::Missing { .. })
    ));
}

#[test]
fn missing_nested_fields_have_paths() {
    let mut c = v1::VehicleConfig::from(&VehicleConfig {
        camera: Some(camera_config([0.0; 4], [0.0; 3], [0.0; 3])),
        ..Default::default()
    });
    c.camera
        .as_mut()
        .unwrap()
        .body_from_cam
        .as_mut()
        .unwrap()
        .rotation = None;
    let (field, e) = field_of(VehicleConfig::try_from(&c));
    assert_eq!(field, "camera.body_from_cam.rotation", "{e}");
    assert_eq!(e.to_string(), "camera.body_from_cam.rotation: missing");
    let c = v1::VehicleConfig::default();
    assert_eq!(field_of(VehicleConfig::try_from(&c)).0, "imu");
}

#[test]
fn batch_must_increase() {
    let s = |t| v1::ImuSample {
        t_ns: t,
        ..Default::default()
    };
    let b = v1::ImuBatch {
        samples: vec![s(1), s(2), s(2)],
    };
    let (field, _) = field_of(imu_batch(&b));
    assert_eq!(field, "samples[2].t_ns");
    let mut b = v1::ImuBatch {
        samples: vec![s(1), s(2)],
    };
    b.samples[1].accel_x_mps2 = 1e9;
    assert_eq!(field_of(imu_batch(&b)).0, "samples[1].accel_x_mps2");
}

#[test]
fn quaternion_norm_checked() {
    let mut t = v1::TruthSample::from(&TruthSample {
        t_ns: 0,
        pos_ned_m: Vector3::zeros(),
        nav_from_body: UnitQuaternion::identity(),
        vel_ned_mps: Vector3::zeros(),
        gyro_bias_radps: Vector3::zeros(),
        accel_bias_mps2: Vector3::zeros(),
    });
    t.nav_from_body = Some(v1::Quaternion {
        w: 2.0,
        x: 0.0,
        y: 0.0,
        z: 0.0,
    });
    assert_eq!(field_of(TruthSample::try_from(&t)).0, "nav_from_body");
}
