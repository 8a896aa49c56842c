//! ArduPilot's board frame and vehicle frame: the one statement of how `AHRS_TRIM_X/Y` is applied,
//! for every reader that meets it (a `.BIN`, a `.tlog`, an ASL folder's `conversion.json`).
//!
//! ArduPilot logs its IMU and compass in the board frame and reports its attitude (`ATT`,
//! `ATTITUDE`, and the `EKF1`/`NKF1`/`XKF1` the references come from) in the vehicle frame: the
//! board rotated by `AHRS_TRIM_X/Y`, the board's roll and pitch on the airframe that its level
//! calibration sets. Read without it, an estimate sits one trim away from every autopilot
//! reference (copter_103: 0.68° of roll). The readers rotate the IMU samples into the vehicle
//! frame ([`rotate_imu`]) and compose the compass's `body_from_mag` with the same rotation
//! ([`rotate_mag_config`]; its samples stay as logged).

use std::collections::BTreeMap;

use nalgebra::{Rotation3, UnitQuaternion};
use uavnav_core::{ImuSample, MagConfig, VehicleConfig};

/// Largest trim ArduPilot accepts for `AHRS_TRIM_X/Y`, rad (10°).
pub const MAX_TRIM_RAD: f64 = 0.1745;

/// `vehicle_from_board` of ArduPilot's `AHRS_TRIM_X/Y` (rad): the rotation that takes a vector
/// from the board frame (IMU, compass) into the vehicle frame the autopilot reports its attitude
/// in. ArduPilot builds `R = from_euler(trim_x, trim_y, 0)` (ZYX, as `nav_from_body`) and
/// reports `C_nav_vehicle = C_nav_board Rᵀ`, so a board vector `u` is `R u` in the vehicle frame
/// (a board rolled +δ on the airframe, with trim δ, reads level). `None` when both are 0, absent,
/// not finite or beyond [`MAX_TRIM_RAD`] (not a trim ArduPilot would use).
pub fn vehicle_from_board(
    trim_x_rad: Option<f64>,
    trim_y_rad: Option<f64>,
) -> Option<Rotation3<f64>> {
    let (x, y) = (trim_x_rad.unwrap_or(0.0), trim_y_rad.unwrap_or(0.0));
    let plausible = |v: f64| v.is_finite() && v.abs() <= MAX_TRIM_RAD;
    if !plausible(x) || !plausible(y) || (x == 0.0 && y == 0.0) {
        return None;
    }
    Some(Rotation3::from_euler_angles(x, y, 0.0))
}

/// An IMU sample in the board frame, in the vehicle frame.
pub fn rotate_imu(r: &Rotation3<f64>, s: &ImuSample) -> ImuSample {
    ImuSample {
        t_ns: s.t_ns,
        gyro_radps: r * s.gyro_radps,
        accel_mps2: r * s.accel_mps2,
    }
}

/// A compass mounted on the board (`body_from_mag` relative to the board) on the vehicle.
pub fn rotate_mag_config(r: &Rotation3<f64>, m: &mut MagConfig) {
    m.body_from_mag = UnitQuaternion::from_rotation_matrix(r) * m.body_from_mag;
}

/// The reader's note for an applied trim; `what` names where the trim came from.
pub fn note(r: &Rotation3<f64>, what: &str) -> String {
    let (roll, pitch, _) = r.euler_angles();
    format!(
        "{what}: IMU read in the vehicle frame of AHRS_TRIM_X/Y (roll {:.2}°, pitch {:.2}°), the \
         frame the autopilot reports its attitude in; the compass by its body_from_mag",
        roll.to_degrees(),
        pitch.to_degrees()
    )
}

/// A log's samples and configuration into the vehicle frame of its `params`' trim, with a note.
pub(crate) fn apply(
    params: &BTreeMap<String, f64>,
    imu: &mut [ImuSample],
    config: &mut VehicleConfig,
    notes: &mut Vec<String>,
) {
    let Some(r) = vehicle_from_board(
        params.get("AHRS_TRIM_X").copied(),
        params.get("AHRS_TRIM_Y").copied(),
    ) else {
        return;
    };
    for s in imu.iter_mut() {
        *s = rotate_imu(&r, s);
    }
    if let Some(m) = config.mag.as_mut() {
        rotate_mag_config(&r, m);
    }
    notes.push(note(&r, "parameters"));
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// A board rolled +3° and pitched −2° on a level airframe, with that trim: its accelerometer
    /// reads level in the vehicle frame. No trim, or one ArduPilot would not take, is no rotation.
    #[test]
    fn the_trim_levels_the_board() {
        let (roll, pitch) = (3f64.to_radians(), -2f64.to_radians());
        let nav_from_board = Rotation3::from_euler_angles(roll, pitch, 0.0);
        let s = ImuSample {
            t_ns: 0,
            gyro_radps: Vector3::zeros(),
            accel_mps2: nav_from_board.inverse() * Vector3::new(0.0, 0.0, -9.81),
        };
        let r = vehicle_from_board(Some(roll), Some(pitch)).unwrap();
        let f_vehicle = rotate_imu(&r, &s).accel_mps2;
        assert!(
            (f_vehicle - Vector3::new(0.0, 0.0, -9.81)).norm() < 1e-12,
            "{f_vehicle}"
        );
        assert!(vehicle_from_board(None, None).is_none());
        assert!(vehicle_from_board(Some(0.0), Some(0.0)).is_none());
        assert!(
            vehicle_from_board(Some(0.2), Some(0.0)).is_none(),
            "beyond 10°"
        );
        assert!(vehicle_from_board(Some(f64::NAN), Some(0.01)).is_none());
    }

    /// `apply` rotates the samples and the compass, and says so; no trim leaves both alone.
    #[test]
    fn apply_rotates_samples_and_compass_with_a_note() {
        let mut params = BTreeMap::new();
        let mut imu = vec![ImuSample {
            t_ns: 1,
            gyro_radps: Vector3::new(0.0, 0.0, 1.0),
            accel_mps2: Vector3::new(0.0, 0.0, -9.81),
        }];
        let mut config = VehicleConfig {
            mag: Some(MagConfig::default()),
            ..VehicleConfig::default()
        };
        let mut notes = Vec::new();
        apply(&params, &mut imu, &mut config, &mut notes);
        assert!(notes.is_empty() && imu[0].accel_mps2.x == 0.0);
        params.insert("AHRS_TRIM_Y".into(), 0.02);
        apply(&params, &mut imu, &mut config, &mut notes);
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(imu[0].accel_mps2.x.abs() > 0.1);
        let m = config.mag.unwrap();
        assert!((m.body_from_mag.angle() - 0.02).abs() < 1e-12);
    }
}
