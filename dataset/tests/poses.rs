//! The pose output files: `poses.csv` rows and TUM lines.

#![allow(clippy::unwrap_used)]

use nalgebra::{UnitQuaternion, Vector3};
use uavnav_dataset::poses::{CSV_LEADING_COLUMNS, csv_header, csv_row, tum_line};

#[test]
fn csv_and_tum_lines() {
    let header = csv_header();
    assert!(header.starts_with(CSV_LEADING_COLUMNS));
    assert!(
        CSV_LEADING_COLUMNS
            .starts_with("timestamp_ns,latitude_deg,longitude_deg,altitude_m,v_north_mps")
    );
    let o = uavnav_core::PoseOutput {
        t_ns: 1_500_000_000,
        lla: uavnav_core::Lla::from_deg(41.0, 14.0, 250.0),
        pos_ned_m: Vector3::new(1.0, 2.0, -3.0),
        vel_ned_mps: Vector3::new(30.0, 0.5, -0.1),
        nav_from_body: UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3),
        euler_rad: Vector3::new(0.1, 0.2, 0.3),
        sigma_pos_ned_m: Vector3::repeat(1.0),
        sigma_vel_mps: Vector3::repeat(0.1),
        sigma_att_rad: Vector3::repeat(0.001),
        gyro_bias_radps: Vector3::zeros(),
        accel_bias_mps2: Vector3::zeros(),
        health: Default::default(),
        aiding: Default::default(),
    };
    let row = csv_row(&o);
    assert_eq!(row.split(',').count(), header.split(',').count());
    let f: Vec<&str> = row.split(',').collect();
    assert_eq!(f[0], "1500000000");
    assert!((f[11].parse::<f64>().unwrap() - 0.1f64.to_degrees()).abs() < 1e-4);
    let tum: Vec<f64> = tum_line(&o)
        .expect("a pose with position")
        .split(' ')
        .map(|x| x.parse().unwrap())
        .collect();
    assert_eq!(tum.len(), 8);
    assert!((tum[0] - 1.5).abs() < 1e-12 && (tum[3] + 3.0).abs() < 1e-12);
    let q = o.nav_from_body.quaternion();
    assert!((tum[7] - q.w).abs() < 1e-9 && (tum[4] - q.i).abs() < 1e-9);

    // Attitude only: the position, velocity and position-σ cells are empty, the rest is there,
    // and there is no trajectory line.
    let mut a = o;
    a.health.mode = uavnav_core::Mode::AttitudeOnly;
    let row = csv_row(&a);
    let f: Vec<&str> = row.split(',').collect();
    assert_eq!(f.len(), header.split(',').count());
    assert!(f[1..7].iter().all(|c| c.is_empty()), "{row}");
    assert!(f[14..17].iter().all(|c| c.is_empty()), "{row}");
    assert!((f[11].parse::<f64>().unwrap() - 0.1f64.to_degrees()).abs() < 1e-4);
    assert!(!f[17].is_empty() && f[20] == "attitude_only", "{row}");
    assert!(tum_line(&a).is_none());
}
