//! What the error-state filter reports: mode, health, the pose output at every IMU sample and
//! the motion prior handed to the vision front end.

use nalgebra::{Matrix3, Vector3};
use uavnav_core::MotionPrior;

use super::Eskf;
use crate::aid_sources::InnovDiag;
use crate::aid_sources::mag_calibration::CalibrationState;
use crate::aid_sources::mag_heading::{MagHeadingSource, MagState};
use crate::health::{
    HeadingHealth, Health, MagCalibrationStatus, MagStatus, Mode, PoseHealth, SourceSummary,
};
use crate::output::{AidingFlags, PoseOutput, euler_sigma_at};
use crate::state::{IP, ITH, IV, N};

impl Eskf {
    /// The current mode.
    pub fn mode(&self) -> Mode {
        let Some(x) = self.x.as_ref() else {
            return Mode::Initialising;
        };
        let pos_var = self.p[(IP, IP)] + self.p[(IP + 1, IP + 1)];
        if !x.is_finite()
            || !pos_var.is_finite()
            || pos_var.sqrt() > self.params.diverged_pos_sigma_m
        {
            return Mode::Diverged;
        }
        let to = self.params.aid_timeout_ns;
        self.gnssless_mode(if self.gnss_pos.diag.active(x.t_ns, to) {
            Mode::Nominal
        } else if self.vision.trans.active(x.t_ns, to) || self.vision.rot.active(x.t_ns, to) {
            Mode::GnssDeniedVision
        } else {
            Mode::InertialOnly
        })
    }

    /// Whether the error covariance's diagonal is finite (a NaN variance would be reported as a
    /// σ of 0: `NaN.max(0.0)` is 0).
    pub fn covariance_finite(&self) -> bool {
        (0..N).all(|k| self.p[(k, k)].is_finite())
    }

    /// Health at the current horizon.
    pub fn health(&self) -> Health {
        let mut cov_diag = [0.0; N];
        for (k, c) in cov_diag.iter_mut().enumerate() {
            *c = self.p[(k, k)];
        }
        Health {
            mode: self.mode(),
            gnss_pos: self.gnss_pos.diag,
            gnss_vel: self.gnss_vel.diag,
            vision_rot: self.vision.rot,
            vision_trans: self.vision.trans,
            mag: self.mag.diag,
            baro: self.baro.diag,
            gnss_tilt: InnovDiag::new(),
            position_hold: self.hold.diag,
            yaw_resets: self.yaw_resets,
            heading: self.heading_health(),
            divergence_resets: 0,
            inputs_rejected: 0,
            imu_gaps_bridged: 0,
            late_dropped: self.late_dropped,
            vision_no_clone: self.vision.no_clone,
            gnss_resets: self.gnss_pos.resets + self.gnss_vel.resets,
            imu_clipped: self.imu_clipped,
            imu_noise_ratio: self.imu_noise_ratio,
            gnss_velocity_delay_s: Some(self.gnss_delay.diag().delay_s),
            cov_diag,
        }
    }

    /// The heading's source and the compass's state.
    fn heading_health(&self) -> HeadingHealth {
        let MagHeadingSource {
            state,
            disturbed,
            contradicted,
            ..
        } = &self.mag;
        let mag = match state {
            MagState::Off => MagStatus::Off,
            MagState::Active => MagStatus::Active,
            MagState::Stopped if *contradicted => MagStatus::StoppedContradicted,
            MagState::Stopped => MagStatus::StoppedDead,
        };
        let mag_calibration = match self.mag_cal.state {
            CalibrationState::Off => MagCalibrationStatus::Off,
            CalibrationState::Learning => MagCalibrationStatus::Learning,
            CalibrationState::Applied => MagCalibrationStatus::Applied,
        };
        HeadingHealth {
            source: self.heading,
            mag,
            mag_disturbed: *disturbed,
            mag_calibration,
            mag_offset_t: self.mag_cal.bias().0.into(),
            mag_calibration_test_ratio: self.mag_cal.diag.test_ratio,
            mag_calibration_restarts: self.mag_cal.resets,
        }
    }

    /// [`Eskf::health`]'s summary, built without the full snapshot (this runs for every output).
    fn pose_health(&self) -> PoseHealth {
        PoseHealth {
            mode: self.mode(),
            gnss_pos: (&self.gnss_pos.diag).into(),
            gnss_vel: (&self.gnss_vel.diag).into(),
            vision_rot: (&self.vision.rot).into(),
            vision_trans: (&self.vision.trans).into(),
            mag: (&self.mag.diag).into(),
            baro: (&self.baro.diag).into(),
            gnss_tilt: SourceSummary::default(),
            position_hold: (&self.hold.diag).into(),
            inputs_rejected: 0,
            late_dropped: self.late_dropped,
            vision_no_clone: self.vision.no_clone,
            gnss_resets: self.gnss_pos.resets + self.gnss_vel.resets,
        }
    }

    pub(super) fn output(&mut self) -> Option<PoseOutput> {
        let frame = *self.frame.as_ref()?;
        let p_out = self.out.x.as_ref()?.p;
        let lla = self
            .lla
            .get_or_insert_with(|| crate::output::LlaLinearizer::new(frame, &p_out))
            .lla(&p_out);
        let o = self.out.x.as_ref()?;
        let x = self.x.as_ref()?;
        let to = self.params.aid_timeout_ns;
        let d = |i: usize| {
            Vector3::new(
                self.p[(i, i)],
                self.p[(i + 1, i + 1)],
                self.p[(i + 2, i + 2)],
            )
            .map(|v| v.max(0.0).sqrt())
        };
        let mut cov_th: Matrix3<f64> = self.p.fixed_view::<3, 3>(ITH, ITH).into_owned();
        cov_th[(2, 2)] = cov_th[(2, 2)].max(self.reported_yaw_floor_rad().powi(2))
            + self.unaided_turn_sigma_rad().powi(2);
        let (r, p_, y) = o.q.euler_angles();
        let euler_rad = Vector3::new(r, p_, y);
        Some(PoseOutput {
            t_ns: o.t_ns,
            lla,
            pos_ned_m: o.p,
            vel_ned_mps: o.v,
            nav_from_body: o.q,
            euler_rad,
            sigma_pos_ned_m: d(IP),
            sigma_vel_mps: d(IV),
            sigma_att_rad: euler_sigma_at(&euler_rad, &cov_th),
            gyro_bias_radps: x.bg,
            accel_bias_mps2: x.ba,
            health: self.pose_health(),
            aiding: AidingFlags {
                gnss_pos: self.gnss_pos.diag.active(x.t_ns, to),
                gnss_vel: self.gnss_vel.diag.active(x.t_ns, to),
                vision_rot: self.vision.rot.active(x.t_ns, to),
                vision_trans: self.vision.trans.active(x.t_ns, to),
            },
        })
    }

    /// Before alignment there is no attitude (no ground plane, no velocity) but the relative
    /// rotation still follows from the raw gyros with the bias taken as zero at its initial σ.
    /// Without it the front end falls back to an unaided essential matrix, which over flat ground
    /// (a planar scene) can return a confident wrong rotation.
    fn uninitialised_prior(&self, t0_ns: i64, t1_ns: i64) -> MotionPrior {
        let Some(bfc) = self.body_from_cam else {
            return MotionPrior::default();
        };
        let Some(b0_from_b1) =
            crate::motion_prior::gyro_rotation(&self.imu, t0_ns, t1_ns, &Vector3::zeros())
        else {
            return MotionPrior::default();
        };
        let dt_s = (t1_ns - t0_ns) as f64 * 1e-9;
        let r_bc = bfc.rotation;
        MotionPrior {
            cam1_from_cam0: Some(r_bc.inverse() * b0_from_b1.inverse() * r_bc),
            rot_sigma_rad: self.gyro_psd.sqrt() * dt_s.sqrt()
                + self.params.init_gyro_bias_sigma_radps * dt_s,
            ..MotionPrior::default()
        }
    }

    /// The prior for the vision front end between frame times `t0_ns < t1_ns` (see
    /// [`MotionPrior`]); fields are `None` where the filter cannot tell.
    pub fn motion_prior(&self, t0_ns: i64, t1_ns: i64, terrain_elevation_m: f64) -> MotionPrior {
        let (Some(bfc), Some(o), Some(frame)) =
            (self.body_from_cam, self.out.x.as_ref(), self.frame.as_ref())
        else {
            return self.uninitialised_prior(t0_ns, t1_ns);
        };
        let bias_sigma = self.p[(crate::state::IBG, crate::state::IBG)]
            .max(0.0)
            .sqrt();
        let now = crate::motion_prior::NowState {
            t_ns: o.t_ns,
            q: o.q,
            p: o.p,
            v: o.v,
            bg: o.bg,
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
            bias_sigma,
        )
    }
}
