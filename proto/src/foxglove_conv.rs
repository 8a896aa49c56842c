//! Conversions into Foxglove display messages, so recordings and live views open in Foxglove.
//!
//! `CameraFrame.image` already *is* a `foxglove.CompressedImage`; GNSS fixes become
//! `foxglove.LocationFix` and pose estimates `foxglove.PoseInFrame`.

use foxglove::messages::{
    LocationFix, Pose, PoseInFrame, Timestamp, location_fix::PositionCovarianceType,
};
use uavnav_core::{GnssFix, Lla, LocalFrame};

use crate::convert::ConvertError;
use crate::v1;

/// Foxglove frame id of the local NED frame poses are drawn in.
pub const NED_FRAME_ID: &str = "ned";
/// Foxglove frame id of the GNSS antenna.
pub const GNSS_FRAME_ID: &str = "gnss0";

/// A Foxglove timestamp for a sensor time; `None` if it is negative or beyond year 2106 (Foxglove
/// timestamps are unsigned 32-bit seconds).
pub fn timestamp(t_ns: i64) -> Option<Timestamp> {
    let sec = u32::try_from(t_ns.div_euclid(1_000_000_000)).ok()?;
    let nsec = u32::try_from(t_ns.rem_euclid(1_000_000_000)).ok()?;
    Some(Timestamp::new(sec, nsec))
}

/// The Foxglove frame id of camera `camera_id` ("cam0", "cam1", ...).
pub fn camera_frame_id(camera_id: u32) -> String {
    format!("cam{camera_id}")
}

/// A GNSS fix as a `foxglove.LocationFix`: position covariance diagonal in ENU (east, north, up,
/// m²), velocity in ENU (m/s).
pub fn location_fix(f: &GnssFix) -> LocationFix {
    let (h2, v2) = (f.sigma_h_m * f.sigma_h_m, f.sigma_v_m * f.sigma_v_m);
    LocationFix {
        timestamp: timestamp(f.t_ns),
        frame_id: GNSS_FRAME_ID.to_owned(),
        latitude: f.lat_deg,
        longitude: f.lon_deg,
        altitude: f.alt_m,
        position_covariance: vec![h2, 0.0, 0.0, 0.0, h2, 0.0, 0.0, 0.0, v2],
        position_covariance_type: PositionCovarianceType::DiagonalKnown as i32,
        heading: None,
        // NED → ENU: swap north/east, negate down.
        velocity: f.velocity.map(|v| foxglove::messages::Vector3 {
            x: v.east_mps,
            y: v.north_mps,
            z: -v.down_mps.unwrap_or(0.0),
        }),
        color: None,
        metadata: Vec::new(),
    }
}

/// A pose estimate as a `foxglove.PoseInFrame` in the local NED frame of `frame` (frame id
/// [`NED_FRAME_ID`]): position = NED offset of the estimate from the frame origin, orientation =
/// `nav_from_body`.
pub fn pose_in_frame(
    p: &v1::PoseEstimate,
    frame: &LocalFrame,
) -> Result<PoseInFrame, ConvertError> {
    let lla = Lla::try_from(
        p.position
            .as_ref()
            .ok_or_else(|| ConvertError::missing("position"))?,
    )
    .map_err(|e| e.within("position"))?;
    let ned = frame.lla_to_ned(&lla);
    attitude_in_frame(p, [ned.x, ned.y, ned.z])
}

/// A pose estimate's attitude (`nav_from_body`) as a `foxglove.PoseInFrame` drawn at `at_ned_m`
/// in the local NED frame (frame id [`NED_FRAME_ID`]), whatever position the estimate carries:
/// for an estimate without one (attitude only, running without GNSS), which a 3D panel still
/// shows turning in place.
pub fn attitude_in_frame(
    p: &v1::PoseEstimate,
    at_ned_m: [f64; 3],
) -> Result<PoseInFrame, ConvertError> {
    let q = crate::convert::geometry::required_quaternion("nav_from_body", &p.nav_from_body)?;
    let [x, y, z] = at_ned_m;
    Ok(PoseInFrame {
        timestamp: timestamp(p.t_ns),
        frame_id: NED_FRAME_ID.to_owned(),
        pose: Some(Pose {
            position: Some(foxglove::messages::Vector3 { x, y, z }),
            orientation: Some(foxglove::messages::Quaternion {
                x: q.i,
                y: q.j,
                z: q.k,
                w: q.w,
            }),
        }),
    })
}

/// `v1::GnssFix` (wire) straight to `LocationFix`, validating it first.
pub fn location_fix_from_wire(f: &v1::GnssFix) -> Result<LocationFix, ConvertError> {
    Ok(location_fix(&GnssFix::try_from(f)?))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn timestamps() {
        let t = timestamp(1_403_636_579_763_555_584).expect("in range");
        assert_eq!((t.sec(), t.nsec()), (1_403_636_579, 763_555_584));
        assert!(timestamp(-1).is_none());
    }
}
