//! Pose output files: the `poses.csv` row (the columns of `uavnav estimate` and `watch`) and the
//! TUM trajectory line, as pure line formatters.

use uavnav_core::PoseOutput;

/// The mandatory leading columns of `poses.csv`, in order.
pub const CSV_LEADING_COLUMNS: &str = "timestamp_ns,latitude_deg,longitude_deg,altitude_m,v_north_mps,v_east_mps,v_down_mps,qw,qx,qy,qz,roll_deg,pitch_deg,yaw_deg,sigma_north_m,sigma_east_m,sigma_down_m,sigma_roll_deg,sigma_pitch_deg,sigma_yaw_deg";

/// Extra columns that follow the leading ones.
pub const CSV_EXTRA_COLUMNS: &str = "mode,gnss_pos_test_ratio,gnss_vel_test_ratio,vision_rot_test_ratio,vision_trans_test_ratio,gnss_pos_rejected,gnss_vel_rejected,vision_rejected";

/// The full header line (no newline).
pub fn csv_header() -> String {
    format!("{CSV_LEADING_COLUMNS},{CSV_EXTRA_COLUMNS}")
}

/// One `poses.csv` row (no newline): degrees at this edge, altitude above the ellipsoid, the
/// quaternion `nav_from_body` (w first), ZYX Euler angles. In a mode without position
/// ([`uavnav_core::Mode::AttitudeOnly`]) the position, velocity and position-σ cells are empty.
pub fn csv_row(o: &PoseOutput) -> String {
    let q = o.nav_from_body.quaternion();
    let e = o.euler_rad.map(f64::to_degrees);
    let se = o.sigma_att_rad.map(f64::to_degrees);
    let h = &o.health;
    let position = if h.mode.has_position() {
        format!(
            "{:.9},{:.9},{:.4},{:.5},{:.5},{:.5}",
            o.lla.lat_deg(),
            o.lla.lon_deg(),
            o.lla.alt_m,
            o.vel_ned_mps.x,
            o.vel_ned_mps.y,
            o.vel_ned_mps.z,
        )
    } else {
        ",,,,,".to_owned()
    };
    let sigma_pos = if h.mode.has_position() {
        format!(
            "{:.4},{:.4},{:.4}",
            o.sigma_pos_ned_m.x, o.sigma_pos_ned_m.y, o.sigma_pos_ned_m.z,
        )
    } else {
        ",,".to_owned()
    };
    format!(
        "{},{position},{:.9},{:.9},{:.9},{:.9},{:.5},{:.5},{:.5},{sigma_pos},{:.5},{:.5},{:.5},{},{:.4},{:.4},{:.4},{:.4},{},{},{}",
        o.t_ns,
        q.w,
        q.i,
        q.j,
        q.k,
        e.x,
        e.y,
        e.z,
        se.x,
        se.y,
        se.z,
        h.mode.as_str(),
        h.gnss_pos.test_ratio,
        h.gnss_vel.test_ratio,
        h.vision_rot.test_ratio,
        h.vision_trans.test_ratio,
        h.gnss_pos.rejected,
        h.gnss_vel.rejected,
        h.vision_rot.rejected + h.vision_trans.rejected,
    )
}

/// One TUM line `t_s x y z qx qy qz qw` (no newline): time in s, position in the estimator's local
/// NED frame (its origin is the first GNSS fix unless an origin was given), `nav_from_body`;
/// `None` in a mode without position (a trajectory line needs one).
pub fn tum_line(o: &PoseOutput) -> Option<String> {
    if !o.health.mode.has_position() {
        return None;
    }
    let q = o.nav_from_body.quaternion();
    Some(format!(
        "{:.9} {:.4} {:.4} {:.4} {:.9} {:.9} {:.9} {:.9}",
        o.t_ns as f64 * 1e-9,
        o.pos_ned_m.x,
        o.pos_ned_m.y,
        o.pos_ned_m.z,
        q.i,
        q.j,
        q.k,
        q.w
    ))
}
