//! Heading without a magnetometer and without assuming heading = course: a Gaussian sum of small
//! yaw filters fed by the IMU and the GNSS velocity (the idea of PX4's EKF-GSF yaw estimator,
//! derived and written here).
//!
//! Each of [`N_MODELS`] hypotheses starts at a different heading round the circle and owns
//! * an attitude `nav_from_body` propagated with the gyros, its tilt corrected towards the
//!   measured specific force minus the kinematic acceleration from the GNSS velocity (rotated into
//!   the body with the hypothesis' own heading, so a turning or accelerating vehicle does not
//!   tilt the hypothesis that is right);
//! * a 3-state EKF `x = [v_N, v_E, ψ]`: the horizontal specific force rotated with the
//!   hypothesis' attitude integrates the velocity,
//!   `v̇_h = Rz(ψ) a_l` (`a_l` the level-frame horizontal specific force), so
//!   `∂v̇_h/∂ψ = [−a_E, a_N]` in NED; the GNSS horizontal velocity updates it.
//!
//! Each GNSS velocity weighs the hypotheses by their innovation likelihood
//! `N(y; 0, S) = exp(−½ yᵀS⁻¹y) / (2π √det S)`. When the vehicle accelerates horizontally (hover
//! corrections, turns, sideways or backward flight alike) the wrong headings predict the wrong
//! velocity change and lose weight; in constant-velocity flight nothing distinguishes them and
//! the composite σ stays wide, so the main filter is never told a heading it does not have. The
//! composite heading is the weighted circular mean, its variance the weighted spread plus the
//! weighted model variances. Pure and allocation-free: ~5 quaternion and 3×3 updates per IMU
//! sample, or per `predict_period_s` (10 ms) for faster IMUs.

use std::f64::consts::{PI, TAU};

use nalgebra::{Matrix2, Matrix3, UnitQuaternion, Vector2, Vector3};

/// Number of heading hypotheses (72° apart: each EKF's linearisation covers ±36°).
pub const N_MODELS: usize = 5;

/// Longest gap between GNSS velocities across which the models' predicted velocities still say
/// something about their headings, s. Over a longer gap each model's velocity integrates its own
/// tilt error and the vibration (a 2° tilt error is 2.3 m/s after 6.6 s, the random walk of
/// `accel_sigma_mps2` only 0.4 m/s): every innovation is then huge and the likelihoods crown a
/// model by chance, with a small σ (a real copter whose log lost GNSS for 4–7 s at a time was
/// aligned 150° wrong at σ 5° that way). After such a gap the velocities are re-anchored on the
/// fix and the weights left as they were.
pub const MAX_VEL_GAP_S: f64 = 2.0;

/// Tuning of the yaw estimator, with documented defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YawEstimatorParams {
    /// Horizontal specific-force noise of each model, m/s²: vibration, tilt error and the
    /// neglected accelerometer bias; generous, since an over-confident model bank locks onto a
    /// wrong heading.
    pub accel_sigma_mps2: f64,
    /// Yaw-rate noise, rad/s (gyro noise and bias).
    pub yaw_rate_sigma_radps: f64,
    /// Floor of the GNSS velocity σ used in the update, m/s.
    pub min_vel_sigma_mps: f64,
    /// Tilt-correction gain of each model's attitude, rad/s per unit error.
    pub tilt_gain: f64,
    /// Composite yaw σ below which the heading counts as known, rad.
    pub converged_sigma_rad: f64,
    /// ... and for how long it must have stayed below it, with the composite heading moving less
    /// than that σ, ns: at the first acceleration one hypothesis can win before its own yaw has
    /// settled (a 45° error with a 1° σ was seen on the simulated multirotor).
    pub converged_hold_ns: i64,
    /// 1-σ of the horizontal specific-force error that persists over many GNSS intervals, m/s²:
    /// a tilt error (1° is 0.17 m/s²), the accelerometer bias, vibration rectification. The models
    /// treat their specific-force noise as white, so their yaw σ shrinks as updates accumulate;
    /// a persistent error of `b` against horizontal accelerations of RMS `a` turns the heading by
    /// up to `atan(b / a)` whatever the number of updates (see
    /// [`YawEstimator::observability_sigma_rad`]).
    pub persistent_accel_sigma_mps2: f64,
    /// Time constant of the RMS horizontal acceleration behind that bound, s.
    pub accel_rms_window_s: f64,
    /// Shortest span of GNSS velocities whose change gives one sample of the kinematic view of
    /// that acceleration, s: long enough that the fixes' velocity noise (0.1–0.3 m/s steps from
    /// one fix to the next on hobby receivers, 0.5–1.5 m/s² over 0.2 s) differenced over it stays
    /// below the accelerations that tell a heading.
    pub accel_rms_span_s: f64,
    /// Shortest interval over which the models are propagated, s: faster IMU samples are summed
    /// (delta angle, delta velocity) until it is reached. The bank's dynamics are the heading and
    /// the horizontal velocity, slow against 10 ms; propagating it at a 1 kHz IMU's rate would
    /// cost ten times as much for nothing (PX4 runs its bank at the filter's 100 Hz the same way).
    pub predict_period_s: f64,
}

impl Default for YawEstimatorParams {
    fn default() -> Self {
        Self {
            accel_sigma_mps2: 1.0,
            yaw_rate_sigma_radps: 0.03,
            min_vel_sigma_mps: 0.3,
            tilt_gain: 0.2,
            converged_sigma_rad: 15f64.to_radians(),
            converged_hold_ns: 2_000_000_000,
            persistent_accel_sigma_mps2: 0.1,
            accel_rms_window_s: 10.0,
            accel_rms_span_s: 1.0,
            predict_period_s: 0.01,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Model {
    q: UnitQuaternion<f64>,
    v: Vector2<f64>,
    yaw: f64,
    p: Matrix3<f64>,
    weight: f64,
}

/// The bank of yaw hypotheses.
#[derive(Debug, Clone, PartialEq)]
pub struct YawEstimator {
    params: YawEstimatorParams,
    models: [Model; N_MODELS],
    /// Tilt from averaged specific force before the first GNSS velocity.
    f_mean: Vector3<f64>,
    f_count: u32,
    started: bool,
    last_vel: Option<(i64, Vector2<f64>)>,
    /// Kinematic horizontal acceleration from consecutive GNSS velocities (NED), low-passed.
    accel_kin: Vector2<f64>,
    /// Horizontal specific-force energy integrated since start: how much the vehicle has
    /// manoeuvred (diagnostics).
    pub manoeuvre_mps2s: f64,
    /// Since when (time, heading) the composite σ has stayed below the threshold with the heading
    /// steady.
    steady_since: Option<(i64, f64)>,
    last_t_ns: i64,
    /// Horizontal specific force (NED, leading model) integrated since the last GNSS velocity,
    /// m/s, and the time it covers, s.
    f_h_int: (Vector2<f64>, f64),
    /// Low-passed mean square of the horizontal specific force (leading model) over GNSS
    /// intervals, m²/s⁴.
    accel_ms: Option<f64>,
    /// Low-passed mean square of the horizontal acceleration the GNSS velocity shows over spans
    /// of at least `accel_rms_span_s`, m²/s⁴, and the fix that starts the current span.
    kin_ms: Option<f64>,
    kin_anchor: Option<(i64, Vector2<f64>)>,
    /// The model with the largest weight (weights change only at GNSS velocities).
    lead: usize,
    /// IMU intervals summed but not yet propagated (`predict_period_s`): gyro · dt (rad),
    /// specific force · dt (m/s), dt (s).
    pending: (Vector3<f64>, Vector3<f64>, f64),
}

impl Default for YawEstimator {
    fn default() -> Self {
        Self::new(YawEstimatorParams::default())
    }
}

/// The ZYX yaw of `nav_from_body` (atan2 of the rotated body x axis), without the other angles.
fn yaw_of(q: &UnitQuaternion<f64>) -> f64 {
    let (w, x, y, z) = (q.w, q.i, q.j, q.k);
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

fn wrap_pi(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

impl YawEstimator {
    /// An idle bank; it starts at the first GNSS velocity after some IMU samples.
    pub fn new(params: YawEstimatorParams) -> Self {
        let m = Model {
            q: UnitQuaternion::identity(),
            v: Vector2::zeros(),
            yaw: 0.0,
            p: Matrix3::zeros(),
            weight: 1.0 / N_MODELS as f64,
        };
        Self {
            params,
            models: [m; N_MODELS],
            f_mean: Vector3::zeros(),
            f_count: 0,
            started: false,
            last_vel: None,
            accel_kin: Vector2::zeros(),
            manoeuvre_mps2s: 0.0,
            steady_since: None,
            last_t_ns: i64::MIN,
            f_h_int: (Vector2::zeros(), 0.0),
            accel_ms: None,
            kin_ms: None,
            kin_anchor: None,
            lead: 0,
            pending: (Vector3::zeros(), Vector3::zeros(), 0.0),
        }
    }

    /// Its tuning.
    pub fn params(&self) -> &YawEstimatorParams {
        &self.params
    }

    /// Whether the bank runs (after its first GNSS velocity).
    pub fn started(&self) -> bool {
        self.started
    }

    /// Takes one IMU interval with its mean rates and specific force: the models are propagated
    /// once at least `predict_period_s` has been summed (an interval that long on its own is
    /// propagated as it is, so a 50 Hz IMU's samples are used one by one).
    pub fn predict(&mut self, gyro: &Vector3<f64>, accel: &Vector3<f64>, dt_s: f64) {
        if dt_s.is_nan() || dt_s <= 0.0 || dt_s >= 1.0 {
            return;
        }
        if !self.started {
            // Level from the averaged specific force until the bank starts.
            self.f_mean += accel;
            self.f_count += 1;
            return;
        }
        if self.pending.2 == 0.0 && dt_s >= self.params.predict_period_s {
            self.propagate(gyro, accel, dt_s);
            return;
        }
        self.pending.0 += gyro * dt_s;
        self.pending.1 += accel * dt_s;
        self.pending.2 += dt_s;
        if self.pending.2 >= self.params.predict_period_s {
            self.flush();
        }
    }

    /// Propagates what [`YawEstimator::predict`] has summed, if anything.
    fn flush(&mut self) {
        let (d_angle, d_vel, dt_s) = self.pending;
        if dt_s > 0.0 {
            self.pending = (Vector3::zeros(), Vector3::zeros(), 0.0);
            self.propagate(&(d_angle / dt_s), &(d_vel / dt_s), dt_s);
        }
    }

    /// Propagates every model over `dt_s` with the mean rates and specific force.
    fn propagate(&mut self, gyro: &Vector3<f64>, accel: &Vector3<f64>, dt_s: f64) {
        let g = 9.80665;
        let f_exp_nav = Vector3::new(self.accel_kin.x, self.accel_kin.y, -g);
        let f_norm = accel.norm();
        // Trust the accelerometer's direction less the further its magnitude is from what the
        // kinematics say (vibration, un-modelled vertical acceleration).
        let dev = ((f_norm - f_exp_nav.norm()) / g).abs();
        let gain = if dev < 0.5 {
            self.params.tilt_gain * (1.0 - 2.0 * dev)
        } else {
            0.0
        };
        let qa = self.params.accel_sigma_mps2.powi(2) * dt_s * dt_s;
        let qy = self.params.yaw_rate_sigma_radps.powi(2) * dt_s;
        let lead = self.lead;
        for (k, m) in self.models.iter_mut().enumerate() {
            let mut w = *gyro;
            if gain > 0.0 && f_norm > 1.0 {
                let f_exp_b = m.q.inverse_transform_vector(&f_exp_nav);
                let e = (accel / f_norm).cross(&f_exp_b.normalize());
                w += e * gain;
            }
            m.q *= UnitQuaternion::from_scaled_axis(w * dt_s);
            let f_nav = m.q.transform_vector(accel);
            let dv = Vector2::new(f_nav.x, f_nav.y) * dt_s;
            m.v += dv;
            if k == lead {
                self.f_h_int.0 += dv;
                self.f_h_int.1 += dt_s;
            }
            // F = [[1,0,−a_E dt],[0,1,a_N dt],[0,0,1]]
            let (c0, c1) = (-dv.y, dv.x);
            let p = m.p;
            let mut n = p;
            // P' = F P Fᵀ + Q with F = I + e₀c0 e₂ᵀ + e₁c1 e₂ᵀ
            for i in 0..3 {
                n[(0, i)] += c0 * p[(2, i)];
                n[(1, i)] += c1 * p[(2, i)];
            }
            let m2 = n;
            for i in 0..3 {
                n[(i, 0)] = m2[(i, 0)] + c0 * m2[(i, 2)];
                n[(i, 1)] = m2[(i, 1)] + c1 * m2[(i, 2)];
            }
            n[(0, 0)] += qa;
            n[(1, 1)] += qa;
            n[(2, 2)] += qy;
            m.p = n;
        }
    }

    /// Fuses a GNSS horizontal velocity (NED, m/s) with its 1-σ per axis at time `t_ns`.
    pub fn fuse_velocity(&mut self, t_ns: i64, v: Vector2<f64>, sigma_mps: f64) {
        if !v.iter().all(|x| x.is_finite()) {
            return;
        }
        // The models are weighed at the bank's latest time, not up to `predict_period_s` behind.
        self.flush();
        let sigma = sigma_mps.max(self.params.min_vel_sigma_mps);
        let mut after_gap = false;
        if let Some((t0, v0)) = self.last_vel {
            let dt = (t_ns - t0) as f64 * 1e-9;
            after_gap = dt > MAX_VEL_GAP_S;
            if dt > 0.05 && dt <= MAX_VEL_GAP_S {
                let a = (v - v0) / dt;
                // low-pass: GNSS velocity differences are noisy
                self.accel_kin += (a - self.accel_kin) * 0.5;
                self.manoeuvre_mps2s += a.norm() * dt;
            } else {
                self.accel_kin = Vector2::zeros();
            }
        }
        self.last_vel = Some((t_ns, v));
        self.track_accel_rms(after_gap);
        self.track_kinematic_rms(t_ns, v, after_gap);
        if !self.started {
            self.start(v, sigma);
            return;
        }
        if after_gap {
            self.reanchor(v, sigma);
            self.last_t_ns = t_ns;
            return;
        }
        let r = sigma * sigma;
        let mut like = [0.0; N_MODELS];
        for (k, m) in self.models.iter_mut().enumerate() {
            // The yaw state is that of the model's attitude, which the gyro propagated.
            m.yaw = yaw_of(&m.q);
            let y = v - m.v;
            let s = Matrix2::new(m.p[(0, 0)] + r, m.p[(0, 1)], m.p[(1, 0)], m.p[(1, 1)] + r);
            let Some(si) = s.try_inverse() else { continue };
            let det = s.determinant().max(1e-12);
            let nis = (y.transpose() * si * y)[(0, 0)];
            like[k] = (-0.5 * nis.min(200.0)).exp() / (TAU * det.sqrt());
            // K = P Hᵀ S⁻¹ with H = [I₂ 0]
            let pht = m.p.fixed_view::<3, 2>(0, 0).into_owned();
            let kg = pht * si;
            let dx = kg * y;
            m.v += Vector2::new(dx[0], dx[1]);
            let dyaw = dx[2];
            m.q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), dyaw) * m.q;
            m.yaw = yaw_of(&m.q);
            let mut p = m.p - kg * pht.transpose();
            p = (p + p.transpose()) * 0.5;
            m.p = p;
        }
        let total: f64 = self
            .models
            .iter()
            .zip(like)
            .map(|(m, l)| m.weight * l)
            .sum();
        if total > 0.0 && total.is_finite() {
            for (m, l) in self.models.iter_mut().zip(like) {
                m.weight = m.weight * l / total;
            }
        }
        // Floor: a hypothesis that lost once must be able to come back (a wrong early decision
        // during a take-off transient).
        let floor = 1e-3 / N_MODELS as f64;
        let mut sum = 0.0;
        for m in &mut self.models {
            m.weight = m.weight.max(floor);
            sum += m.weight;
        }
        for m in &mut self.models {
            m.weight /= sum;
        }
        self.lead = self.leading();
        self.last_t_ns = t_ns;
        let thr = self.params.converged_sigma_rad;
        self.steady_since = match (self.yaw(), self.steady_since) {
            (Some((yaw, s)), Some((t0, y0))) if s < thr && wrap_pi(yaw - y0).abs() < thr => {
                Some((t0, y0))
            }
            (Some((yaw, s)), _) if s < thr => Some((t_ns, yaw)),
            _ => None,
        };
    }

    /// The model with the largest weight.
    fn leading(&self) -> usize {
        let mut best = 0;
        for (k, m) in self.models.iter().enumerate() {
            if m.weight > self.models[best].weight {
                best = k;
            }
        }
        best
    }

    /// Folds the mean horizontal specific force since the last GNSS velocity into its low-passed
    /// mean square (none across a gap).
    fn track_accel_rms(&mut self, after_gap: bool) {
        let (sum, dt) = std::mem::replace(&mut self.f_h_int, (Vector2::zeros(), 0.0));
        if after_gap || dt <= 0.0 {
            return;
        }
        let a2 = (sum / dt).norm_squared();
        let alpha = (dt / self.params.accel_rms_window_s).min(1.0);
        let ms = self.accel_ms.get_or_insert(a2);
        *ms += (a2 - *ms) * alpha;
    }

    /// Once the span since `kin_anchor` reaches `accel_rms_span_s`, folds the change of the GNSS
    /// velocity over it into `kin_ms` and starts the next span at this fix (anew after a gap).
    fn track_kinematic_rms(&mut self, t_ns: i64, v: Vector2<f64>, after_gap: bool) {
        let Some((t0, v0)) = self.kin_anchor.filter(|_| !after_gap) else {
            self.kin_anchor = Some((t_ns, v));
            return;
        };
        let span_s = (t_ns - t0) as f64 * 1e-9;
        if span_s < self.params.accel_rms_span_s.max(1e-3) {
            return;
        }
        self.kin_anchor = Some((t_ns, v));
        let a2 = ((v - v0) / span_s).norm_squared();
        let alpha = (span_s / self.params.accel_rms_window_s).min(1.0);
        let ms = self.kin_ms.get_or_insert(a2);
        *ms += (a2 - *ms) * alpha;
    }

    /// The heading error a persistent horizontal specific-force error can hide, rad:
    /// `atan(b / a_rms)`, with `b` = `persistent_accel_sigma_mps2` and `a_rms` the recent RMS
    /// horizontal acceleration. A hovering copter (a_rms 0.3 m/s²) cannot know its heading better
    /// than ~18° this way, however many fixes agree; a turning plane (a few m/s²) to 1–2°. π/2
    /// before any interval was seen.
    ///
    /// `a_rms` is the smaller of two views: the mean specific force the leading model rotated
    /// into NED over each fix interval, and the change of the GNSS velocity over spans of
    /// `accel_rms_span_s`. Each alone can show an acceleration the vehicle did not make: the
    /// specific force through the model's tilt error (10° is 1.7 m/s²) and through vibration,
    /// the velocity change through the fixes' noise. Public ArduPilot copters that hop about at
    /// under 1 m/s, or lie tipped over after a crash, showed 1.3–2.5 m/s² RMS of specific force
    /// and claimed 4–10° while 20–40° off the autopilot's compass heading.
    pub fn observability_sigma_rad(&self) -> f64 {
        self.hidden_heading_rad(self.accel_ms.zip(self.kin_ms).map(|(f2, k2)| f2.min(k2)))
    }

    /// `atan(b / a_rms)` for a mean-square acceleration `a2`; π/2 when there is none yet.
    fn hidden_heading_rad(&self, a2: Option<f64>) -> f64 {
        let b = self.params.persistent_accel_sigma_mps2;
        a2.map_or(std::f64::consts::FRAC_PI_2, |a2| {
            b.atan2(a2.max(0.0).sqrt())
        })
    }

    fn start(&mut self, v: Vector2<f64>, sigma: f64) {
        let f = if self.f_count > 0 {
            self.f_mean / self.f_count as f64
        } else {
            Vector3::new(0.0, 0.0, -9.81)
        };
        let roll = (-f.y).atan2(-f.z);
        let pitch = f.x.atan2(f.y.hypot(f.z));
        let spread = TAU / N_MODELS as f64;
        for (k, m) in self.models.iter_mut().enumerate() {
            let yaw = wrap_pi(k as f64 * spread);
            m.q = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
            m.yaw = yaw;
            m.v = v;
            m.p = Matrix3::from_diagonal(&Vector3::new(
                sigma * sigma,
                sigma * sigma,
                (0.5 * spread).powi(2),
            ));
            m.weight = 1.0 / N_MODELS as f64;
        }
        self.started = true;
    }

    /// After a gap in the velocities ([`MAX_VEL_GAP_S`]): every model's velocity is set to the
    /// fix with the fix's σ and no correlation with its heading, which keeps its own σ; the
    /// weights stay, and the heading must hold steady anew before it counts as converged.
    fn reanchor(&mut self, v: Vector2<f64>, sigma: f64) {
        for m in &mut self.models {
            m.v = v;
            let yaw_var = m.p[(2, 2)];
            m.p = Matrix3::from_diagonal(&Vector3::new(sigma * sigma, sigma * sigma, yaw_var));
        }
        self.steady_since = None;
    }

    /// The composite heading and its σ, rad (`None` before the bank starts).
    pub fn yaw(&self) -> Option<(f64, f64)> {
        if !self.started {
            return None;
        }
        let (s, c) = self.models.iter().fold((0.0, 0.0), |(s, c), m| {
            (s + m.weight * m.yaw.sin(), c + m.weight * m.yaw.cos())
        });
        let mean = s.atan2(c);
        let var: f64 = self
            .models
            .iter()
            .map(|m| m.weight * (wrap_pi(m.yaw - mean).powi(2) + m.p[(2, 2)]))
            .sum();
        Some((mean, var.max(0.0).sqrt()))
    }

    /// The heading when the bank has converged: σ below the threshold, steadily, for
    /// `converged_hold_ns`.
    pub fn converged_yaw(&self) -> Option<(f64, f64)> {
        let (t0, _) = self.steady_since?;
        if self.last_t_ns - t0 < self.params.converged_hold_ns {
            return None;
        }
        self.yaw()
            .filter(|&(_, s)| s < self.params.converged_sigma_rad)
    }

    /// Whether the recent accelerations are too small for the GNSS velocity to tell the heading
    /// as well as the bank requires for convergence: a hover, or a straight line at constant
    /// speed. Judged on the specific force alone, not on the smaller view that bounds what may
    /// be claimed ([`Self::observability_sigma_rad`]): the small, quick accelerations of a hover
    /// that a one-second velocity change smooths away still carry the heading to a filter that
    /// weighs them with its own σ (copter_218 without its compass: yaw RMSE 9.4° against 10.9°
    /// when the corrections stopped on the smaller view).
    pub fn heading_unobservable(&self) -> bool {
        self.hidden_heading_rad(self.accel_ms) > self.params.converged_sigma_rad
    }

    /// The σ a heading seen only through the GNSS velocity can honestly claim, rad: the bank's
    /// σ combined with what the recent accelerations cannot tell
    /// ([`Self::observability_sigma_rad`]). `None` before the bank starts. Also while the bank
    /// does not count as converged: a yaw-in-place turn moves its heading, which resets its
    /// steadiness clock, but not its spread (copter_218 without its compass: the filter's own σ
    /// was 3.8° through such turns while 12° from the autopilot's heading).
    pub fn honest_sigma_rad(&self) -> Option<f64> {
        self.yaw()
            .map(|(_, s)| s.hypot(self.observability_sigma_rad()))
    }

    /// The models' weights (diagnostics).
    pub fn weights(&self) -> [f64; N_MODELS] {
        self.models.map(|m| m.weight)
    }

    /// Sets every model's heading and spread anew around the bank's own state (after the main
    /// filter took the heading, the bank keeps running: nothing to do) — or restarts it.
    pub fn restart(&mut self) {
        *self = Self::new(self.params);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vehicle with heading `yaw0` flying a sideways-and-back pattern (body-frame accelerations
    /// only sideways: a course-based heading would be 90° off).
    fn fly(yaw0: f64) -> YawEstimator {
        let mut e = YawEstimator::default();
        let dt = 0.01;
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw0);
        let mut v = Vector2::zeros();
        for k in 0..6000 {
            let t = k as f64 * dt;
            // body acceleration along +y (right), sinusoidal: 1.5 m/s² peak, 8 s period
            let a_b = Vector3::new(0.0, 1.5 * (TAU * t / 8.0).sin(), 0.0);
            let a_n = q.transform_vector(&a_b);
            v += Vector2::new(a_n.x, a_n.y) * dt;
            let f_b = a_b - q.inverse_transform_vector(&Vector3::new(0.0, 0.0, 9.80665));
            e.predict(&Vector3::zeros(), &f_b, dt);
            if k % 20 == 0 {
                e.fuse_velocity((t * 1e9) as i64, v, 0.2);
            }
        }
        e
    }

    #[test]
    fn a_fast_imu_is_summed_to_the_predict_period() {
        // Ten 1 ms samples of constant rates propagate the models as one 10 ms sample does.
        let start = |e: &mut YawEstimator| {
            e.predict(&Vector3::zeros(), &Vector3::new(0.0, 0.0, -9.80665), 0.01);
            e.fuse_velocity(0, Vector2::zeros(), 0.2);
        };
        let (mut fast, mut slow) = (YawEstimator::default(), YawEstimator::default());
        start(&mut fast);
        start(&mut slow);
        let gyro = Vector3::new(0.01, -0.02, 0.3);
        let f_b = Vector3::new(1.0, 0.5, -9.80665);
        for _ in 0..100 {
            for _ in 0..10 {
                fast.predict(&gyro, &f_b, 0.001);
            }
            slow.predict(&gyro, &f_b, 0.01);
        }
        fast.fuse_velocity(1_000_000_000, Vector2::new(1.0, 0.5), 0.2);
        slow.fuse_velocity(1_000_000_000, Vector2::new(1.0, 0.5), 0.2);
        for (a, b) in fast.models.iter().zip(&slow.models) {
            assert!((a.yaw - b.yaw).abs() < 1e-9, "{} vs {}", a.yaw, b.yaw);
            assert!((a.v - b.v).norm() < 1e-9);
            assert!((a.p - b.p).norm() < 1e-12);
            assert!((a.weight - b.weight).abs() < 1e-9);
        }
        // A part-period left over is propagated before a velocity is weighed.
        fast.predict(&gyro, &f_b, 0.004);
        let before = fast.models[0].q;
        fast.fuse_velocity(1_100_000_000, Vector2::new(1.0, 0.5), 0.2);
        assert_ne!(fast.models[0].q, before);
        assert_eq!(fast.pending.2, 0.0);
    }

    #[test]
    fn converges_from_every_heading_flying_sideways() {
        for i in 0..12 {
            let yaw0 = wrap_pi(i as f64 * TAU / 12.0 + 0.1);
            let e = fly(yaw0);
            let (yaw, sigma) = e.converged_yaw().expect("converged");
            assert!(
                wrap_pi(yaw - yaw0).abs() < 5f64.to_radians(),
                "truth {:.1} est {:.1} sigma {:.1}",
                yaw0.to_degrees(),
                yaw.to_degrees(),
                sigma.to_degrees()
            );
        }
    }

    #[test]
    fn a_gap_in_the_velocities_reanchors_instead_of_weighing() {
        let mut e = fly(0.3);
        let before = e.weights();
        assert!(e.converged_yaw().is_some());
        // 6 s without GNSS while a biased accelerometer integrates 0.35 m/s² sideways.
        let f_b = Vector3::new(0.0, 0.35, -9.80665);
        for _ in 0..600 {
            e.predict(&Vector3::zeros(), &f_b, 0.01);
        }
        let t = e.last_t_ns + 6_000_000_000;
        e.fuse_velocity(t, Vector2::new(1.0, 2.0), 0.2);
        assert_eq!(e.weights(), before, "a fix after a gap weighs nothing");
        assert!(e.models.iter().all(|m| m.v == Vector2::new(1.0, 2.0)));
        assert!(e.converged_yaw().is_none(), "convergence is earned anew");
    }

    #[test]
    fn the_honest_sigma_follows_how_hard_the_vehicle_accelerates() {
        // Sideways at 1.5 m/s² peak (RMS ~1.06): a 0.1 m/s² persistent error hides ~5.4°.
        let e = fly(0.3);
        let obs = e.observability_sigma_rad().to_degrees();
        assert!((4.0..7.0).contains(&obs), "{obs}");
        let (_, model) = e.converged_yaw().expect("converged");
        let honest = e.honest_sigma_rad().expect("converged");
        assert!(
            honest >= model && honest >= obs.to_radians(),
            "{honest} {model}"
        );
        // Then a hover with 0.1 m/s² of corrections: the bound widens past 25°.
        let mut e = e;
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3);
        let mut v = Vector2::zeros();
        for k in 0..4000 {
            let t = 60.0 + k as f64 * 0.01;
            let a_b = Vector3::new(0.1 * (TAU * t / 4.0).sin(), 0.0, 0.0);
            let a_n = q.transform_vector(&a_b);
            v += Vector2::new(a_n.x, a_n.y) * 0.01;
            let f_b = a_b - q.inverse_transform_vector(&Vector3::new(0.0, 0.0, 9.80665));
            e.predict(&Vector3::zeros(), &f_b, 0.01);
            if k % 20 == 0 {
                e.fuse_velocity((t * 1e9) as i64, v, 0.2);
            }
        }
        let obs = e.observability_sigma_rad().to_degrees();
        assert!(obs > 25.0, "{obs}");
    }

    #[test]
    fn a_shaking_vehicle_that_goes_nowhere_does_not_claim_to_know_its_heading() {
        // Standing still (the fixes say so) while the frame shakes: a 1 m/s² horizontal specific
        // force at 1.3 Hz that the 0.2 s fix intervals do not average away. The specific force
        // alone would claim an RMS acceleration of ~0.7 m/s², a heading told to ~9°.
        let mut e = YawEstimator::default();
        let dt = 0.01;
        for k in 0..6000 {
            let t = k as f64 * dt;
            let shake = Vector3::new((TAU * 1.3 * t).sin(), 0.0, 0.0);
            e.predict(
                &Vector3::zeros(),
                &(shake - Vector3::new(0.0, 0.0, 9.80665)),
                dt,
            );
            if k % 20 == 0 {
                e.fuse_velocity((t * 1e9) as i64, Vector2::zeros(), 0.2);
            }
        }
        let obs = e.observability_sigma_rad().to_degrees();
        assert!(obs > 45.0, "{obs}");
        let honest = e.honest_sigma_rad().expect("started").to_degrees();
        assert!(honest > 45.0, "{honest}");
    }

    #[test]
    fn stays_uncertain_without_acceleration() {
        let mut e = YawEstimator::default();
        let f_b = Vector3::new(0.0, 0.0, -9.80665);
        for k in 0..3000 {
            e.predict(&Vector3::zeros(), &f_b, 0.01);
            if k % 20 == 0 {
                e.fuse_velocity(k * 10_000_000, Vector2::new(10.0, 0.0), 0.2);
            }
        }
        assert!(e.converged_yaw().is_none(), "{:?}", e.yaw());
    }
}
