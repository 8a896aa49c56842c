//! `sensor.yaml` (and `body.yaml`) ↔ the parts of [`VehicleConfig`] they describe.

use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};
use uavnav_core::{
    BaroConfig, CameraConfig, CameraModel, Distortion, FilterProfile, GnssConfig, ImuConfig, Lla,
    MagConfig,
};

use super::layout::fmt_f64;
use crate::error::{DatasetError, Result};
use crate::yaml::Yaml;

/// Largest accepted deviation of `T_BS`'s rotation block from orthonormal (EuRoC prints 12 digits).
const ROTATION_TOL: f64 = 1e-4;

/// `T_BS` as an isometry `body_from_sensor`.
pub fn read_t_bs(y: &Yaml) -> Result<Isometry3<f64>> {
    let m = y.matrix4("T_BS")?;
    let line = y.get("T_BS").map_or(1, |n| n.line);
    let r = Matrix3::new(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]);
    let err = (r.transpose() * r - Matrix3::identity()).abs().max();
    if err > ROTATION_TOL || r.determinant() < 0.0 {
        return Err(DatasetError::parse(
            y.path(),
            line,
            "`T_BS` rotation block is not a rotation",
        ));
    }
    if m[12] != 0.0 || m[13] != 0.0 || m[14] != 0.0 || m[15] != 1.0 {
        return Err(DatasetError::parse(
            y.path(),
            line,
            "`T_BS` last row must be [0, 0, 0, 1]",
        ));
    }
    // Orthonormalise the printed matrix (from_matrix iterates to the nearest rotation).
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r));
    Ok(Isometry3::from_parts(
        Translation3::new(m[3], m[7], m[11]),
        rot,
    ))
}

/// `T_BS` block in the OpenCV-matrix style EuRoC uses.
pub fn write_t_bs(t: &Isometry3<f64>) -> String {
    let m = t.to_homogeneous();
    let rows: Vec<String> = (0..4)
        .map(|r| {
            (0..4)
                .map(|c| fmt_f64(m[(r, c)]))
                .collect::<Vec<_>>()
                .join(", ")
        })
        .collect();
    format!(
        "T_BS:\n  cols: 4\n  rows: 4\n  data: [{}]\n",
        rows.join(",\n         ")
    )
}

fn positive(y: &Yaml, key: &str) -> Result<f64> {
    let v = y.f64(key)?;
    if v > 0.0 {
        Ok(v)
    } else {
        let line = y.get(key).map_or(1, |n| n.line);
        Err(DatasetError::parse(
            y.path(),
            line,
            format!("`{key}` must be > 0, found {v}"),
        ))
    }
}

/// The IMU noise model from `imu0/sensor.yaml`. `T_BS` must be the identity (body = IMU frame).
pub fn read_imu(path: &Path) -> Result<ImuConfig> {
    let y = Yaml::read(path)?;
    if y.get("T_BS").is_some() {
        let t = read_t_bs(&y)?;
        if t.translation.vector.norm() > 1e-9 || t.rotation.angle() > 1e-9 {
            let line = y.get("T_BS").map_or(1, |n| n.line);
            return Err(DatasetError::parse(
                path,
                line,
                "imu0 `T_BS` must be the identity (body = IMU frame)",
            ));
        }
    }
    Ok(ImuConfig {
        rate_hz: positive(&y, "rate_hz")?,
        gyro_noise_density: y.f64("gyroscope_noise_density")?,
        gyro_random_walk: y.f64("gyroscope_random_walk")?,
        accel_noise_density: y.f64("accelerometer_noise_density")?,
        accel_random_walk: y.f64("accelerometer_random_walk")?,
        gyro_bias_sigma_radps: optional_non_negative(&y, GYRO_BIAS_KEY)?,
        accel_bias_sigma_mps2: optional_non_negative(&y, ACCEL_BIAS_KEY)?,
    })
}

/// Optional `imu0/sensor.yaml` keys (not in EuRoC/Kalibr): the turn-on biases' 1-σ.
const GYRO_BIAS_KEY: &str = "gyroscope_turn_on_bias_sigma";
const ACCEL_BIAS_KEY: &str = "accelerometer_turn_on_bias_sigma";

/// An optional key's value, ≥ 0 and finite; 0 when absent.
fn optional_non_negative(y: &Yaml, key: &str) -> Result<f64> {
    let Some(node) = y.get(key) else {
        return Ok(0.0);
    };
    let v = y.f64(key)?;
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(DatasetError::parse(
            y.path(),
            node.line,
            format!("`{key}` must be finite and >= 0, found {v}"),
        ))
    }
}

/// `imu0/sensor.yaml` text.
pub fn write_imu(c: &ImuConfig) -> String {
    // The turn-on biases only when known, so files of IMUs without them stay as they were.
    let mut biases = String::new();
    if c.gyro_bias_sigma_radps > 0.0 {
        biases += &format!(
            "{GYRO_BIAS_KEY}: {}   # [ rad / s ]\n",
            fmt_f64(c.gyro_bias_sigma_radps)
        );
    }
    if c.accel_bias_sigma_mps2 > 0.0 {
        biases += &format!(
            "{ACCEL_BIAS_KEY}: {}   # [ m / s^2 ]\n",
            fmt_f64(c.accel_bias_sigma_mps2)
        );
    }
    format!(
        "%YAML:1.0\nsensor_type: imu\ncomment: written by uavnav\n{}rate_hz: {}\n\
         gyroscope_noise_density: {}     # [ rad / s / sqrt(Hz) ]\n\
         gyroscope_random_walk: {}       # [ rad / s^2 / sqrt(Hz) ]\n\
         accelerometer_noise_density: {} # [ m / s^2 / sqrt(Hz) ]\n\
         accelerometer_random_walk: {}   # [ m / s^3 / sqrt(Hz) ]\n{biases}",
        write_t_bs(&Isometry3::identity()),
        fmt_f64(c.rate_hz),
        fmt_f64(c.gyro_noise_density),
        fmt_f64(c.gyro_random_walk),
        fmt_f64(c.accel_noise_density),
        fmt_f64(c.accel_random_walk),
    )
}

/// Camera 0 from `cam0/sensor.yaml`.
pub fn read_camera(path: &Path) -> Result<CameraConfig> {
    let y = Yaml::read(path)?;
    let line = |key: &str| y.get(key).map_or(1, |n| n.line);
    let model = y
        .get("camera_model")
        .map(|_| y.str("camera_model"))
        .transpose()?
        .unwrap_or("pinhole");
    if model != "pinhole" {
        return Err(DatasetError::parse(
            path,
            line("camera_model"),
            format!("unsupported camera_model '{model}'"),
        ));
    }
    let res = y.f64_list("resolution", 2)?;
    let side = |v: f64| -> Result<u32> {
        if v >= 1.0 && v.fract() == 0.0 && v <= f64::from(u16::MAX) {
            Ok(v as u32)
        } else {
            Err(DatasetError::parse(
                path,
                line("resolution"),
                format!("bad image size {v}"),
            ))
        }
    };
    let k = y.f64_list("intrinsics", 4)?;
    let distortion = match y
        .get("distortion_model")
        .map(|_| y.str("distortion_model"))
        .transpose()?
    {
        None | Some("none") => Distortion::None,
        Some("radial-tangential" | "radtan") => {
            let d = y.f64_list("distortion_coefficients", 4)?;
            Distortion::RadTan {
                k1: d[0],
                k2: d[1],
                p1: d[2],
                p2: d[3],
            }
        }
        Some(other) => {
            return Err(DatasetError::parse(
                path,
                line("distortion_model"),
                format!(
                    "unsupported distortion_model '{other}' (expected radial-tangential or none)"
                ),
            ));
        }
    };
    if k[0] <= 0.0 || k[1] <= 0.0 {
        return Err(DatasetError::parse(
            path,
            line("intrinsics"),
            "focal lengths must be > 0",
        ));
    }
    Ok(CameraConfig {
        rate_hz: positive(&y, "rate_hz")?,
        model: CameraModel {
            width: side(res[0])?,
            height: side(res[1])?,
            fx: k[0],
            fy: k[1],
            cx: k[2],
            cy: k[3],
            distortion,
        },
        body_from_cam: read_t_bs(&y)?,
    })
}

/// `cam0/sensor.yaml` text.
pub fn write_camera(c: &CameraConfig) -> String {
    let m = &c.model;
    let (name, [k1, k2, p1, p2]) = match m.distortion {
        Distortion::None => ("none", [0.0; 4]),
        Distortion::RadTan { k1, k2, p1, p2 } => ("radial-tangential", [k1, k2, p1, p2]),
    };
    let f = fmt_f64;
    format!(
        "%YAML:1.0\nsensor_type: camera\ncomment: written by uavnav\n\
         # Camera pose in the body frame: p_body = T_BS * p_cam.\n{}rate_hz: {}\nresolution: [{}, {}]\n\
         camera_model: pinhole\nintrinsics: [{}, {}, {}, {}] # fu, fv, cu, cv\ndistortion_model: {name}\n\
         distortion_coefficients: [{}, {}, {}, {}]\n",
        write_t_bs(&c.body_from_cam),
        f(c.rate_hz),
        m.width,
        m.height,
        f(m.fx),
        f(m.fy),
        f(m.cx),
        f(m.cy),
        f(k1),
        f(k2),
        f(p1),
        f(p2),
    )
}

/// Longest GNSS delay accepted, s: autopilots report 0.1–0.5 s; longer means a wrong unit (the
/// service's bound, which keeps the estimator's IMU history within its memory bound).
pub const MAX_GNSS_DELAY_S: f64 = 1.0;

/// The GNSS receiver from `gnss0/sensor.yaml` (lever arm = `T_BS` translation; optional `delay_s`,
/// how long after its validity a fix is stamped, default 0).
pub fn read_gnss(path: &Path) -> Result<GnssConfig> {
    let y = Yaml::read(path)?;
    let t = read_t_bs(&y)?;
    let delay_s = match y.get("delay_s") {
        Some(node) => {
            let d = y.f64("delay_s")?;
            if !(0.0..=MAX_GNSS_DELAY_S).contains(&d) {
                return Err(DatasetError::parse(
                    path,
                    node.line,
                    format!("`delay_s` must be within 0..={MAX_GNSS_DELAY_S} s, found {d}"),
                ));
            }
            d
        }
        None => 0.0,
    };
    let altitude_reference = match y.get("altitude_reference") {
        Some(node) => y
            .str("altitude_reference")?
            .parse()
            .map_err(|e: String| DatasetError::parse(path, node.line, e))?,
        None => uavnav_core::AltitudeReference::Ellipsoid,
    };
    Ok(GnssConfig {
        rate_hz: positive(&y, "rate_hz")?,
        lever_arm_body_m: t.translation.vector,
        delay_ns: uavnav_core::s_to_ns(delay_s),
        altitude_reference,
    })
}

/// The magnetometer from `mag0/sensor.yaml`: `T_BS` (rotation only: magnetometer -> body),
/// `rate_hz`, and its noise as `sigma` [T] (one number, or one per axis: the largest is used).
pub fn read_mag(path: &Path) -> Result<MagConfig> {
    let y = Yaml::read(path)?;
    let t = read_t_bs(&y)?;
    let sigma_t = match y.f64("sigma") {
        Ok(s) => s,
        Err(_) => y.f64_list("sigma", 3)?.into_iter().fold(0.0, f64::max),
    };
    if !(sigma_t > 0.0 && sigma_t < 1e-4) {
        let line = y.get("sigma").map_or(1, |n| n.line);
        return Err(DatasetError::parse(
            path,
            line,
            format!("`sigma` must be in tesla, > 0 and < 1e-4, found {sigma_t}"),
        ));
    }
    Ok(MagConfig {
        rate_hz: positive(&y, "rate_hz")?,
        body_from_mag: t.rotation,
        sigma_t,
    })
}

/// `mag0/sensor.yaml` text.
pub fn write_mag(c: &MagConfig) -> String {
    let t = Isometry3::from_parts(Translation3::identity(), c.body_from_mag);
    format!(
        "%YAML:1.0\nsensor_type: magnetometer\ncomment: written by uavnav\n\
         # T_BS: magnetometer frame -> body frame (FRD, = imu0); rotation only.\n{}rate_hz: {}\n\
         sigma: {} # [T] per axis and sample\n",
        write_t_bs(&t),
        fmt_f64(c.rate_hz),
        fmt_f64(c.sigma_t),
    )
}

/// The barometer from `baro0/sensor.yaml`: `rate_hz`, `sigma_pressure` [Pa].
pub fn read_baro(path: &Path) -> Result<BaroConfig> {
    let y = Yaml::read(path)?;
    Ok(BaroConfig {
        rate_hz: positive(&y, "rate_hz")?,
        sigma_pressure_pa: positive(&y, "sigma_pressure")?,
    })
}

/// `baro0/sensor.yaml` text.
pub fn write_baro(c: &BaroConfig) -> String {
    format!(
        "%YAML:1.0\nsensor_type: barometer\ncomment: written by uavnav\nrate_hz: {}\n\
         sigma_pressure: {} # [Pa] per sample\n",
        fmt_f64(c.rate_hz),
        fmt_f64(c.sigma_pressure_pa),
    )
}

/// `gnss0/sensor.yaml` text.
pub fn write_gnss(c: &GnssConfig) -> String {
    let t = Isometry3::from_parts(
        Translation3::from(c.lever_arm_body_m),
        UnitQuaternion::identity(),
    );
    format!(
        "%YAML:1.0\nsensor_type: gnss\ncomment: written by uavnav\n\
         # Antenna phase centre in the body frame: the T_BS translation is the lever arm, m.\n{}rate_hz: {}\n\
         delay_s: {} # a fix stamped t was valid at t - delay_s\n\
         altitude_reference: {} # ellipsoid (WGS84) or msl (EGM96 geoid)\n",
        write_t_bs(&t),
        fmt_f64(c.rate_hz),
        fmt_f64(uavnav_core::ns_to_s(c.delay_ns)),
        c.altitude_reference.as_str()
    )
}

/// The truth origin from `state_groundtruth_estimate0/sensor.yaml`, if it has one.
pub fn read_origin(path: &Path) -> Result<Option<Lla>> {
    if !path.exists() {
        return Ok(None);
    }
    let y = Yaml::read(path)?;
    if y.get("origin").is_none() {
        return Ok(None);
    }
    let o = y.f64_list("origin", 3)?;
    let line = y.get("origin").map_or(1, |n| n.line);
    if !(-90.0..=90.0).contains(&o[0]) || !(-180.0..=180.0).contains(&o[1]) {
        return Err(DatasetError::parse(
            path,
            line,
            "origin latitude/longitude out of range",
        ));
    }
    Ok(Some(Lla::from_deg(o[0], o[1], o[2])))
}

/// `state_groundtruth_estimate0/sensor.yaml` text.
pub fn write_truth(origin: Option<&Lla>) -> String {
    let mut s = String::from(
        "%YAML:1.0\nsensor_type: visual-inertial\ncomment: ground truth written by uavnav\n\
         # R is the local NED tangent frame at origin; q_RS rotates body vectors into R; body = imu0.\n",
    );
    s.push_str(&write_t_bs(&Isometry3::identity()));
    if let Some(o) = origin {
        s.push_str(&format!(
            "origin: [{}, {}, {}] # lat_deg, lon_deg, alt_m (WGS84 ellipsoid)\n",
            fmt_f64(o.lat_deg()),
            fmt_f64(o.lon_deg()),
            fmt_f64(o.alt_m)
        ));
    }
    s
}

/// The prefix of the `comment` that marks `state_groundtruth_estimate0` as a reference (another
/// estimator's output) rather than ground truth; the shared real-flight conversions use it.
pub const NOT_TRUTH_PREFIX: &str = "NOT ground truth";

/// Whether `state_groundtruth_estimate0/sensor.yaml` marks its samples as a reference: `Some`
/// with the `reference` key's value (what produced it) when the `comment` starts with
/// [`NOT_TRUTH_PREFIX`] or a `reference` key is present; `None` for ground truth or no file.
pub fn read_reference_marker(path: &Path) -> Result<Option<Option<String>>> {
    if !path.exists() {
        return Ok(None);
    }
    let y = Yaml::read(path)?;
    let source = y.get("reference").map(|_| y.str("reference")).transpose()?;
    let marked = y
        .get("comment")
        .map(|_| y.str("comment"))
        .transpose()?
        .is_some_and(|c| {
            c.get(..NOT_TRUTH_PREFIX.len())
                .is_some_and(|p| p.eq_ignore_ascii_case(NOT_TRUTH_PREFIX))
        });
    Ok((marked || source.is_some()).then(|| source.map(str::to_owned)))
}

/// `state_groundtruth_estimate0/sensor.yaml` text for a reference: the same layout as for truth,
/// with the shared conversions' "NOT ground truth" comment and the `reference` key.
pub fn write_reference(origin: Option<&Lla>, source: Option<&str>) -> String {
    let truth = write_truth(origin);
    let what = source.unwrap_or("estimate");
    let mut s = truth.replacen(
        "comment: ground truth written by uavnav\n",
        &format!(
            "comment: {NOT_TRUTH_PREFIX}: the autopilot's own {what}, written by uavnav from a flight log\n"
        ),
        1,
    );
    if let Some(src) = source {
        s.push_str(&format!("reference: {src}\n"));
    }
    s
}

/// The uavnav extras of `body.yaml`.
#[derive(Debug, Clone, PartialEq)]
pub struct BodyExtras {
    /// Vehicle identifier.
    pub vehicle_id: Option<String>,
    /// Terrain elevation above the ellipsoid, m.
    pub terrain_elevation_m: f64,
    /// Filter profile.
    pub profile: FilterProfile,
    /// Airframe (`airframe: unknown | fixed_wing | multirotor`).
    pub airframe: uavnav_core::Airframe,
}

/// Reads `body.yaml` if present (missing keys take defaults).
pub fn read_body(path: &Path) -> Result<BodyExtras> {
    let mut out = BodyExtras {
        vehicle_id: None,
        terrain_elevation_m: 0.0,
        profile: FilterProfile::default(),
        airframe: uavnav_core::Airframe::default(),
    };
    if !path.exists() {
        return Ok(out);
    }
    let y = Yaml::read(path)?;
    if y.get("vehicle_id").is_some() {
        out.vehicle_id = Some(y.str("vehicle_id")?.to_owned());
    }
    if y.get("terrain_elevation_m").is_some() {
        out.terrain_elevation_m = y.f64("terrain_elevation_m")?;
    }
    if y.get("filter_profile").is_some() {
        let line = y.get("filter_profile").map_or(1, |n| n.line);
        out.profile = y
            .str("filter_profile")?
            .parse()
            .map_err(|e: String| DatasetError::parse(path, line, e))?;
    }
    if y.get("airframe").is_some() {
        let line = y.get("airframe").map_or(1, |n| n.line);
        out.airframe = y
            .str("airframe")?
            .parse()
            .map_err(|e: String| DatasetError::parse(path, line, e))?;
    }
    Ok(out)
}

/// `body.yaml` text.
pub fn write_body(
    vehicle_id: &str,
    terrain_elevation_m: f64,
    profile: FilterProfile,
    airframe: uavnav_core::Airframe,
) -> String {
    format!(
        "%YAML:1.0\ncomment: written by uavnav\nvehicle_id: {vehicle_id}\n\
         terrain_elevation_m: {} # above the WGS84 ellipsoid, m\nfilter_profile: {}\n\
         airframe: {} # unknown | fixed_wing | multirotor\n",
        fmt_f64(terrain_elevation_m),
        profile.as_str(),
        airframe.as_str()
    )
}
