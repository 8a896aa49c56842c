//! The output vocabulary ↔ wire: a property round trip over every field of `PoseOutput`, the
//! service's compact pose, and refusals that name the field.

#![allow(clippy::unwrap_used)] // tests may unwrap

use nalgebra::{UnitQuaternion, Vector3};
use proptest::prelude::*;
use uavnav_core::{AidingFlags, Lla, Mode, PoseHealth, PoseOutput, SourceSummary};
use uavnav_proto::convert::output::{aiding_from_wire, mode_from_wire, mode_to_wire, pose_to_wire};
use uavnav_proto::{ConvertError, v1};

fn v3() -> impl Strategy<Value = Vector3<f64>> {
    prop::array::uniform3(-1.0e3f64..1.0e3).prop_map(Vector3::from)
}

fn sigma() -> impl Strategy<Value = Vector3<f64>> {
    prop::array::uniform3(0.0f64..1.0e3).prop_map(Vector3::from)
}

fn summary() -> impl Strategy<Value = SourceSummary> {
    (0.0f64..1.0e6, any::<u64>(), any::<u64>()).prop_map(|(test_ratio, fused, rejected)| {
        SourceSummary {
            test_ratio,
            fused,
            rejected,
        }
    })
}

fn health() -> impl Strategy<Value = PoseHealth> {
    (
        prop::sample::select(Mode::ALL.to_vec()),
        prop::array::uniform8(summary()),
        any::<[u64; 3]>(),
        any::<u32>(),
    )
        .prop_map(|(mode, s, c, gnss_resets)| PoseHealth {
            mode,
            gnss_pos: s[0],
            gnss_vel: s[1],
            vision_rot: s[2],
            vision_trans: s[3],
            mag: s[4],
            baro: s[5],
            gnss_tilt: s[6],
            position_hold: s[7],
            inputs_rejected: c[0],
            late_dropped: c[1],
            vision_no_clone: c[2],
            gnss_resets,
        })
}

fn aiding() -> impl Strategy<Value = AidingFlags> {
    any::<[bool; 4]>().prop_map(|b| AidingFlags {
        gnss_pos: b[0],
        gnss_vel: b[1],
        vision_rot: b[2],
        vision_trans: b[3],
    })
}

prop_compose! {
    fn pose()(
        t_ns in any::<i64>(),
        lat in -90.0f64..90.0, lon in -180.0f64..180.0, alt in -500.0f64..20_000.0,
        pos in v3(), vel in v3(),
        rpy in prop::array::uniform3(-3.0f64..3.0),
        euler in v3(),
        s_pos in sigma(), s_vel in sigma(), s_att in sigma(),
        bg in v3(), ba in v3(),
        health in health(), aiding in aiding(),
    ) -> PoseOutput {
        PoseOutput {
            t_ns,
            lla: Lla::from_deg(lat, lon, alt),
            pos_ned_m: pos,
            vel_ned_mps: vel,
            nav_from_body: UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
            euler_rad: euler,
            sigma_pos_ned_m: s_pos,
            sigma_vel_mps: s_vel,
            sigma_att_rad: s_att,
            gyro_bias_radps: bg,
            accel_bias_mps2: ba,
            health,
            aiding,
        }
    }
}

/// Equal to the last bits of the radian ↔ degree conversion of latitude and longitude.
fn close_lla(a: &Lla, b: &Lla) -> bool {
    (a.lat_rad - b.lat_rad).abs() <= 4.0 * f64::EPSILON
        && (a.lon_rad - b.lon_rad).abs() <= 8.0 * f64::EPSILON
        && a.alt_m == b.alt_m
}

proptest! {
    #[test]
    fn pose_round_trip_keeps_every_field(p in pose()) {
        let w = pose_to_wire("veh/1", &p, 42);
        prop_assert_eq!(&w.vehicle_id, "veh/1");
        prop_assert_eq!(w.ingest_wall_ns, 42);
        let back = PoseOutput::try_from(&w).unwrap();
        // Attitude only: position, velocity and their σ are not sent and read back as zero.
        let p = if p.health.mode.has_position() {
            p
        } else {
            prop_assert!(w.position.is_none() && w.vel_ned_mps.is_none() && w.pos_ned_m.is_none());
            prop_assert!(w.sigma_pos_ned_m.is_none() && w.sigma_vel_ned_mps.is_none());
            PoseOutput {
                lla: Lla::from_deg(0.0, 0.0, 0.0),
                pos_ned_m: Vector3::zeros(),
                vel_ned_mps: Vector3::zeros(),
                sigma_pos_ned_m: Vector3::zeros(),
                sigma_vel_mps: Vector3::zeros(),
                ..p
            }
        };
        prop_assert!(close_lla(&back.lla, &p.lla), "{:?} vs {:?}", back.lla, p.lla);
        // Everything else bit for bit.
        let same_lla = PoseOutput { lla: p.lla, ..back };
        prop_assert_eq!(same_lla, p);
        // And wire → core → wire gives the same message again.
        let again = pose_to_wire("veh/1", &back, 42);
        prop_assert_eq!(PoseOutput::try_from(&again).unwrap(), back);
    }

    #[test]
    fn aiding_round_trip(a in aiding()) {
        let wire: Vec<i32> = uavnav_proto::convert::output::aiding_to_wire(&a).map(|s| s as i32).collect();
        prop_assert_eq!(aiding_from_wire("aiding_sources", &wire).unwrap(), a);
        // The summary VISION bit is set exactly when a vision part is.
        prop_assert_eq!(wire.contains(&(v1::AidingSource::Vision as i32)), a.vision_rot || a.vision_trans);
    }
}

#[test]
fn every_mode_maps_both_ways_and_unspecified_is_refused() {
    for m in Mode::ALL {
        assert_eq!(mode_from_wire("mode", mode_to_wire(m) as i32).unwrap(), m);
    }
    let e = mode_from_wire("mode", v1::EstimatorMode::Unspecified as i32).unwrap_err();
    assert!(matches!(e, ConvertError::UnknownEnum { ref field, .. } if field == "mode"));
    assert!(mode_from_wire("mode", 99).is_err());
}

#[test]
fn a_sender_that_only_says_vision_reads_as_both_parts() {
    let a = aiding_from_wire("aiding_sources", &[v1::AidingSource::Vision as i32]).unwrap();
    assert!(a.vision_rot && a.vision_trans && !a.gnss_pos);
    let e = aiding_from_wire("aiding_sources", &[1, 77]).unwrap_err();
    assert_eq!(e.field(), "aiding_sources[1]");
}

#[test]
fn the_services_compact_pose_converts_with_defaults() {
    let p = PoseOutput {
        t_ns: 5,
        lla: Lla::from_deg(41.0, 14.0, 100.0),
        pos_ned_m: Vector3::new(1.0, 2.0, 3.0),
        vel_ned_mps: Vector3::new(4.0, 5.0, 6.0),
        nav_from_body: UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3),
        euler_rad: Vector3::new(0.1, 0.2, 0.3),
        sigma_pos_ned_m: Vector3::repeat(1.0),
        sigma_vel_mps: Vector3::repeat(0.1),
        sigma_att_rad: Vector3::repeat(0.01),
        gyro_bias_radps: Vector3::repeat(1e-3),
        accel_bias_mps2: Vector3::repeat(1e-2),
        health: PoseHealth {
            mode: Mode::Nominal,
            ..PoseHealth::default()
        },
        aiding: AidingFlags {
            gnss_pos: true,
            ..AidingFlags::default()
        },
    };
    let mut w = pose_to_wire("a", &p, 0);
    w.pos_ned_m = None;
    w.gyro_bias_radps = None;
    w.accel_bias_mps2 = None;
    w.health = None;
    let back = PoseOutput::try_from(&w).unwrap();
    assert_eq!(back.pos_ned_m, Vector3::zeros());
    assert_eq!(back.gyro_bias_radps, Vector3::zeros());
    assert_eq!(back.health.mode, Mode::Nominal);
    assert_eq!(back.aiding, p.aiding);
    assert_eq!(back.vel_ned_mps, p.vel_ned_mps);
}

#[test]
fn bad_poses_name_the_field() {
    let p = PoseOutput {
        t_ns: 5,
        lla: Lla::from_deg(41.0, 14.0, 100.0),
        pos_ned_m: Vector3::zeros(),
        vel_ned_mps: Vector3::zeros(),
        nav_from_body: UnitQuaternion::identity(),
        euler_rad: Vector3::zeros(),
        sigma_pos_ned_m: Vector3::repeat(1.0),
        sigma_vel_mps: Vector3::repeat(0.1),
        sigma_att_rad: Vector3::repeat(0.01),
        gyro_bias_radps: Vector3::zeros(),
        accel_bias_mps2: Vector3::zeros(),
        health: PoseHealth::default(),
        aiding: AidingFlags::default(),
    };
    let good = pose_to_wire("a", &p, 0);
    let mut w = good.clone();
    w.position = None;
    assert_eq!(PoseOutput::try_from(&w).unwrap_err().field(), "position");
    // Attitude only: position, velocity and their σ may be absent (they read as zero).
    let mut w = good.clone();
    w.mode = v1::EstimatorMode::AttitudeOnly as i32;
    w.position = None;
    w.vel_ned_mps = None;
    w.sigma_pos_ned_m = None;
    let back = PoseOutput::try_from(&w).unwrap();
    assert_eq!(back.health.mode, Mode::AttitudeOnly);
    assert_eq!(back.sigma_pos_ned_m, Vector3::zeros());
    assert_eq!(back.sigma_vel_mps, Vector3::repeat(0.1));
    let mut w = good.clone();
    w.sigma_att_rad.as_mut().unwrap().y = -1.0;
    assert_eq!(
        PoseOutput::try_from(&w).unwrap_err().field(),
        "sigma_att_rad.y"
    );
    let mut w = good.clone();
    w.health.as_mut().unwrap().magnetometer = Some(v1::SourceSummary {
        test_ratio: f64::NAN,
        fused: 0,
        rejected: 0,
    });
    assert_eq!(
        PoseOutput::try_from(&w).unwrap_err().field(),
        "health.magnetometer.test_ratio"
    );
}
