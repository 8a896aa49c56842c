//! The ASL/EuRoC folder layout extended with `gnss0`: paths, CSV headers and column names.
//!
//! ```text
//! <root>/mav0/imu0/data.csv, sensor.yaml          IMU (body = imu0 frame)
//! <root>/mav0/cam0/data.csv, sensor.yaml, data/   camera 0, images <t_ns>.png|.jpg
//! <root>/mav0/gnss0/data.csv, sensor.yaml         GNSS (T_BS translation = lever arm)
//! <root>/mav0/mag0/data.csv, sensor.yaml          magnetometer (T_BS rotation: mag -> body)
//! <root>/mav0/baro0/data.csv, sensor.yaml         barometer
//! <root>/mav0/state_groundtruth_estimate0/data.csv, sensor.yaml (origin)   optional truth
//! <root>/mav0/body.yaml                           optional uavnav extras (vehicle_id,
//!                                                 terrain_elevation_m, filter_profile)
//! <root>/conversion.json                          optional record of a flight-log conversion:
//!                                                 an ArduPilot trim in it rotates the IMU
//!                                                 (see `super::conversion`)
//! ```

/// The sensor folder names.
pub const MAV: &str = "mav0";
/// IMU folder.
pub const IMU: &str = "imu0";
/// Camera 0 folder.
pub const CAM: &str = "cam0";
/// GNSS folder.
pub const GNSS: &str = "gnss0";
/// Magnetometer folder.
pub const MAG: &str = "mag0";
/// Barometer folder.
pub const BARO: &str = "baro0";
/// Truth folder.
pub const TRUTH: &str = "state_groundtruth_estimate0";
/// Data file in each sensor folder.
pub const DATA_CSV: &str = "data.csv";
/// Sensor description in each sensor folder.
pub const SENSOR_YAML: &str = "sensor.yaml";
/// Camera image folder inside `cam0`.
pub const IMAGE_DIR: &str = "data";
/// Vehicle-level extras (EuRoC ships a `body.yaml` with a comment only).
pub const BODY_YAML: &str = "body.yaml";

/// `imu0/data.csv` header, written exactly.
pub const IMU_HEADER: &str = "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]";
/// `imu0/data.csv` columns (names without units), read by name.
pub const IMU_COLUMNS: &[&str] = &[
    "timestamp",
    "w_RS_S_x",
    "w_RS_S_y",
    "w_RS_S_z",
    "a_RS_S_x",
    "a_RS_S_y",
    "a_RS_S_z",
];

/// `cam0/data.csv` header.
pub const CAM_HEADER: &str = "#timestamp [ns],filename";
/// `cam0/data.csv` columns.
pub const CAM_COLUMNS: &[&str] = &["timestamp", "filename"];

/// `gnss0/data.csv` header (altitude above the WGS84 ellipsoid).
pub const GNSS_HEADER: &str = "#timestamp [ns],latitude [deg],longitude [deg],altitude [m],v_north [m s^-1],v_east [m s^-1],v_down [m s^-1],sigma_horizontal [m],sigma_vertical [m],sigma_velocity [m s^-1]";
/// `gnss0/data.csv` columns.
pub const GNSS_COLUMNS: &[&str] = &[
    "timestamp",
    "latitude",
    "longitude",
    "altitude",
    "v_north",
    "v_east",
    "v_down",
    "sigma_horizontal",
    "sigma_vertical",
    "sigma_velocity",
];

/// `mag0/data.csv` header: calibrated flux density in the magnetometer frame.
pub const MAG_HEADER: &str = "#timestamp [ns],m_x [T],m_y [T],m_z [T]";
/// `mag0/data.csv` columns.
pub const MAG_COLUMNS: &[&str] = &["timestamp", "m_x", "m_y", "m_z"];

/// `baro0/data.csv` header (the temperature cell may be empty).
pub const BARO_HEADER: &str = "#timestamp [ns],pressure [Pa],temperature [degC]";
/// `baro0/data.csv` columns.
pub const BARO_COLUMNS: &[&str] = &["timestamp", "pressure", "temperature"];

/// `state_groundtruth_estimate0/data.csv` header (the EuRoC columns).
pub const TRUTH_HEADER: &str = "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]";
/// Truth columns.
pub const TRUTH_COLUMNS: &[&str] = &[
    "timestamp",
    "p_RS_R_x",
    "p_RS_R_y",
    "p_RS_R_z",
    "q_RS_w",
    "q_RS_x",
    "q_RS_y",
    "q_RS_z",
    "v_RS_R_x",
    "v_RS_R_y",
    "v_RS_R_z",
    "b_w_RS_S_x",
    "b_w_RS_S_y",
    "b_w_RS_S_z",
    "b_a_RS_S_x",
    "b_a_RS_S_y",
    "b_a_RS_S_z",
];

/// Formats a float for CSV/YAML: shortest text that parses back to the same `f64` (exponent form
/// for very small or large magnitudes), so files round-trip bit-exactly. Negative zero is written
/// as `0.0`: protobuf and MCAP do not keep the sign of zero, and the files must not depend on the
/// path the data took.
pub fn fmt_f64(v: f64) -> String {
    let v = if v == 0.0 { 0.0 } else { v };
    format!("{v:?}")
}
