//! The heading of the error-state filter: where it comes from (magnetometer, yaw-hypothesis bank,
//! course for a fixed wing), its alignment from unknown, the emergency reset from the bank, and
//! the magnetometer's fusion against the world magnetic model.

use nalgebra::Vector3;
use uavnav_core::magnetic::{MagneticField, MagneticModel, decimal_year};

use super::Eskf;
use crate::aid_sources::gnss_pos::GnssMeas;
use crate::aid_sources::mag_heading::{DEAD_FIELD_T, MagState, heading_from_field};
use crate::init::{set_yaw, yaw_from_course};
use crate::state::{ITH, IV, set_uncorrelated};

pub use uavnav_core::output::HeadingSource;

/// Smallest heading disagreement between the compass and the yaw bank that counts as a
/// contradiction, rad: below it the two agree as well as compasses do.
pub const MAG_CONTRADICTION_MIN_RAD: f64 = 0.79;

/// Time constant of the smoothed disagreement between the compass-held heading and the yaw
/// bank, s: long enough to average the bank's fix-to-fix noise, short against a compass error
/// that builds up over tens of seconds.
pub const MAG_CONFLICT_TAU_S: f64 = 5.0;

/// The compass/bank disagreement behind [`Eskf`]'s `compass_conflict_rad`: the part of the
/// disagreement `d` that the bank's own σ `σ_b` does not explain, `√max(0, d² − σ_b²)`, smoothed
/// over [`MAG_CONFLICT_TAU_S`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(super) struct CompassConflict {
    /// Time of the last update, ns, and the smoothed value, rad.
    last: Option<(i64, f64)>,
}

impl CompassConflict {
    /// Takes `(d, σ_b)` at `t_ns`, or `None` while the bank has not converged (the value is then
    /// held), and returns the smoothed unexplained disagreement, rad.
    pub(super) fn update(&mut self, t_ns: i64, seen: Option<(f64, f64)>) -> f64 {
        let Some((d, bank_sigma)) = seen else {
            return self.last.map_or(0.0, |(_, c)| c);
        };
        let excess = (d * d - bank_sigma * bank_sigma).max(0.0).sqrt();
        let c = match self.last {
            Some((t0, c0)) if t_ns > t0 => {
                let a = 1.0 - (-((t_ns - t0) as f64 * 1e-9) / MAG_CONFLICT_TAU_S).exp();
                c0 + (excess - c0) * a
            }
            Some((_, c0)) => c0,
            None => excess,
        };
        self.last = Some((t_ns, c));
        c
    }
}

/// UNIX time of 2000-01-01, ns: stamps before it are on another clock (time since boot), and the
/// date for the magnetic model is unknown.
const UNIX_2000_NS: i64 = 946_684_800_000_000_000;

impl Eskf {
    pub(super) fn feed_yaw_estimator(&mut self, m: &GnssMeas) {
        // The bank needs the horizontal velocity only (ground speed and course will do).
        if let Some(v) = m.vel_h_mps {
            self.yaw_est.fuse_velocity(m.t_ns, v, m.sigma_vel_mps);
        }
    }

    /// Aligns an unknown heading from the yaw estimator (or the course when allowed), and resets
    /// an estimator-aligned heading that GNSS velocity keeps contradicting.
    pub(super) fn manage_heading(&mut self, m: &GnssMeas) {
        let mag_active = self.mag_fusing();
        let gsf = self.yaw_est.converged_yaw();
        if !self.yaw_aligned {
            if let (Some((yaw, sigma)), Some(x)) = (gsf, self.x.as_mut()) {
                set_yaw(
                    x,
                    &mut self.p,
                    yaw,
                    // At least the bank's own threshold of a known heading: the bank's σ can be
                    // overconfident when it converges (11.8° off at a few degrees on the
                    // simulated multirotor), and a handed-over σ too small leaves GNSS too little
                    // gain to correct it (copter_218 without its compass: yaw RMSE 10.8° with a
                    // 5° floor, 9.9° with this one).
                    sigma.max(self.params.yaw_estimator.converged_sigma_rad),
                );
                self.yaw_aligned = true;
                self.heading = HeadingSource::YawEstimator;
                self.corrected = true;
                self.forget_horizontal_accel_bias();
                self.reset_velocity_to_gnss(m);
            } else if self.course_heading
                && let Some(v) = m.vel_ned_mps
                && v.xy().norm() >= self.params.init_min_speed_mps
                && let Some(x) = self.x.as_mut()
            {
                yaw_from_course(x, &mut self.p, &v, &self.params);
                self.yaw_aligned = true;
                self.heading = HeadingSource::Course;
                self.corrected = true;
                self.reset_velocity_to_gnss(m);
            }
            return;
        }
        if mag_active {
            self.check_mag_against_bank(m.t_ns, gsf);
        }
        let mag_active = self.mag_fusing();
        // Without a magnetometer the heading is seen only through the GNSS velocity while the
        // vehicle accelerates; the filter's yaw σ then shrinks on what its linear model believes,
        // and in long hovers it grows by the gyro noise alone, while a real heading also wanders
        // with the gyro's scale error over every yaw-in-place turn (copter_218 without its
        // compass: σ 3–4.5° while 10–16° from the autopilot's compass heading after 824° of
        // turning). The yaw bank sees the same data through nonlinear models, and its spread
        // widens when they stop telling the hypotheses apart: the output does not claim to know
        // the heading better. Only the reported σ is floored, not the filter's covariance: raised
        // there, it made every GNSS velocity of a hover a large heading correction, and the
        // velocity's errors turned the heading (copter_218 without its compass: 25–29° from the
        // autopilot's heading through a 45 s hover; yaw RMSE 11.4° against 10.8° now).
        self.yaw_sigma_floor_rad = if self.heading_seen_by_gnss_velocity_only() {
            self.yaw_est.honest_sigma_rad().unwrap_or(0.0)
        } else if mag_active {
            self.compass_conflict_rad(m.t_ns, gsf)
        } else {
            0.0
        };
        // Emergency reset: GNSS velocity rejected for a while and the yaw estimator confidently
        // elsewhere (a heading aligned on a wrong hypothesis, or lost in a manoeuvre).
        let rejected_for = if self.gnss_vel.diag.consecutive_rejects > 0 {
            m.t_ns - self.gnss_vel.diag.first_reject_t_ns
        } else {
            0
        };
        if mag_active || rejected_for < self.params.yaw_reset_timeout_ns {
            return;
        }
        if let Some(bank) = gsf
            && let Some((d, s)) = self.disagreement_with(bank)
            && d.abs() > 3.0 * s
        {
            self.reset_yaw_to(bank);
            self.reset_velocity_to_gnss(m);
        }
    }

    /// Whether the compass is active and has been fused.
    fn mag_fusing(&self) -> bool {
        self.mag.state == MagState::Active && self.mag.diag.fused > 0
    }

    /// Whether the main filter sees the heading only through the GNSS velocity, as the yaw bank
    /// does: no compass fused, the antenna on the IMU and no camera (a lever arm or a camera
    /// tells the main filter more than the bank knows).
    fn heading_seen_by_gnss_velocity_only(&self) -> bool {
        !self.mag_fusing() && self.lever_b.norm() < 0.05 && self.body_from_cam.is_none()
    }

    /// The error states GNSS must not correct now: the yaw, when nothing but the GNSS velocity
    /// sees the heading (no compass fused, no lever arm, no camera) and the vehicle has not
    /// accelerated enough for it to tell the heading ([`YawEstimator::heading_unobservable`]).
    /// Why: a hovering copter's GNSS velocity, whose errors the linear model reads as heading
    /// information, turned the heading the wrong way (copter_218 without its compass: +9° in 5 s
    /// of hover while the gyro turned −8°, both references following the gyro). The yaw is then
    /// held by the gyro until the vehicle manoeuvres. (Tried and dropped: also holding it
    /// whenever the accelerations tell the heading worse than the filter's own σ does. GNSS then
    /// stopped correcting the heading as it wandered with the gyro, 21.6° yaw RMSE against
    /// 10.8°.)
    ///
    /// Before the heading is aligned: the horizontal accelerometer bias. It is a body-frame
    /// quantity that only the unknown heading maps into the velocity, and the yaw, held
    /// uncorrelated while unknown, leaves the velocity's σ without the heading's share of the
    /// acceleration: the innovations that share explains went into the bias (σ 0.3 → 0.04 m/s²
    /// in 13 s on a simulated multirotor without a compass, with a 0.3 m/s² bias) and through it
    /// into the tilt (3.3° off at a σ of 0.55°). The bias is forgotten at the alignment anyway
    /// ([`Self::forget_horizontal_accel_bias`]); held, its uncertainty still weighs every update.
    /// That flight: tilt within 3σ over the whole flight 89.5 → 99.6 % (east axis).
    ///
    /// [`YawEstimator::heading_unobservable`]: crate::yaw_estimator::YawEstimator::heading_unobservable
    pub(super) fn heading_unobservable_states(&self) -> &'static [usize] {
        if !self.yaw_aligned {
            return &[crate::state::IBA, crate::state::IBA + 1];
        }
        if self.heading_seen_by_gnss_velocity_only() && self.yaw_est.heading_unobservable() {
            &[ITH + 2]
        } else {
            &[]
        }
    }

    /// The filter's yaw minus the bank's `(yaw, σ)` (wrapped), and the σ of that difference.
    fn disagreement_with(&self, (yaw, sigma): (f64, f64)) -> Option<(f64, f64)> {
        let (_, _, cur) = self.x.as_ref()?.q.euler_angles();
        let d = (yaw - cur + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        Some((d, (self.p[(ITH + 2, ITH + 2)] + sigma * sigma).sqrt()))
    }

    /// Resets the heading to the bank's `(yaw, σ)` (counted in `yaw_resets`).
    fn reset_yaw_to(&mut self, (yaw, sigma): (f64, f64)) {
        let Some(x) = self.x.as_mut() else { return };
        set_yaw(
            x,
            &mut self.p,
            yaw,
            sigma.max(self.params.init_yaw_sigma_rad * 0.5),
        );
        self.heading = HeadingSource::YawEstimator;
        self.yaw_resets += 1;
        self.corrected = true;
    }

    /// A compass can be consistently wrong — a bad calibration or mounting, a field bent by the
    /// airframe — while its direction and strength look plausible (on public ArduPilot copters its
    /// heading strays 40° from the autopilot's on one flight), and heading fusion then holds the
    /// filter confidently wrong. The yaw bank sees the heading independently, through the GNSS
    /// velocity: when it has converged and the two disagree beyond 3σ of their combined
    /// uncertainty (and by more than [`MAG_CONTRADICTION_MIN_RAD`]) for
    /// `mag_contradiction_timeout_ns` in a row, the compass is stopped for the flight and the
    /// heading taken from the bank (counted in `yaw_resets`, shown by the mag source's state).
    fn check_mag_against_bank(&mut self, t_ns: i64, gsf: Option<(f64, f64)>) {
        let Some((bank, (d, s))) = gsf.and_then(|b| Some((b, self.disagreement_with(b)?))) else {
            self.mag_contradicted_since_ns = None;
            return;
        };
        if d.abs() <= (3.0 * s).max(MAG_CONTRADICTION_MIN_RAD) {
            self.mag_contradicted_since_ns = None;
            return;
        }
        let since = *self.mag_contradicted_since_ns.get_or_insert(t_ns);
        if t_ns - since < self.params.mag_contradiction_timeout_ns {
            return;
        }
        self.mag.stop_contradicted();
        self.reset_yaw_to(bank);
        self.mag_contradicted_since_ns = None;
    }

    /// The least yaw σ a compass-held heading can claim while the converged yaw bank sees the
    /// heading elsewhere: their disagreement, smoothed over [`MAG_CONFLICT_TAU_S`] (held while
    /// the bank has not converged).
    ///
    /// Why: the compass's error is correlated over minutes (a calibration residual, motor
    /// currents), so heading fusion every half second shrinks the filter's yaw σ to ~2° while
    /// the compass can be 5–25° off; two independent sources of the heading that disagree by `d`
    /// mean that one of them is off by about that much, and the output cannot tell which. On
    /// public ArduPilot copters (the survey in the README) the compass-held heading drifted 10–36°
    /// from the autopilot's own compass heading for a minute with σ 1.6–2°, while the bank sat
    /// 8–20° from it. Only the reported σ is floored, as for a heading without a compass: the
    /// filter's own yaw σ shapes its gains, and the compass stays the heading source until the
    /// contradiction is gross (`check_mag_against_bank`).
    fn compass_conflict_rad(&mut self, t_ns: i64, gsf: Option<(f64, f64)>) -> f64 {
        let seen = gsf
            .and_then(|b| self.disagreement_with(b))
            .zip(self.yaw_est.honest_sigma_rad())
            .map(|((d, _), bank_sigma)| (d, bank_sigma));
        self.mag_bank_conflict.update(t_ns, seen)
    }

    /// After a heading alignment or reset: the velocity to the GNSS velocity, with the receiver's
    /// σ and no correlation with the other states (as PX4 does after a yaw reset from its bank).
    ///
    /// Why: the velocity was propagated with the wrong heading; on the simulated multirotor from a
    /// start 37° off, the forward acceleration before the alignment left it 0.8 m/s off, the GNSS
    /// velocity then stayed gated out for 2 s after the alignment, and when it got in, the
    /// linearised update read the 0.5 m/s left as 0.16 m/s² of accelerometer bias and a heading
    /// swinging −8° then +22° (truth 0.01 m/s², and the bank was right within 1°).
    fn reset_velocity_to_gnss(&mut self, m: &GnssMeas) {
        let Some(x) = self.x.as_mut() else { return };
        let (v, axes) = match (m.vel_ned_mps, m.vel_h_mps) {
            (Some(v), _) => (v, 3),
            (None, Some(vh)) => (Vector3::new(vh.x, vh.y, x.v.z), 2),
            (None, None) => return,
        };
        // The antenna's velocity: the lever-arm term C (ω × r) is left in and covered by the σ,
        // as a body rate of 0.1 rad/s times the lever arm; at least 0.1 m/s whatever the
        // receiver states (a missing or zero σ must not make the reset exact).
        let var = m
            .sigma_vel_mps
            .hypot(0.1 * self.lever_b.norm().min(10.0))
            .max(0.1)
            .powi(2);
        x.v = v;
        for i in IV..IV + axes {
            set_uncorrelated(&mut self.p, i, var);
        }
        self.corrected = true;
    }

    /// After a heading alignment late in a flight: what the filter learnt of the horizontal
    /// accelerometer bias under an unknown heading is not to be trusted (velocity errors from the
    /// wrong heading went partly into it); back to its initial σ, uncorrelated.
    ///
    /// The tilt was told apart from that bias by the same linearisation: only a yaw turn
    /// separates a tilt error `δθ` from a horizontal bias `δb` (level, `g δθ ≈ δb` in the
    /// specific force), and under an unknown heading the turn was seen with the wrong heading.
    /// So the tilt's variance gets back the bias's share, `σ_b² / g²` per axis (eq. A1, ours).
    /// Why: on a simulated multirotor without a compass and with a 0.3 m/s² turn-on accelerometer
    /// bias, the roll stayed 1–2.5° off for 20 s at a σ of 0.3–0.6° after the alignment.
    fn forget_horizontal_accel_bias(&mut self) {
        const G_MPS2: f64 = 9.80665;
        let s2 = self.params.init_accel_bias_sigma_mps2.powi(2);
        // Added, not set: the tilt keeps what the GNSS velocity told it, plus the ambiguity.
        for k in 0..2 {
            self.p[(ITH + k, ITH + k)] += s2 / (G_MPS2 * G_MPS2);
        }
        for k in 0..2 {
            set_uncorrelated(&mut self.p, crate::state::IBA + k, s2);
        }
        if let Some(x) = self.x.as_mut() {
            x.ba.x = 0.0;
            x.ba.y = 0.0;
        }
    }

    /// The model field for this flight, computed once at the origin and the data's date.
    fn model_field(&mut self, t_ns: i64) -> Option<(MagneticField, f64)> {
        if self.mag_field.is_none() {
            let origin = self.frame.as_ref()?.origin();
            let (year, extra) = if t_ns > UNIX_2000_NS {
                let y = decimal_year(t_ns);
                // Linear secular variation outside 2025–2030: ~0.15° of declination per year.
                (
                    y,
                    (0.15f64 * MagneticModel::years_outside_validity(y)).to_radians(),
                )
            } else {
                // Unknown date: mid-validity, with a few years' worth of declination change.
                (2027.5, 1f64.to_radians())
            };
            self.mag_field = Some((MagneticModel::field(&origin, year), extra));
        }
        self.mag_field
    }

    /// Feeds the compass calibration (eq. M2) with the raw sample and returns the sample with the
    /// learnt offset removed once it is applied, and the heading σ the offset adds, rad: once
    /// applied, its remaining uncertainty's (`∂α/∂b = −gᵀ C` with `g` the azimuth's gradient,
    /// eq. M1); known but not applied, the heading error it would make.
    fn calibrated_mag(&mut self, t_ns: i64, m_b: &Vector3<f64>) -> (Vector3<f64>, f64) {
        let Some(x) = self.x else {
            return (*m_b, 0.0);
        };
        if self.mag.state == MagState::Stopped || m_b.norm() < DEAD_FIELD_T {
            return (*m_b, 0.0);
        }
        let c = x.q.to_rotation_matrix().into_inner();
        let p_th = self.p.fixed_view::<3, 3>(ITH, ITH).into_owned();
        let model = if self.frame_provisional {
            None
        } else {
            self.model_field(t_ns)
                .map(|(f, _)| (f.inclination_rad(), f.strength_t()))
        };
        self.mag_cal.set_model(model);
        if self.mag_cal.update(t_ns, m_b, &c, &p_th, -x.p.z) {
            // The compass's typical field was learnt through the offset now removed.
            self.mag.relearn_typical();
        }
        // The azimuth's gradient with respect to a body-frame offset: `∂α/∂b = −gᵀ C`.
        let j_b = |m: &Vector3<f64>| {
            let m_n = c * m;
            let h2 = (m_n.x * m_n.x + m_n.y * m_n.y).max(1e-30);
            -(Vector3::new(-m_n.y, m_n.x, 0.0) / h2).transpose() * c
        };
        if let Some((b, p_b)) = self.mag_cal.applied() {
            let m = m_b - b;
            let j = j_b(&m);
            return (m, (j * p_b * j.transpose())[(0, 0)].max(0.0).sqrt());
        }
        // Known but not worth correcting: the heading error it would make widens the σ, so a
        // compass whose offset was judged too small to correct is not trusted beyond it.
        let extra = self
            .mag_cal
            .unapplied()
            .map_or(0.0, |b| (j_b(m_b) * b)[(0, 0)].abs());
        (*m_b, extra)
    }

    pub(super) fn fuse_mag(&mut self, t_ns: i64, m_b_raw: &Vector3<f64>) {
        let (m_b, cal_sigma) = self.calibrated_mag(t_ns, m_b_raw);
        let m_b = &m_b;
        let field = if self.frame_provisional {
            self.own_field(m_b)
        } else {
            self.model_field(t_ns)
        };
        let Some((field, extra)) = field else {
            return;
        };
        let Some(x) = self.x else { return };
        let sigma = self
            .params
            .mag_heading_sigma_rad
            .hypot(extra)
            .hypot(cal_sigma)
            .hypot(
                self.mag
                    .static_sigma_rad(&field, self.params.mag_max_inclination_error_rad),
            );
        if !self.yaw_aligned {
            if !self.mag.check_alive(m_b)
                || !self
                    .mag
                    .consistent(&x, m_b, &field, self.params.mag_max_inclination_error_rad)
            {
                self.mag.align_break();
                return;
            }
            let Some(implied) = heading_from_field(&x, m_b, field.declination_rad()) else {
                return;
            };
            if let (Some(yaw), Some(xm)) = (self.mag.align_with(implied), self.x.as_mut()) {
                set_yaw(xm, &mut self.p, yaw, sigma * 2.0);
                self.yaw_aligned = true;
                self.heading = HeadingSource::Magnetometer;
                self.corrected = true;
            }
            return;
        }
        let dx = self.mag.fuse(
            &x,
            &mut self.p,
            m_b,
            &field,
            sigma,
            self.params.mag_max_inclination_error_rad,
            self.params.gate_sigma,
            t_ns,
        );
        self.inject(dx);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: i64 = 1_000_000_000;

    #[test]
    fn the_conflict_is_what_the_bank_sigma_does_not_explain() {
        let deg = f64::to_radians;
        let mut c = CompassConflict::default();
        // Inside the bank's own σ: no conflict.
        assert_eq!(c.update(0, Some((deg(8.0), deg(10.0)))), 0.0);
        // 20° apart with the bank at 12°: √(20² − 12²) = 16°, reached over a few τ.
        let mut v = 0.0;
        for k in 1..=60 {
            v = c.update(k * S / 2, Some((deg(-20.0), deg(12.0))));
            if k == 10 {
                // After 5 s = τ: 1 − 1/e of the way.
                let want = deg(16.0) * (1.0 - (-1.0f64).exp());
                assert!((v - want).abs() < 1e-9, "{v} vs {want}");
            }
        }
        assert!((v - deg(16.0)).abs() < deg(0.1), "{}", v.to_degrees());
        // Held while the bank is unconverged, then decays once the two agree again.
        assert_eq!(c.update(31 * S, None), v);
        let later = c.update(41 * S, Some((0.0, deg(5.0))));
        assert!(later < v * 0.2 && later > 0.0, "{}", later.to_degrees());
        // A repeated or older stamp changes nothing.
        assert_eq!(c.update(41 * S, Some((deg(90.0), 0.0))), later);
    }
}
