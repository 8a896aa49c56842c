//! What the `paper` profile tells the outside: the motion prior for the vision front end, its
//! health and the pose output (with the stated σ the split filters cannot know by themselves).

use super::*;
use crate::health::HeadingSource;
use heading::BankState;

impl PaperFilter {
    /// Motion prior from the gyro samples and the attitude filter.
    pub fn motion_prior(&self, t0_ns: i64, t1_ns: i64, terrain_elevation_m: f64) -> MotionPrior {
        let (Some(bfc), Some(att), Some(gi), Some(frame)) = (
            self.body_from_cam,
            self.att.as_ref(),
            self.gps_imu.as_ref(),
            self.frame.as_ref(),
        ) else {
            return MotionPrior::default();
        };
        let pv = self.vio2.as_ref().unwrap_or(gi);
        let now = crate::motion_prior::NowState {
            t_ns: att.t_ns,
            q: att.quaternion(),
            p: pv.x,
            v: pv.v,
            bg: Vector3::zeros(),
        };
        crate::motion_prior::prior(
            &self.imu,
            &bfc,
            frame,
            &now,
            t0_ns,
            t1_ns,
            terrain_elevation_m,
            self.gyro_psd.sqrt(),
            0.0,
        )
    }

    /// Whether the filters' covariance diagonals are finite (a NaN variance would be reported
    /// as a σ of 0).
    pub fn covariance_finite(&self) -> bool {
        let att = self
            .att
            .as_ref()
            .is_none_or(|a| (0..3).all(|k| a.p[(k, k)].is_finite()));
        let pv = [&self.gps_imu, &self.vio2]
            .into_iter()
            .flatten()
            .all(|f| (0..6).all(|k| f.p[(k, k)].is_finite()));
        att && pv
    }

    /// Health (mode from the filters' activity).
    pub fn health(&self) -> Health {
        let mut h = self.health;
        h.divergence_resets = self.divergence_resets;
        h.gnss_tilt = self.gnss_tilt.diag;
        h.yaw_resets = self.heading.resets;
        // This profile reads no compass: its heading is the course's (a fixed wing, once the
        // alignment settled it) or the yaw bank's.
        h.heading.source = if self.att.is_none() {
            HeadingSource::Unknown
        } else if self.course_heading && self.aligned {
            HeadingSource::Course
        } else if self.heading.state == BankState::Active {
            HeadingSource::YawEstimator
        } else {
            HeadingSource::Unknown
        };
        let t = self.imu.back().map(|s| s.t_ns).unwrap_or(0);
        let to = self.params.aid_timeout_ns;
        h.mode = match (&self.att, &self.gps_imu) {
            (Some(att), _) if !att.euler.iter().all(|v| v.is_finite()) => Mode::Diverged,
            (Some(_), None) if self.gnssless => Mode::AttitudeOnly,
            (Some(_), Some(gi)) if !gi.x.iter().all(|v| v.is_finite()) => Mode::Diverged,
            (Some(_), Some(_)) if h.gnss_pos.active(t, to) => Mode::Nominal,
            (Some(_), Some(_)) if self.vio2.is_some() && h.vision_trans.active(t, to) => {
                Mode::GnssDeniedVision
            }
            (Some(_), Some(_)) => Mode::InertialOnly,
            _ => Mode::Initialising,
        };
        if let Some(att) = &self.att {
            if let Some(pv) = self.vio2.as_ref().or(self.gps_imu.as_ref()) {
                for k in 0..6 {
                    h.cov_diag[k] = pv.p[(k, k)];
                }
            }
            for k in 0..3 {
                h.cov_diag[6 + k] = att.p[(k, k)];
            }
        }
        h
    }

    /// The pose without GNSS (`gnssless`): attitude only; the position fields are the frame's
    /// origin and are not reported ([`Mode::AttitudeOnly`]).
    fn output_attitude_only(&self, t_ns: i64, att: &AttitudeEkf, frame: &LocalFrame) -> PoseOutput {
        let h = self.health();
        let to = self.params.aid_timeout_ns;
        let sigma_att = reported_euler_sigma(att);
        // Not reported (the mode says so); kept finite, as every published number is: the
        // velocity is the one the tilt windows hold at zero, the position is unknown.
        let sigma_vel = Vector3::repeat(self.params.paper_noaid_speed_sigma_mps);
        let sigma_pos = Vector3::repeat(self.params.diverged_pos_sigma_m);
        PoseOutput {
            t_ns,
            lla: frame.ned_to_lla(&Vector3::zeros()),
            pos_ned_m: Vector3::zeros(),
            vel_ned_mps: Vector3::zeros(),
            nav_from_body: att.quaternion(),
            euler_rad: crate::output::canonical_euler(&att.euler),
            sigma_pos_ned_m: sigma_pos,
            sigma_vel_mps: sigma_vel,
            sigma_att_rad: sigma_att,
            gyro_bias_radps: self.gnss_tilt.gyro_bias_radps(),
            accel_bias_mps2: Vector3::zeros(),
            health: (&h).into(),
            aiding: AidingFlags {
                gnss_pos: false,
                gnss_vel: false,
                vision_rot: h.vision_rot.active(t_ns, to),
                vision_trans: false,
            },
        }
    }

    pub(super) fn output(&self, t_ns: i64) -> Option<PoseOutput> {
        if self.gnssless {
            let (Some(att), Some(frame)) = (self.att.as_ref(), self.frame.as_ref()) else {
                return None;
            };
            return Some(self.output_attitude_only(t_ns, att, frame));
        }
        let (Some(att), Some(gi), Some(frame)) = (
            self.att.as_ref(),
            self.gps_imu.as_ref(),
            self.frame.as_ref(),
        ) else {
            return None;
        };
        let pv = self.vio2.as_ref().unwrap_or(gi);
        let mut pos_cov = pv.p.fixed_view::<3, 3>(0, 0).into_owned();
        if self.vio2.is_none() {
            // GPS-IMU averages the fixes as white: what it states includes their correlated
            // part, which no averaging removes (see `gnss_correlated_var`).
            for k in 0..3 {
                pos_cov[(k, k)] = pos_cov[(k, k)].max(self.gnss_correlated_var[k]);
            }
        }
        let h = self.health();
        let to = self.params.aid_timeout_ns;
        let sd = |m: &Matrix3<f64>| m.diagonal().map(|v| v.max(0.0).sqrt());
        let mut sigma_att = reported_euler_sigma(att);
        if !att.video_active() {
            sigma_att.z = sigma_att.z.max(self.heading.reported_sigma_floor_rad());
        }
        sigma_att.z = sigma_att
            .z
            .hypot(self.params.gyro_scale_sigma * self.unaided_turn_rad);
        Some(PoseOutput {
            t_ns,
            lla: frame.ned_to_lla(&pv.x),
            pos_ned_m: pv.x,
            vel_ned_mps: pv.v,
            nav_from_body: att.quaternion(),
            euler_rad: crate::output::canonical_euler(&att.euler),
            sigma_pos_ned_m: sd(&pos_cov),
            sigma_vel_mps: sd(&pv.p.fixed_view::<3, 3>(3, 3).into_owned()),
            sigma_att_rad: sigma_att,
            gyro_bias_radps: self.gnss_tilt.gyro_bias_radps(),
            accel_bias_mps2: Vector3::zeros(),
            health: (&h).into(),
            aiding: AidingFlags {
                gnss_pos: h.gnss_pos.active(t_ns, to),
                gnss_vel: h.gnss_vel.active(t_ns, to),
                vision_rot: h.vision_rot.active(t_ns, to),
                vision_trans: h.vision_trans.active(t_ns, to),
            },
        })
    }
}

/// The Euler angles' σ as reported: at most that of an angle uniform round the circle
/// (`UNALIGNED_YAW_SIGMA_RAD`, 104°). Near ±90° of pitch the roll and yaw of an Euler-angle
/// filter lose their meaning and its covariance grows without bound (10⁸ ° on a tumbling
/// survey copter without GNSS); beyond that cap the angle is simply unknown.
fn reported_euler_sigma(att: &AttitudeEkf) -> Vector3<f64> {
    att.p_euler()
        .diagonal()
        .map(|v| v.max(0.0).sqrt().min(crate::init::UNALIGNED_YAW_SIGMA_RAD))
}
