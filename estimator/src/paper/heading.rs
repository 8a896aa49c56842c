//! Profile `paper`, OUR ADDITION (not in the paper; `EstimatorParams::paper_yaw_bank`): the heading
//! of a vehicle whose GNSS course is not its heading, from the yaw-hypothesis bank
//! ([`crate::yaw_estimator`], shared with `eskf`).
//!
//! The paper aligns the heading from the GNSS course (a fixed wing flies where it points). A
//! multirotor hovers and flies sideways and backwards, so this profile does not take its course
//! as the heading; before this source it had no heading at all for one (its yaw σ said so, a
//! heading uniform round the circle, and the shared real copter's yaw was 148° RMSE from the
//! autopilot's). The bank of heading hypotheses, fed by the IMU and the GNSS horizontal velocity,
//! tells the heading once the vehicle accelerates horizontally, in any direction of the body.
//!
//! Lifecycle:
//! - **off** with `paper_yaw_bank = false` or when the course gives the heading (a fixed wing,
//!   or `course_heading`);
//! - **starting** from the filters' start: the bank runs on every IMU interval (the gyro less
//!   the bias `gnss_tilt` has learnt) and every fix's horizontal velocity;
//! - **active** once the bank has converged (its σ below `yaw_estimator.converged_sigma_rad`,
//!   steadily): the attitude filter's yaw is set to the bank's, with the bank's σ (at least
//!   [`MIN_HANDOVER_SIGMA_RAD`]), and the yaw's cross-covariances are cleared; from then on the
//!   paper's filter carries the heading (gyro integration, the lever arm, and `gnss_tilt` once
//!   the yaw σ is small enough for it);
//! - **reset** when the converged bank and the filter disagree by more than 3σ of their combined
//!   uncertainty for [`CONTRADICTION_NS`] in a row, or, while the bank can tell the heading
//!   (its honest σ, [`YawEstimator::honest_sigma_rad`], below `converged_sigma_rad`: a hover
//!   cannot) without counting as converged (a long turn), by more than
//!   [`GROSS_CONTRADICTION_RAD`] for as long: the yaw is set to the bank's
//!   again, counted in the health's `yaw_resets`;
//! - back to **starting** with the filters at a restart (the divergence check), and at the end
//!   of a GNSS outage that lost the heading ([`BankHeading::restart_search`], from
//!   `paper::outage`): the bank keeps running, and hands its heading over as soon as it can
//!   tell it, converged or not (a long turn); counted in `yaw_resets`.
//!
//! The disagreement with the bank and its test ratio are computed at every fix while the bank
//! can tell the heading, whether or not anything is reset.
//!
//! Reported σ: while the heading is from the bank and no video chain runs, the output's yaw σ
//! is at least what the bank can honestly claim ([`YawEstimator::honest_sigma_rad`]): the
//! filter's own yaw σ shrinks on what its linear model believes while a hover leaves the heading
//! unobservable, as in `eskf`.

use super::attitude::AttitudeEkf;
use crate::yaw_estimator::{YawEstimator, YawEstimatorParams};

/// Least yaw σ handed over from the bank, rad: the bank's σ can be over-confident at the moment
/// it converges (its models take their specific-force noise as white), and a σ below
/// `gnss_tilt`'s limit for correcting the heading lets the GNSS acceleration refine it from there.
pub const MIN_HANDOVER_SIGMA_RAD: f64 = 0.087; // 5°

/// Smallest disagreement with a bank that can tell the heading but does not count as converged
/// (see `at_fix`) that resets the filter's heading, rad: beyond what the bank's fix-to-fix noise
/// and the filter's drift between resets explain (the compass-contradiction bound of `eskf`).
pub const GROSS_CONTRADICTION_RAD: f64 = 0.79; // 45°

/// How long a contradiction must last before the filter's heading is reset to the bank, ns: a
/// converged bank's beyond 3σ, or a gross one from a bank that can tell the heading without
/// counting as converged. Nothing else in this profile sees a multirotor's heading (its GPS-IMU
/// filter's velocity test ratio stays near 0 with the heading 60° off), so the bank's word is
/// not checked against the filter's own innovations as `eskf` checks it (`yaw_reset_timeout_ns`
/// of GNSS velocity rejected). A bank can converge, briefly and confidently, on a wrong hypothesis while
/// the vehicle takes off: on copter_218 it left a right hand-over for a heading 57° off at σ 6°
/// for 3.5 s, and with a 1 s wait the filter followed it and stayed 60–65° off for 30 s (yaw
/// RMSE 23.5° against the autopilot's, 14.7° with this wait). The gross contradiction had this
/// wait already.
pub const CONTRADICTION_NS: i64 = 5_000_000_000;

/// Where the heading source stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BankState {
    /// Not used (disabled, or the course gives the heading).
    #[default]
    Off,
    /// The bank runs; the filter's heading is still unknown.
    Starting,
    /// The filter's heading came from the bank.
    Active,
}

/// The bank and its hand-over to the attitude filter.
#[derive(Debug, Clone, PartialEq)]
pub struct BankHeading {
    bank: YawEstimator,
    /// Lifecycle state.
    pub state: BankState,
    /// Since when the converged bank has disagreed with the filter beyond 3σ, ns.
    contradicted_since_ns: Option<i64>,
    /// The last disagreement (filter − bank, rad) over 3σ of the combined uncertainty; computed
    /// at every fix while the bank can tell the heading (diagnostics).
    pub test_ratio: f64,
    /// Heading resets to the bank after the first alignment.
    pub resets: u32,
    /// Starting again after an outage lost the heading ([`Self::restart_search`]): a bank that
    /// can tell the heading hands it over without counting as converged.
    refinding: bool,
}

impl BankHeading {
    /// A source that starts with the filters when `enabled`.
    pub fn new(params: YawEstimatorParams, enabled: bool) -> Self {
        Self {
            bank: YawEstimator::new(params),
            state: if enabled {
                BankState::Starting
            } else {
                BankState::Off
            },
            contradicted_since_ns: None,
            test_ratio: 0.0,
            resets: 0,
            refinding: false,
        }
    }

    /// Back to the state of [`Self::new`] (the filters restarted).
    pub fn restart(&mut self) {
        let enabled = self.state != BankState::Off;
        *self = Self::new(*self.bank_params(), enabled);
    }

    /// Back to **starting**, the bank left running: the heading must be found again (see
    /// `paper::outage`); the next hand-over counts as a reset. Nothing happens while the
    /// source is off.
    pub fn restart_search(&mut self) {
        if self.state == BankState::Off {
            return;
        }
        self.state = BankState::Starting;
        self.contradicted_since_ns = None;
        self.refinding = true;
    }

    /// The bank itself (diagnostics).
    pub fn bank(&self) -> &YawEstimator {
        &self.bank
    }

    fn bank_params(&self) -> &YawEstimatorParams {
        self.bank.params()
    }

    /// One IMU interval: mean gyro (bias removed) and specific force, body frame.
    pub fn add_imu(
        &mut self,
        gyro: &nalgebra::Vector3<f64>,
        accel: &nalgebra::Vector3<f64>,
        dt_s: f64,
    ) {
        if self.state != BankState::Off {
            self.bank.predict(gyro, accel, dt_s);
        }
    }

    /// A fix's horizontal velocity (N, E, m/s, σ m/s): the bank's update, then the hand-over or
    /// the reset of the attitude filter's heading.
    pub fn at_fix(
        &mut self,
        t_ns: i64,
        vel_h_mps: nalgebra::Vector2<f64>,
        sigma_vel_mps: f64,
        att: &mut AttitudeEkf,
    ) {
        if self.state == BankState::Off {
            return;
        }
        self.bank.fuse_velocity(t_ns, vel_h_mps, sigma_vel_mps);
        if self.state == BankState::Starting {
            let found = self
                .bank
                .converged_yaw()
                .or_else(|| self.refinding.then(|| self.telling_yaw()).flatten());
            if let Some((yaw, sigma)) = found {
                att.set_yaw(yaw, sigma.max(MIN_HANDOVER_SIGMA_RAD));
                self.state = BankState::Active;
                self.test_ratio = 0.0;
                if std::mem::take(&mut self.refinding) {
                    self.resets += 1;
                }
            }
            return;
        }
        // After the hand-over: the converged bank (its heading holding still) resets the filter
        // on a 3σ disagreement lasting [`CONTRADICTION_NS`]. A vehicle in a long turn never holds
        // its heading still, so the bank never counts as converged there while it can tell the
        // heading (its honest σ small): a fixed wing of unknown airframe circling for minutes
        // drifted 50–120° from the bank, with σ 4–8°. Then only a gross contradiction resets,
        // [`GROSS_CONTRADICTION_RAD`] for as long: resetting on every 3σ
        // disagreement with an unsteady bank took a 10 Hz-IMU plane's roll and pitch from 5° to
        // 8–14° of RMSE.
        let converged = self.bank.converged_yaw();
        let Some((yaw, sigma)) = converged.or_else(|| self.telling_yaw()) else {
            self.contradicted_since_ns = None;
            return;
        };
        let d = uavnav_core::rotation::wrap_pi(att.euler.z - yaw);
        let s = (att.p[(2, 2)].max(0.0) + sigma * sigma).sqrt();
        self.test_ratio = d.abs() / (3.0 * s).max(1e-9);
        let bound = if converged.is_some() {
            3.0 * s
        } else {
            (3.0 * s).max(GROSS_CONTRADICTION_RAD)
        };
        if d.abs() <= bound {
            self.contradicted_since_ns = None;
            return;
        }
        let since = *self.contradicted_since_ns.get_or_insert(t_ns);
        if t_ns - since >= CONTRADICTION_NS {
            att.set_yaw(yaw, sigma.max(MIN_HANDOVER_SIGMA_RAD));
            self.resets += 1;
            self.contradicted_since_ns = None;
        }
    }

    /// The bank's heading and honest σ while it can tell the heading (that σ below
    /// `converged_sigma_rad`), converged or not (a long turn).
    fn telling_yaw(&self) -> Option<(f64, f64)> {
        match (self.bank.yaw(), self.bank.honest_sigma_rad()) {
            (Some((yaw, _)), Some(s)) if s < self.bank_params().converged_sigma_rad => {
                Some((yaw, s))
            }
            _ => None,
        }
    }

    /// The least yaw σ the output may state, rad: what the bank can honestly claim while the
    /// heading is from it (0 otherwise).
    pub fn reported_sigma_floor_rad(&self) -> f64 {
        if self.state == BankState::Active {
            self.bank.honest_sigma_rad().unwrap_or(0.0)
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector2, Vector3};
    use uavnav_core::rotation::wrap_pi;

    /// Flies a vehicle of heading `yaw0` sideways and back (body accelerations along y only) for
    /// `n` 10 ms steps from step `k0`, feeding `src` and `att` as the paper filter does.
    fn fly(
        src: &mut BankHeading,
        att: &mut AttitudeEkf,
        yaw0: f64,
        v: &mut Vector2<f64>,
        k0: i64,
        n: i64,
    ) {
        let dt = 0.01;
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw0);
        for k in k0..k0 + n {
            let t = k as f64 * dt;
            let a_b = Vector3::new(0.0, 1.5 * (std::f64::consts::TAU * t / 8.0).sin(), 0.0);
            let a_n = q.transform_vector(&a_b);
            *v += Vector2::new(a_n.x, a_n.y) * dt;
            let f_b = a_b - q.inverse_transform_vector(&Vector3::new(0.0, 0.0, 9.80665));
            src.add_imu(&Vector3::zeros(), &f_b, dt);
            if k % 20 == 0 {
                src.at_fix(k * 10_000_000, *v, 0.2, att);
            }
        }
    }

    #[test]
    fn a_heading_lost_in_an_outage_is_handed_over_again() {
        let yaw0 = 1.0;
        let mut src = BankHeading::new(YawEstimatorParams::default(), true);
        let mut att = AttitudeEkf::new(Vector3::zeros(), Vector3::repeat(0.5), 0);
        let mut v = Vector2::zeros();
        fly(&mut src, &mut att, yaw0, &mut v, 0, 6000);
        assert_eq!(src.state, BankState::Active);
        assert!(wrap_pi(att.euler.z - yaw0).abs() < 5f64.to_radians());
        // An outage left the heading 100° off with a σ of 60°: within 3σ of the bank, so the
        // contradiction test never fires.
        att.set_yaw(yaw0 + 100f64.to_radians(), 60f64.to_radians());
        fly(&mut src, &mut att, yaw0, &mut v, 6000, 200);
        assert!(wrap_pi(att.euler.z - yaw0).abs() > 90f64.to_radians());
        assert_eq!(src.resets, 0);
        // Declared lost: the next fix hands the bank's heading over.
        src.restart_search();
        assert_eq!(src.state, BankState::Starting);
        fly(&mut src, &mut att, yaw0, &mut v, 6200, 21);
        assert_eq!(src.state, BankState::Active);
        assert!(wrap_pi(att.euler.z - yaw0).abs() < 5f64.to_radians());
        assert_eq!(src.resets, 1);
    }

    #[test]
    fn a_converged_bank_resets_the_heading_only_after_a_lasting_contradiction() {
        let yaw0 = -0.5;
        let mut src = BankHeading::new(YawEstimatorParams::default(), true);
        let mut att = AttitudeEkf::new(Vector3::zeros(), Vector3::repeat(0.5), 0);
        let mut v = Vector2::zeros();
        fly(&mut src, &mut att, yaw0, &mut v, 0, 6000);
        assert_eq!(src.state, BankState::Active);
        assert!(src.bank().converged_yaw().is_some());
        // The filter's heading 60° off at σ 2°: far beyond 3σ of the converged bank.
        att.set_yaw(yaw0 + 60f64.to_radians(), 2f64.to_radians());
        // 4 s of contradiction: not yet (a bank can be confidently wrong that long).
        fly(&mut src, &mut att, yaw0, &mut v, 6000, 400);
        assert_eq!(src.resets, 0);
        assert!(src.test_ratio > 1.0);
        assert!(wrap_pi(att.euler.z - yaw0).abs() > 50f64.to_radians());
        // Past `CONTRADICTION_NS`: reset to the bank, counted.
        fly(&mut src, &mut att, yaw0, &mut v, 6400, 200);
        assert_eq!(src.resets, 1);
        assert!(wrap_pi(att.euler.z - yaw0).abs() < 5f64.to_radians());
    }

    #[test]
    fn an_unused_source_stays_off() {
        let mut src = BankHeading::new(YawEstimatorParams::default(), false);
        src.restart_search();
        assert_eq!((src.state, src.resets), (BankState::Off, 0));
    }
}
