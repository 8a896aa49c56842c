//! MAVLink telemetry import of the shared public tlog (ArduPlane VTOL SITL as a ground station
//! recorded it), checked against what pymavlink 2.4.50 reads from the same file: the message
//! counts of system 1 and the first decoded values.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use uavnav_logs::{ImportOptions, LogKind, TimeBase, VehicleKind};

#[test]
fn tlog_counts_and_values_match_pymavlink() {
    let Some(root) = uavnav_testdata::shared_data("public_flight_logs") else {
        return;
    };
    let log = uavnav_logs::open(
        root.join("ardupilot_vtol_sitl.tlog"),
        &ImportOptions::default(),
    )
    .unwrap();
    assert_eq!(log.source, LogKind::Mavlink);
    // HEARTBEAT.type 1 (fixed wing) from ArduPlane.
    assert_eq!(log.vehicle, VehicleKind::Plane);
    assert_eq!(log.time_base, TimeBase::Unix);
    for (name, n) in [
        ("RAW_IMU", 795),
        ("SCALED_IMU2", 796),
        ("GPS_RAW_INT", 799),
        ("SYSTEM_TIME", 811),
        ("ATTITUDE", 888),
        ("GLOBAL_POSITION_INT", 807),
        ("SCALED_PRESSURE", 794),
    ] {
        assert_eq!(log.message_counts.get(name), Some(&n), "{name}");
    }
    // Every RAW_IMU sample kept but the one whose stamp goes back 1 s (the 8th: 611 541 976 µs
    // then 610 541 878 µs, as pymavlink reads it too), with ArduPilot's units.
    assert_eq!(log.imu.len(), 794);
    assert!(log.notes.iter().any(|n| n.contains("RAW_IMU: 1 samples")));
    // First RAW_IMU: time_usec 608 582 234, zacc −999 mG, zgyro −231 mrad/s, zmag −541 mGauss;
    // SYSTEM_TIME pairs boot 608 582 ms with UNIX 1 533 737 145 465 009 µs.
    let s = log.imu[0];
    assert!(
        (s.t_ns - 1_533_737_145_465_243_000).abs() < 2_000_000,
        "{}",
        s.t_ns
    );
    assert!((s.accel_mps2.z + 0.999 * 9.806_65).abs() < 1e-9);
    assert!((s.gyro_radps.z + 0.231).abs() < 1e-12);
    assert!((log.mag[0].field_t.z + 541e-7).abs() < 1e-15);
    // PARAM_VALUE: 1,147 messages, 1,053 parameters (the ground station read some twice); SITL's
    // AHRS_EKF_TYPE 10 and no trim, so the IMU stays as sent (checked above).
    assert_eq!(log.message_counts.get("PARAM_VALUE"), Some(&1147));
    assert_eq!(log.params.len(), 1053);
    assert_eq!(log.params.get("SYSID_THISMAV"), Some(&1.0));
    assert_eq!(log.params.get("AHRS_EKF_TYPE"), Some(&10.0));
    assert_eq!(log.params.get("AHRS_TRIM_X"), Some(&0.0));
    assert!(!log.notes.iter().any(|n| n.contains("AHRS_TRIM")));
    // First GPS_RAW_INT: lat −35.3629847°, 1.87 m/s at course 182.82°, HDOP 1.21.
    let g = log.gnss[0];
    assert!((g.lat_deg + 35.362_984_7).abs() < 1e-9);
    let v = g.velocity.unwrap();
    assert!((v.horizontal_mps().norm() - 1.87).abs() < 1e-9);
    assert!(v.down_mps.is_none(), "GPS_RAW_INT has no vertical velocity");
    assert!((log.baro[0].pressure_pa - 94_459.54).abs() < 0.1);
    assert!(!log.reference.is_empty());
    assert!(log.notes.iter().any(|n| n.contains("telemetry stream")));
}

/// A radio link corrupts bytes: the reader skips what fails its checksum and never panics.
#[test]
fn corrupted_telemetry_never_panics() {
    let Some(root) = uavnav_testdata::shared_data("public_flight_logs") else {
        return;
    };
    let data = std::fs::read(root.join("ardupilot_vtol_sitl.tlog")).unwrap();
    let clean = uavnav_logs::import(&data, &ImportOptions::default()).unwrap();
    let mut rng = 0x2545_f491_4f6c_dd1du64;
    for _ in 0..20 {
        let mut d = data.clone();
        for _ in 0..200 {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            let i = (rng % d.len() as u64) as usize;
            d[i] ^= (rng >> 32) as u8 | 1;
        }
        let cut = d.len() - (rng % 1000) as usize;
        if let Ok(log) = uavnav_logs::import(&d[..cut], &ImportOptions::default()) {
            assert!(log.imu.len() <= clean.imu.len());
            assert!(log.imu.windows(2).all(|w| w[0].t_ns < w[1].t_ns));
        }
    }
}
