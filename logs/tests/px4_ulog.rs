//! PX4 ULog import of the shared public logs, with the message counts their README gives
//! (pyulog 1.3.0, `px4-ulog` 0.6.1 and `yule_log` 0.4.0 agree on them).
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use uavnav_logs::{ImportOptions, LogKind};

#[test]
fn ulog_counts_match_the_readme() {
    let Some(root) = uavnav_testdata::shared_data("public_flight_logs") else {
        return;
    };
    for (file, imu, gps, new_schema) in [
        ("sample_px4_events.ulg", 7783, 583, true),
        ("sample_log_small.ulg", 1298, 32, false),
    ] {
        let log = uavnav_logs::open(root.join(file), &ImportOptions::default()).expect(file);
        assert_eq!(log.source, LogKind::Px4);
        assert_eq!(
            log.message_counts.get("sensor_combined"),
            Some(&imu),
            "{file}"
        );
        assert_eq!(
            log.message_counts.get("vehicle_gps_position"),
            Some(&gps),
            "{file}"
        );
        if file == "sample_px4_events.ulg" {
            // the README's third count: vehicle_imu at 2 Hz in this logging profile
            assert_eq!(log.message_counts.get("vehicle_imu"), Some(&62), "{file}");
        }
        assert_eq!(
            log.imu.len(),
            imu,
            "{file}: every sensor_combined sample kept"
        );
        assert!(!log.gnss.is_empty(), "{file}: no fixes kept");
        for g in &log.gnss {
            assert!(g.lat_deg.abs() <= 90.0 && g.lon_deg.abs() <= 180.0);
            assert!(
                g.alt_m > -500.0 && g.alt_m < 9000.0,
                "{file} altitude {}",
                g.alt_m
            );
        }
        // the accelerometer reads ~1 g at rest or in steady flight
        let g_mean: f64 =
            log.imu.iter().map(|s| s.accel_mps2.norm()).sum::<f64>() / log.imu.len() as f64;
        assert!((g_mean - 9.8).abs() < 1.5, "{file} mean |f| {g_mean}");
        eprintln!(
            "{file} (new schema {new_schema}): IMU {} at {:.1} Hz, GNSS kept {} of {gps}, MAG {}, BARO {}, reference {} origin {:?}, delay {} s, vehicle {:?}, firmware {:?}, time {:?}, notes {:?}",
            log.imu.len(),
            log.config.imu.rate_hz,
            log.gnss.len(),
            log.mag.len(),
            log.baro.len(),
            log.reference.len(),
            log.reference_origin,
            log.gnss_delay_s,
            log.vehicle,
            log.firmware,
            log.time_base,
            log.notes
        );
    }
}
