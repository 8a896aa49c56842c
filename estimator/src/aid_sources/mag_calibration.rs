//! In-flight compass calibration: the compass's hard-iron offset in body axes and the local
//! field as the compass reads it, from the 3-axis field and the filter's tilt (eq. M2). The
//! heading source ([`super::mag_heading`]) subtracts the learnt offset once it is known well
//! enough (its σ moves the heading by less than
//! [`MagCalibrationParams::apply_heading_sigma_rad`]) and large enough to be worth it
//! ([`MagCalibrationParams::apply_min_heading_rad`]); a known offset below that widens the
//! compass heading's σ by the heading error it makes.
//!
//! Why a separate 5-state filter, and why these states. An uncalibrated compass (a new
//! airframe, a battery or a camera moved near it) reads the Earth's field plus a field fixed in
//! the body, `m_b = Cᵀ F + b + n`: a few µT of `b` against the 17 µT horizontal field a 0.7-scale
//! compass reads at mid latitudes turns the heading by up to 20° as the vehicle yaws (the
//! simulated multirotor with a 6–10 µT offset hovering after its manoeuvres: 26.7–100 % of
//! its yaw within 3σ with heading fusion alone, `estimator/tests/compass_calibration.rs`). The offset is what can be learnt; but fused against the filter's own heading
//! it is not: in a hover a heading error and a horizontal offset explain the same readings, and
//! the heading the compass itself set would teach the offset its own error. So the calibration
//! takes from the filter only what the compass cannot bias, the tilt: with `m_n = C (m_b − b)`,
//! the vertical field `m_n,D` and the horizontal field's strength `|m_n,NE|` do not depend on
//! the heading at all (a heading error turns `m_n` about the vertical). They must equal the
//! local field's vertical and horizontal strength, `F_D` and `F_H`, whatever the heading:
//!
//! **Eq. M2**: `r(b, F_D, F_H) = [ (C (m_b − b))_D − F_D ,  |(C (m_b − b))_NE| − F_H ] = 0 + v`,
//! states `s = [b (3, body, T), F_D, F_H (T)]`, `∂r/∂b = −[e_Dᵀ; uᵀ] C` with `u` the unit
//! horizontal direction of `m_n` (as a 3-vector), `∂r/∂(F_D, F_H) = −I₂`. A yaw turn makes a
//! body-horizontal offset swing the horizontal strength (the classic compass swing); a bank or
//! a pitch separates the vertical offset from `F_D`. The filter's tilt error `δθ` enters as
//! `∂r/∂δθ = −[e_Dᵀ; uᵀ] [m_n]×`, whose yaw column is zero (the heading invariance), and its
//! covariance is added to the measurement noise (considered, not estimated). `F_D` and `F_H`
//! are the compass's own field (its scale error included): the model's strength is not trusted
//! (real compasses read 0.6–0.8 of it), only its declination, by the heading source.
//!
//! Lifecycle:
//! * **off** until the vehicle flies ([`MagCalibrationParams::learn_min_height_m`] above its
//!   lowest height), the filter has a tilt within [`MagCalibrationParams::max_tilt_sigma_rad`]
//!   and the compass gives a usable sample (the heading source's dead-compass test stops it);
//! * **learning**: started from the first sample with `b = 0` and its prior σ, `F` from the
//!   sample (correlated with `b` as it must be); fused at most every
//!   [`MagCalibrationParams::min_interval_ns`] (consecutive compass errors are alike) and gated
//!   (χ², 2 dof): a motor-current spike or a steel structure is a rejected sample, with its test
//!   ratio in the diagnostics;
//! * **known** (still learning): the offset's σ moves the heading by less than the threshold
//!   (it takes a yaw swing); the heading source adds the heading error the offset makes to the
//!   compass's σ ([`MagCalibration::unapplied`]);
//! * **applied**: known, and turning the heading by more than the least worth correcting; the
//!   heading source then uses `m_b − b̂` and adds the offset's remaining σ;
//! * **reset** (restarted from the current sample, counted) after
//!   [`MagCalibrationParams::reset_after_rejections`] rejections in a row: the compass's
//!   surroundings changed for good (a payload swapped), and an offset that no longer explains
//!   the readings must not be applied.

use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, Vector2, Vector3};
use uavnav_core::rotation::skew;

use super::{InnovDiag, chi2_gate};

/// Tuning of the compass calibration (`EstimatorParams::mag_calibration`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MagCalibrationParams {
    /// Learn and apply the offset at all.
    pub enabled: bool,
    /// Prior 1-σ of each offset axis, T. 20 µT: an uncalibrated compass on a small airframe
    /// (a calibrated one is within 1 µT, which the prior covers as well).
    pub prior_bias_sigma_t: f64,
    /// 1-σ of one sample's error in each of the two residuals, T: the sensor's noise is far
    /// below it; motor currents and vibration are what a sample carries, and they are alike
    /// from sample to sample. With 1 µT the shared copter's offset was known to 0.3 µT a minute
    /// into its flight at 1.3 µT from where the rest of the flight put it; PX4 and ArduPilot
    /// fuse their 3-axis compasses with 5 µT.
    pub sample_sigma_t: f64,
    /// Random walk of the offset, T/√s (temperature, a current that changes slowly): 10 nT/√s is
    /// 0.08 µT in a minute, 0.6 µT in an hour.
    pub bias_walk_t_per_sqrt_s: f64,
    /// Random walk of the field's two strengths, T/√s (the vehicle travels; the sensor's scale
    /// drifts with temperature).
    pub field_walk_t_per_sqrt_s: f64,
    /// Shortest interval between two fused samples, ns.
    pub min_interval_ns: i64,
    /// The calibration learns only this far above the lowest height the filter has been at
    /// since it started, m: on the ground the compass reads the steel and the cables of the
    /// ground and the hangar, and motors spinning up (on the shared copter an offset learnt
    /// through its take-off was 3.5 µT off what the rest of its flight showed).
    pub learn_min_height_m: f64,
    /// The calibration learns only while the filter's roll and pitch σ are both below this, rad.
    pub max_tilt_sigma_rad: f64,
    /// The offset is applied once its horizontal σ over the horizontal field is below this, rad
    /// (the largest heading error it can still cause, 1σ).
    pub apply_heading_sigma_rad: f64,
    /// The offset is applied only when, less twice its σ, it turns the heading by at least
    /// this, rad (its body-horizontal part over the horizontal field); a smaller known offset
    /// widens the compass heading's σ instead. 15°: on the 16 public ArduPilot copters with a
    /// compass (`real_flights survey`) the learnt offsets turned the heading by at most 10°
    /// (3.1 µT on `15-12-2014/16`, 0.8 µT on the shared copter_218), and subtracting those moved
    /// the heading away from the autopilots' own (which fuse the same compass with bias states
    /// of their own): yaw within 3σ 100 → 90 % and 87.8 → 77.1 % on two of them with 5°, where
    /// widening left 98.1 and 88.2 %. What a residual of that size is (motor currents, a
    /// mounting tilt that reads as an offset when level, or an offset) the data cannot tell.
    pub apply_min_heading_rad: f64,
    /// Samples that must have been fused before the offset is applied.
    pub min_fused: u64,
    /// The learnt field's inclination must be within this of the world magnetic model's, rad,
    /// for the offset to be acted on. A real compass's direction matches the model (copter_218:
    /// 58.2° against 58.1°) while its strength does not; a hover that barely tilts cannot tell
    /// the vertical offset from the vertical field, and the pair then drifts together to a
    /// field of any inclination (on the public ArduPilot survey, −12° and 68° at a site whose model
    /// gives about 58°, with offsets of 34 and 88 µT). 15°: the compass copters there learnt 57.9–61.0°, and
    /// 71.3° on `14-11-2014/118`, whose compass sits 10° off its autopilot's heading.
    pub plausible_inclination_rad: f64,
    /// The learnt field's strength must be within these multiples of the model's (the shared
    /// compasses read 0.6–0.8 of it; one surveyed copter 1.8).
    pub plausible_strength_ratio: (f64, f64),
    /// Rejections in a row that restart the calibration.
    pub reset_after_rejections: u32,
}

impl Default for MagCalibrationParams {
    fn default() -> Self {
        Self {
            enabled: true,
            prior_bias_sigma_t: 2.0e-5,
            sample_sigma_t: 3.0e-6,
            bias_walk_t_per_sqrt_s: 1.0e-8,
            field_walk_t_per_sqrt_s: 1.0e-8,
            min_interval_ns: 200_000_000,
            learn_min_height_m: 3.0,
            max_tilt_sigma_rad: 3f64.to_radians(),
            apply_heading_sigma_rad: 3f64.to_radians(),
            apply_min_heading_rad: 15f64.to_radians(),
            min_fused: 50,
            reset_after_rejections: 25,
            plausible_inclination_rad: 15f64.to_radians(),
            plausible_strength_ratio: (0.25, 4.0),
        }
    }
}

/// State of the calibration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CalibrationState {
    /// Not started (no tilt yet, or no usable sample).
    #[default]
    Off,
    /// Learning; the offset is not applied yet.
    Learning,
    /// The offset is known well enough and is applied to the compass.
    Applied,
}

/// Calibration states: offset (body, T), vertical and horizontal field strength (T).
const NS: usize = 5;
type Cov5 = SMatrix<f64, NS, NS>;

/// The compass calibration (eq. M2).
#[derive(Debug, Clone, PartialEq)]
pub struct MagCalibration {
    params: MagCalibrationParams,
    /// Lifecycle state.
    pub state: CalibrationState,
    /// Diagnostics of the 2-dof residual (computed for every sample seen, fused or not).
    pub diag: InnovDiag,
    /// Restarts after a run of rejections or an implausible result ([`Self::plausible`]).
    pub resets: u32,
    /// Restarts because what was learnt was not a compass ([`Self::plausible`]).
    pub implausible_restarts: u32,
    s: SVector<f64, NS>,
    p: Cov5,
    last_t_ns: i64,
    /// Samples fused since the last (re)start.
    fused_since_start: u64,
    /// The world magnetic model's inclination (rad) and strength (T) where the vehicle is, when
    /// the filter knows where that is.
    model: Option<(f64, f64)>,
    /// The lowest height the filter has given, m (`+∞` before the first sample).
    lowest_height_m: f64,
}

/// Residual of eq. M2 and its Jacobians: `(r, ∂r/∂b, ∂r/∂δθ)` for the sample `m_b` (body, T),
/// attitude `c` (`nav_from_body`), offset `b` and field `(F_D, F_H)`. `None` when the sample has
/// no horizontal field to speak of (its direction `u` is undefined).
pub fn residual(
    c: &Matrix3<f64>,
    m_b: &Vector3<f64>,
    b: &Vector3<f64>,
    f_d: f64,
    f_h: f64,
) -> Option<(Vector2<f64>, SMatrix<f64, 2, 3>, SMatrix<f64, 2, 3>)> {
    let m_n = c * (m_b - b);
    let h = m_n.xy().norm();
    if h < 1e-9 {
        return None;
    }
    let mut g = SMatrix::<f64, 2, 3>::zeros();
    g[(0, 2)] = 1.0;
    g[(1, 0)] = m_n.x / h;
    g[(1, 1)] = m_n.y / h;
    let r = Vector2::new(m_n.z - f_d, h - f_h);
    Some((r, -g * c, -g * skew(&m_n)))
}

impl MagCalibration {
    /// A calibration that has seen nothing.
    pub fn new(params: MagCalibrationParams) -> Self {
        Self {
            params,
            state: CalibrationState::Off,
            diag: InnovDiag::new(),
            resets: 0,
            implausible_restarts: 0,
            s: SVector::zeros(),
            p: Cov5::zeros(),
            last_t_ns: i64::MIN,
            fused_since_start: 0,
            model: None,
            lowest_height_m: f64::INFINITY,
        }
    }

    /// The offset estimate (body, T) and its covariance.
    pub fn bias(&self) -> (Vector3<f64>, Matrix3<f64>) {
        (
            self.s.fixed_rows::<3>(0).into_owned(),
            self.p.fixed_view::<3, 3>(0, 0).into_owned(),
        )
    }

    /// The compass's own field: vertical and horizontal strength, T (zero while off).
    pub fn field_t(&self) -> (f64, f64) {
        (self.s[3], self.s[4])
    }

    /// Sets the world magnetic model's field where the vehicle is (`None` while the filter's
    /// place is provisional): what [`Self::plausible`] checks the learnt field against.
    pub fn set_model(&mut self, inclination_rad_strength_t: Option<(f64, f64)>) {
        self.model = inclination_rad_strength_t;
    }

    /// Whether the learnt offset and field describe a compass in the Earth's field: an offset no
    /// larger than the field it leaves and, with the model, no larger than the model's field,
    /// and a field whose inclination and strength agree with the model's
    /// ([`MagCalibrationParams::plausible_inclination_rad`],
    /// [`MagCalibrationParams::plausible_strength_ratio`]). An offset beyond the Earth's field
    /// is not something a compass that an autopilot calibrated keeps; such a result is the
    /// vertical offset and field drifting together, and applying it would turn the heading
    /// by anything.
    pub fn plausible(&self) -> bool {
        let prm = &self.params;
        let b = self.s.fixed_rows::<3>(0).norm();
        let (f_d, f_h) = (self.s[3], self.s[4]);
        let f = f_d.hypot(f_h);
        if f_h <= 0.0 || b > f {
            return false;
        }
        let Some((inclination_rad, strength_t)) = self.model else {
            return true;
        };
        let (lo, hi) = prm.plausible_strength_ratio;
        (f_d.atan2(f_h) - inclination_rad).abs() <= prm.plausible_inclination_rad
            && b <= strength_t
            && (lo * strength_t..=hi * strength_t).contains(&f)
    }

    /// The offset to subtract from the compass and its covariance, once applied.
    pub fn applied(&self) -> Option<(Vector3<f64>, Matrix3<f64>)> {
        (self.state == CalibrationState::Applied).then(|| self.bias())
    }

    /// Takes one usable sample `m_b` (body, T) at `t_ns` with the filter's attitude `c`, its
    /// attitude-error covariance `p_th` (global, rad²) and its height `height_m` (up, m, any
    /// datum); returns whether the calibration became
    /// applied with this sample (the caller then relearns what it learnt from uncorrected
    /// samples).
    pub fn update(
        &mut self,
        t_ns: i64,
        m_b: &Vector3<f64>,
        c: &Matrix3<f64>,
        p_th: &Matrix3<f64>,
        height_m: f64,
    ) -> bool {
        let prm = self.params;
        self.lowest_height_m = self.lowest_height_m.min(height_m);
        if !prm.enabled
            || p_th[(0, 0)].max(p_th[(1, 1)]).sqrt() > prm.max_tilt_sigma_rad
            || height_m - self.lowest_height_m < prm.learn_min_height_m
        {
            return false;
        }
        if self.state == CalibrationState::Off {
            return self.start(t_ns, m_b, c);
        }
        if t_ns - self.last_t_ns < prm.min_interval_ns {
            return false;
        }
        let dt_s = (t_ns - self.last_t_ns) as f64 * 1e-9;
        let b = self.s.fixed_rows::<3>(0).into_owned();
        let Some((r, j_b, j_th)) = residual(c, m_b, &b, self.s[3], self.s[4]) else {
            return false;
        };
        self.last_t_ns = t_ns;
        let qb = prm.bias_walk_t_per_sqrt_s.powi(2) * dt_s;
        let qf = prm.field_walk_t_per_sqrt_s.powi(2) * dt_s;
        for i in 0..3 {
            self.p[(i, i)] += qb;
        }
        self.p[(3, 3)] += qf;
        self.p[(4, 4)] += qf;
        let mut h = SMatrix::<f64, 2, NS>::zeros();
        h.fixed_view_mut::<2, 3>(0, 0).copy_from(&j_b);
        h[(0, 3)] = -1.0;
        h[(1, 4)] = -1.0;
        let rm = Matrix2::identity() * prm.sample_sigma_t.powi(2) + j_th * p_th * j_th.transpose();
        let pht = self.p * h.transpose();
        let s = h * pht + rm;
        let Some(s_inv) = s.try_inverse() else {
            return false;
        };
        let y = -r;
        let nis = (y.transpose() * s_inv * y)[(0, 0)];
        let d = &mut self.diag;
        d.innov = [y.x, y.y, 0.0];
        d.innov_var = [s[(0, 0)], s[(1, 1)], 0.0];
        d.test_ratio = nis / chi2_gate(2, 3.29);
        if d.test_ratio > 1.0 {
            d.rejected += 1;
            if d.consecutive_rejects == 0 {
                d.first_reject_t_ns = t_ns;
            }
            d.consecutive_rejects += 1;
            if d.consecutive_rejects >= prm.reset_after_rejections {
                self.resets += 1;
                return self.start(t_ns, m_b, c);
            }
            return false;
        }
        d.fused += 1;
        d.consecutive_rejects = 0;
        d.last_fused_t_ns = t_ns;
        self.fused_since_start += 1;
        let k = pht * s_inv;
        self.s += k * y;
        // Joseph form: the prior's 20 µT against 1 µT samples is a large first gain.
        let ikh = Cov5::identity() - k * h;
        self.p = ikh * self.p * ikh.transpose() + k * rm * k.transpose();
        self.p = (self.p + self.p.transpose()) * 0.5;
        if self.fused_since_start >= prm.min_fused && !self.plausible() {
            // Not a compass in the Earth's field: start again rather than act on it (the same
            // data may lead there again; it is then never applied, and never widens the σ).
            self.resets += 1;
            self.implausible_restarts += 1;
            return self.start(t_ns, m_b, c);
        }
        let was = self.state;
        if self.state == CalibrationState::Learning && self.ready() {
            self.state = CalibrationState::Applied;
        }
        was != self.state
    }

    /// Whether the offset is known well enough to act on: enough samples, and a horizontal σ
    /// that turns the heading by less than [`MagCalibrationParams::apply_heading_sigma_rad`].
    fn known(&self) -> bool {
        let f_h = self.s[4];
        if self.fused_since_start < self.params.min_fused || f_h <= 0.0 || !self.plausible() {
            return false;
        }
        let pbh = self.p.fixed_view::<2, 2>(0, 0);
        // Largest eigenvalue of the 2×2 horizontal block.
        let (a, d, bc) = (pbh[(0, 0)], pbh[(1, 1)], pbh[(0, 1)]);
        let lmax = 0.5 * (a + d) + (0.25 * (a - d).powi(2) + bc * bc).sqrt();
        lmax.sqrt() / f_h <= self.params.apply_heading_sigma_rad
    }

    /// Whether the offset is known and large enough to be worth applying: less twice its σ, it
    /// turns the heading by more than [`MagCalibrationParams::apply_min_heading_rad`]. Once
    /// applied it stays applied until a restart (a learnt offset that shrinks is still the best
    /// estimate).
    fn ready(&self) -> bool {
        if !self.known() {
            return false;
        }
        // At its lower 2σ bound along its own direction: an estimate that crosses the threshold
        // while still uncertain is not worth it (on the shared copter without GNSS, 1.7 µT ±
        // 0.6 µT one minute into the flight, 0.8 µT later).
        let pbh = self.p.fixed_view::<2, 2>(0, 0);
        let b_h = self.s.fixed_rows::<2>(0).into_owned();
        let offset_h = b_h.norm();
        let along = if offset_h > 0.0 {
            let u = b_h / offset_h;
            (u.transpose() * pbh * u)[(0, 0)].max(0.0).sqrt()
        } else {
            0.0
        };
        (offset_h - 2.0 * along) / self.s[4] >= self.params.apply_min_heading_rad
    }

    /// The offset learnt but not applied, once it is known ([`Self::known`]): too small to be
    /// worth correcting, it is still what the compass may be off by, and the heading source
    /// widens its σ by the heading error it would make.
    pub fn unapplied(&self) -> Option<Vector3<f64>> {
        (self.state == CalibrationState::Learning && self.known())
            .then(|| self.s.fixed_rows::<3>(0).into_owned())
    }

    /// (Re)starts from one sample: `b = 0` with its prior, the field read through it, with the
    /// correlation `F − F̂ = (∂r/∂b) b` that an unknown offset gives the first reading.
    fn start(&mut self, t_ns: i64, m_b: &Vector3<f64>, c: &Matrix3<f64>) -> bool {
        let Some((r0, j_b, _)) = residual(c, m_b, &Vector3::zeros(), 0.0, 0.0) else {
            return false;
        };
        let prm = self.params;
        let pbb = Matrix3::identity() * prm.prior_bias_sigma_t.powi(2);
        self.s = SVector::zeros();
        self.s[3] = r0.x;
        self.s[4] = r0.y;
        self.p = Cov5::zeros();
        self.p.fixed_view_mut::<3, 3>(0, 0).copy_from(&pbb);
        let pfb = j_b * pbb;
        self.p.fixed_view_mut::<2, 3>(3, 0).copy_from(&pfb);
        self.p
            .fixed_view_mut::<3, 2>(0, 3)
            .copy_from(&pfb.transpose());
        let pff = j_b * pbb * j_b.transpose() + Matrix2::identity() * prm.sample_sigma_t.powi(2);
        self.p.fixed_view_mut::<2, 2>(3, 3).copy_from(&pff);
        self.state = CalibrationState::Learning;
        self.last_t_ns = t_ns;
        self.fused_since_start = 0;
        self.diag.consecutive_rejects = 0;
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, UnitQuaternion};

    const S: i64 = 1_000_000_000;

    /// The field a 0.7-scale compass reads at mid latitudes: 17 µT north, 27 µT down.
    fn field() -> Vector3<f64> {
        Vector3::new(17e-6, 0.0, 27e-6)
    }

    fn att(roll_deg: f64, pitch_deg: f64, yaw_deg: f64) -> Matrix3<f64> {
        Rotation3::from_euler_angles(
            roll_deg.to_radians(),
            pitch_deg.to_radians(),
            yaw_deg.to_radians(),
        )
        .into_inner()
    }

    /// A deterministic pseudo-random sequence in [−1, 1].
    fn noise(k: usize) -> f64 {
        let x = ((k as f64 + 1.0) * 12.9898).sin() * 43_758.545_3;
        2.0 * (x - x.floor()) - 1.0
    }

    /// A swing: yaw round the circle at 10°/s with a roll and pitch of up to 15°.
    fn swing(k: usize) -> Matrix3<f64> {
        let t = k as f64 * 0.2;
        att(15.0 * (0.3 * t).sin(), 10.0 * (0.17 * t).cos(), 10.0 * t)
    }

    /// On the ground for the first second, then 10 m up.
    fn height(k: usize) -> f64 {
        if k < 5 { 0.0 } else { 10.0 }
    }

    fn reading(c: &Matrix3<f64>, b: &Vector3<f64>, k: usize) -> Vector3<f64> {
        c.transpose() * field()
            + b
            + Vector3::new(noise(3 * k), noise(3 * k + 1), noise(3 * k + 2)) * 1e-7
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let c = att(12.0, -7.0, 130.0);
        let m = c.transpose() * field() + Vector3::new(3e-6, -5e-6, 2e-6);
        let b = Vector3::new(1e-6, -2e-6, 0.5e-6);
        let (_, j_b, j_th) = residual(&c, &m, &b, 26e-6, 16e-6).unwrap();
        let eps = 1e-9;
        for i in 0..3 {
            let (mut bp, mut bm) = (b, b);
            bp[i] += eps;
            bm[i] -= eps;
            let (rp, _, _) = residual(&c, &m, &bp, 26e-6, 16e-6).unwrap();
            let (rm, _, _) = residual(&c, &m, &bm, 26e-6, 16e-6).unwrap();
            let num = (rp - rm) / (2.0 * eps);
            assert!(
                (num - j_b.column(i)).norm() < 1e-6,
                "b{i}: {num} vs {}",
                j_b.column(i)
            );
            // The global attitude error: C ← exp(δθ) C.
            let turned = |a: f64| {
                let mut d = Vector3::zeros();
                d[i] = a;
                let ca = UnitQuaternion::from_scaled_axis(d)
                    .to_rotation_matrix()
                    .into_inner()
                    * c;
                residual(&ca, &m, &b, 26e-6, 16e-6).unwrap().0
            };
            let num = (turned(1e-6) - turned(-1e-6)) / 2e-6;
            assert!(
                (num - j_th.column(i)).norm() < 1e-10,
                "th{i}: {num} vs {}",
                j_th.column(i)
            );
        }
        // The heading invariance: no yaw column.
        assert!(j_th.column(2).norm() < 1e-18, "{}", j_th.column(2));
    }

    #[test]
    fn a_swing_learns_the_offset_whatever_the_heading_error() {
        let b = Vector3::new(8e-6, -6e-6, 3e-6);
        let p_th = Matrix3::identity() * 1f64.to_radians().powi(2);
        let mut learnt = Vec::new();
        for heading_error_deg in [0.0, 25.0] {
            let mut cal = MagCalibration::new(MagCalibrationParams::default());
            let mut applied_at = None;
            for k in 0..300 {
                let c = swing(k);
                // The filter's attitude may be off in heading (the compass's own error): eq. M2
                // does not see it.
                let c_est = att(0.0, 0.0, heading_error_deg) * c;
                if cal.update(
                    k as i64 * S / 5,
                    &reading(&c, &b, k),
                    &c_est,
                    &p_th,
                    height(k),
                ) {
                    applied_at = Some(k);
                }
            }
            let (bh, pb) = cal.bias();
            for i in 0..3 {
                let sigma = pb[(i, i)].sqrt();
                assert!(
                    (bh[i] - b[i]).abs() < 3.0 * sigma.max(1e-8),
                    "{i}: {} vs {}, σ {sigma}",
                    bh[i],
                    b[i]
                );
                // The vertical offset is seen only through the roll and pitch, ±15° here.
                assert!(
                    sigma < if i < 2 { 0.6e-6 } else { 1.5e-6 },
                    "{i}: σ {sigma}"
                );
            }
            assert_eq!(cal.state, CalibrationState::Applied);
            assert!(applied_at.is_some_and(|k| k < 200), "{applied_at:?}");
            let (f_d, f_h) = cal.field_t();
            assert!(
                (f_d - 27e-6).abs() < 0.3e-6 && (f_h - 17e-6).abs() < 0.3e-6,
                "{f_d} {f_h}"
            );
            learnt.push(bh);
        }
        assert!((learnt[0] - learnt[1]).norm() < 1e-12, "{learnt:?}");
    }

    /// Feeds 300 samples of a swing with offset `b`; returns the calibration.
    fn swung(b: Vector3<f64>, model: Option<(f64, f64)>) -> MagCalibration {
        let p_th = Matrix3::identity() * 1f64.to_radians().powi(2);
        let mut cal = MagCalibration::new(MagCalibrationParams::default());
        cal.set_model(model);
        for k in 0..300 {
            let c = swing(k);
            cal.update(k as i64 * S / 5, &reading(&c, &b, k), &c, &p_th, height(k));
        }
        cal
    }

    #[test]
    fn only_a_compass_in_the_earths_field_is_corrected() {
        let b = Vector3::new(8e-6, -6e-6, 3e-6);
        let f = field();
        let inclination = f.z.atan2(f.x);
        // The model agrees in direction, not in strength (a compass reading 0.7 of it): applied.
        let cal = swung(b, Some((inclination, f.norm() / 0.7)));
        assert_eq!(cal.state, CalibrationState::Applied);
        assert!(cal.plausible());
        assert_eq!(cal.implausible_restarts, 0);
        // A model 40° steeper than what the compass reads: never acted on, started again.
        let cal = swung(b, Some((inclination + 40f64.to_radians(), f.norm())));
        assert_eq!(cal.state, CalibrationState::Learning);
        assert!(cal.applied().is_none() && cal.unapplied().is_none());
        assert!(
            cal.implausible_restarts >= 4,
            "{}",
            cal.implausible_restarts
        );
        // A strength 5× the model's: the same.
        let cal = swung(b, Some((inclination, f.norm() / 5.0)));
        assert!(cal.applied().is_none() && cal.unapplied().is_none());
        assert!(cal.implausible_restarts > 0);
        // Without a model, an offset larger than the field it leaves (47 µT against 32 µT) is
        // not a compass's either, though the swing determines it.
        let big = Vector3::new(30e-6, -30e-6, 20e-6);
        let cal = swung(big, None);
        assert!(cal.applied().is_none() && cal.unapplied().is_none());
        assert!(cal.implausible_restarts > 0);
        // …while a plausible one is learnt and applied without a model as before.
        let cal = swung(b, None);
        assert_eq!(cal.state, CalibrationState::Applied);
    }

    #[test]
    fn a_hover_at_one_heading_never_applies_an_offset() {
        let b = Vector3::new(8e-6, -6e-6, 3e-6);
        let p_th = Matrix3::identity() * 1f64.to_radians().powi(2);
        let mut cal = MagCalibration::new(MagCalibrationParams::default());
        for k in 0..600 {
            let c = att(noise(k), noise(k + 7), 40.0 + noise(k + 11));
            cal.update(k as i64 * S / 5, &reading(&c, &b, k), &c, &p_th, height(k));
        }
        assert_eq!(cal.state, CalibrationState::Learning);
        assert!(cal.applied().is_none());
    }

    #[test]
    fn no_tilt_no_learning_and_a_changed_compass_restarts() {
        let b = Vector3::new(8e-6, -6e-6, 3e-6);
        let mut cal = MagCalibration::new(MagCalibrationParams::default());
        // Roll and pitch unknown (10°): nothing starts.
        let wide = Matrix3::identity() * 10f64.to_radians().powi(2);
        cal.update(0, &reading(&swing(0), &b, 0), &swing(0), &wide, 0.0);
        cal.update(S, &reading(&swing(1), &b, 1), &swing(1), &wide, 10.0);
        assert_eq!(cal.state, CalibrationState::Off);
        // On the ground (or never above where it started): nothing starts either.
        let mut grounded = MagCalibration::new(MagCalibrationParams::default());
        for k in 0..300 {
            let p_th = Matrix3::identity() * 0.5f64.to_radians().powi(2);
            grounded.update(
                k as i64 * S / 5,
                &reading(&swing(k), &b, k),
                &swing(k),
                &p_th,
                2.0,
            );
        }
        assert_eq!(grounded.state, CalibrationState::Off);
        let p_th = Matrix3::identity() * 0.5f64.to_radians().powi(2);
        for k in 0..300 {
            cal.update(
                k as i64 * S / 5,
                &reading(&swing(k), &b, k),
                &swing(k),
                &p_th,
                10.0,
            );
        }
        assert_eq!(cal.state, CalibrationState::Applied);
        // A magnet mounted next to the compass: 15 µT more, for good.
        let b2 = b + Vector3::new(0.0, 15e-6, 0.0);
        let mut k = 300;
        while cal.resets == 0 && k < 400 {
            cal.update(
                k as i64 * S / 5,
                &reading(&swing(k), &b2, k),
                &swing(k),
                &p_th,
                10.0,
            );
            k += 1;
        }
        assert_eq!(cal.resets, 1, "no restart");
        assert_eq!(cal.state, CalibrationState::Learning);
        assert!(cal.applied().is_none());
        for k in k..k + 400 {
            cal.update(
                k as i64 * S / 5,
                &reading(&swing(k), &b2, k),
                &swing(k),
                &p_th,
                10.0,
            );
        }
        let (bh, _) = cal.bias();
        assert!((bh - b2).norm() < 0.5e-6, "{bh} vs {b2}");
    }
}
