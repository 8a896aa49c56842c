//! `<root>/conversion.json`: the record a flight-log conversion leaves beside `mav0` (the shared
//! real flights carry one). One fact in it changes how the data is read: an ArduPilot log's
//! `params.AHRS_TRIM_X/Y`, the board's roll and pitch on the airframe. Such a conversion keeps the
//! IMU and compass in the board frame the autopilot logs in, while the autopilot reports its
//! attitude (and every reference taken from it) in the vehicle frame; the reader rotates the IMU
//! into the vehicle frame and composes the compass's `body_from_mag` with the same rotation
//! (`uavnav_logs::trim`), as `uavnav convert` does for a log it imports
//! itself (it writes no `conversion.json`, so nothing is rotated twice).

use std::path::Path;

use nalgebra::Rotation3;

use crate::error::{DatasetError, Result};

/// File name, beside `mav0`.
pub const CONVERSION_JSON: &str = "conversion.json";

/// The `vehicle_from_board` rotation a `conversion.json` in `root` states (`None` without the
/// file, without the trim parameters, or with both 0).
pub fn vehicle_from_board(root: &Path) -> Result<Option<Rotation3<f64>>> {
    let path = root.join(CONVERSION_JSON);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(DatasetError::io(&path, e)),
    };
    let unsupported = |message: String| DatasetError::Unsupported {
        path: path.clone(),
        message,
    };
    let json: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| unsupported(format!("not JSON ({e})")))?;
    let trim = |key: &str| -> Result<Option<f64>> {
        match json.get("params").and_then(|p| p.get(key)) {
            None | Some(serde_json::Value::Null) => Ok(None),
            Some(v) => v
                .as_f64()
                .filter(|x| x.is_finite())
                .map(Some)
                .ok_or_else(|| unsupported(format!("params.{key}: {v} is not a number"))),
        }
    };
    let (x, y) = (trim("AHRS_TRIM_X")?, trim("AHRS_TRIM_Y")?);
    for (key, v) in [("AHRS_TRIM_X", x), ("AHRS_TRIM_Y", y)] {
        if let Some(v) = v
            && v.abs() > uavnav_logs::trim::MAX_TRIM_RAD
        {
            return Err(unsupported(format!(
                "params.{key}: {v} rad is beyond ArduPilot's ±10° trim"
            )));
        }
    }
    Ok(uavnav_logs::trim::vehicle_from_board(x, y))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, text: &str) {
        std::fs::write(dir.join(CONVERSION_JSON), text).unwrap();
    }

    #[test]
    fn the_trim_is_read_and_bad_values_are_named() {
        let dir = tempfile::tempdir().unwrap();
        assert!(vehicle_from_board(dir.path()).unwrap().is_none(), "no file");
        write(
            dir.path(),
            r#"{"params": {"AHRS_TRIM_X": 0.0119, "AHRS_TRIM_Y": -0.0039}}"#,
        );
        let r = vehicle_from_board(dir.path()).unwrap().unwrap();
        let (roll, pitch, yaw) = r.euler_angles();
        assert!((roll - 0.0119).abs() < 1e-12 && (pitch + 0.0039).abs() < 1e-12 && yaw == 0.0);
        write(
            dir.path(),
            r#"{"params": {"AHRS_TRIM_X": 0.0, "AHRS_TRIM_Y": 0.0}}"#,
        );
        assert!(
            vehicle_from_board(dir.path()).unwrap().is_none(),
            "zero trim"
        );
        write(dir.path(), r#"{"source": "something else"}"#);
        assert!(
            vehicle_from_board(dir.path()).unwrap().is_none(),
            "no params"
        );
        write(dir.path(), r#"{"params": {"AHRS_TRIM_X": "x"}}"#);
        let e = vehicle_from_board(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("conversion.json") && e.contains("AHRS_TRIM_X"),
            "{e}"
        );
        write(dir.path(), r#"{"params": {"AHRS_TRIM_Y": 0.5}}"#);
        let e = vehicle_from_board(dir.path()).unwrap_err().to_string();
        assert!(e.contains("AHRS_TRIM_Y") && e.contains("10°"), "{e}");
        write(dir.path(), "{not json");
        let e = vehicle_from_board(dir.path()).unwrap_err().to_string();
        assert!(e.contains("not JSON"), "{e}");
    }
}
