//! Strapdown mechanization in the fixed local NED frame and error-state covariance prediction.
//!
//! Physics (shared with the simulator): `q̇ = ½ q ⊗ (ω_ib − b_g − Cᵀ ω_ie)`,
//! `v̇ = C (f − b_a) + gⁿ − 2 ω_ie × v`, `ṗ = v` — the paper's eqs. (29)–(30) with the
//! Earth-rate terms of a rotating Earth-fixed frame.
//!
//! Error dynamics (global attitude error `R_true = Exp(δθ) R`):
//! `δṗ = δv`, `δv̇ = −[C f̂]× δθ − C δb_a − 2[ω_ie]× δv + C n_a`,
//! `δθ̇ = −[ω_ie]× δθ − C δb_g − C n_g`, biases random walks, GNSS error `δġ = −δg/τ + n`.
//! The covariance is propagated with the block-sparse `F = I + A·dt` (no dense 24³ products).

use nalgebra::{Matrix3, Vector3};
use uavnav_core::rotation::skew;

use crate::state::{Cov, IBA, IBG, ICP, ICTH, IGM, IP, ITH, IV, N, Nominal, exp_q};

/// A mean IMU sample over an integration interval (bias not removed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuMean {
    /// Angular rate w.r.t. inertial space, body, rad/s.
    pub gyro: Vector3<f64>,
    /// Specific force, body, m/s².
    pub accel: Vector3<f64>,
}

/// Continuous-time process noise densities (squared, per second).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessNoise {
    /// Gyro white noise PSD, (rad/s)²/Hz.
    pub gyro_psd: f64,
    /// Accel white noise PSD, (m/s²)²/Hz.
    pub accel_psd: f64,
    /// Gyro bias random-walk PSD.
    pub gyro_bias_psd: f64,
    /// Accel bias random-walk PSD.
    pub accel_bias_psd: f64,
    /// GNSS Gauss–Markov driving PSD per axis (2σ²/τ), horizontal and vertical.
    pub gm_psd: [f64; 3],
    /// GNSS Gauss–Markov correlation time, s.
    pub gm_tau_s: f64,
}

/// Earth rate in the local NED frame at the origin latitude, rad/s.
pub fn earth_rate_ned(lat0_rad: f64) -> Vector3<f64> {
    let w = uavnav_core::geodesy::OMEGA_EARTH_RADPS;
    Vector3::new(w * lat0_rad.cos(), 0.0, -w * lat0_rad.sin())
}

/// Integrates the nominal state over `dt_s` with the mean IMU sample (paper eqs. 29–30; the
/// attitude part is the quaternion form of eq. 31). Uses the mid-interval attitude for the
/// specific-force rotation.
pub fn integrate_nominal(
    x: &mut Nominal,
    imu: &ImuMean,
    dt_s: f64,
    g_ned: &Vector3<f64>,
    w_ie: &Vector3<f64>,
    gm_tau_s: f64,
) {
    let r0 = x.q.to_rotation_matrix();
    let w_nb = imu.gyro - x.bg - r0.transpose() * w_ie;
    let half = exp_q(&(w_nb * (0.5 * dt_s)));
    let r_mid = (x.q * half).to_rotation_matrix();
    let a = r_mid * (imu.accel - x.ba) + g_ned - 2.0 * w_ie.cross(&x.v);
    x.p += x.v * dt_s + a * (0.5 * dt_s * dt_s);
    x.v += a * dt_s;
    x.q = x.q * half * half;
    x.gm *= (-dt_s / gm_tau_s).exp();
}

/// The non-trivial blocks of the continuous error-dynamics matrix `A` (so `F = I + A dt`).
#[derive(Debug, Clone, Copy)]
pub struct ErrorDynamics {
    /// `∂δv̇/∂δθ = −[C f̂]×`.
    pub a_v_th: Matrix3<f64>,
    /// `C` (nav_from_body); `∂δv̇/∂δb_a = ∂δθ̇/∂δb_g = −C`.
    pub c: Matrix3<f64>,
    /// `[ω_ie]×`.
    pub w_ie_x: Matrix3<f64>,
    /// `1/τ` of the GNSS error.
    pub inv_tau: f64,
}

impl ErrorDynamics {
    /// Linearises at the nominal state with the mean IMU sample.
    pub fn new(x: &Nominal, imu: &ImuMean, w_ie: &Vector3<f64>, gm_tau_s: f64) -> Self {
        let c = *x.q.to_rotation_matrix().matrix();
        Self {
            a_v_th: -skew(&(c * (imu.accel - x.ba))),
            c,
            w_ie_x: skew(w_ie),
            inv_tau: 1.0 / gm_tau_s,
        }
    }

    /// The dense `F = I + A dt` (for tests and the Jacobian check).
    pub fn dense_f(&self, dt_s: f64) -> Cov {
        let mut a = Cov::zeros();
        a.fixed_view_mut::<3, 3>(IP, IV)
            .copy_from(&Matrix3::identity());
        a.fixed_view_mut::<3, 3>(IV, ITH).copy_from(&self.a_v_th);
        a.fixed_view_mut::<3, 3>(IV, IBA).copy_from(&(-self.c));
        a.fixed_view_mut::<3, 3>(IV, IV)
            .copy_from(&(-2.0 * self.w_ie_x));
        a.fixed_view_mut::<3, 3>(ITH, ITH)
            .copy_from(&(-self.w_ie_x));
        a.fixed_view_mut::<3, 3>(ITH, IBG).copy_from(&(-self.c));
        a.fixed_view_mut::<3, 3>(IGM, IGM)
            .copy_from(&(-self.inv_tau * Matrix3::identity()));
        Cov::identity() + a * dt_s
    }

    /// `P ← F P Fᵀ + Q dt` with `F = I + A dt`, in place.
    ///
    /// With `G = A dt` and `P` symmetric, `F P Fᵀ = P + B + Bᵀ + B Gᵀ` where `B = G P`. `G` has only
    /// 12 non-zero rows (position, velocity, attitude, GNSS error), so `B` is 12 rows of `P`
    /// combined 3×3-blockwise and `E = B Gᵀ` a 12×12 block. With `D = B + ½E` (12 rows),
    /// `P' = P + D + Dᵀ`: outside the 12×12 block row `a` of `D` is added to row and column `a`;
    /// inside it each pair `D_ab + D_ba` is summed once and written to both places, so an exactly
    /// symmetric `P` (every writer of `P` keeps it so) stays exactly symmetric. Plain loops over
    /// contiguous columns: this runs every `cov_period_s` for every vehicle of the service, and
    /// nalgebra's generic block products and a full symmetrising pass cost several times more.
    pub fn propagate(&self, p: &mut Cov, dt_s: f64, q: &ProcessNoise) {
        let g = StepBlocks::new(self, dt_s);
        let mut d = g.rows_of_gp(p.as_slice());
        for row in d.iter_mut() {
            let e = g.row_times_gt(row);
            for (c, &rc) in ACTIVE.iter().enumerate() {
                row[rc] += 0.5 * e[c];
            }
        }
        let s = p.as_mut_slice();
        for (a, &ra) in ACTIVE.iter().enumerate() {
            for &j in &PASSIVE {
                s[ra + j * N] += d[a][j];
                s[j + ra * N] += d[a][j];
            }
            for (b, &rb) in ACTIVE.iter().enumerate().skip(a) {
                let v = d[a][rb] + d[b][ra];
                s[ra + rb * N] += v;
                if rb != ra {
                    s[rb + ra * N] += v;
                }
            }
        }
        add_process_noise(p, dt_s, q);
    }
}

/// The error states whose dynamics rows are zero (biases, clone): only `B`'s columns reach them.
const PASSIVE: [usize; 12] = [
    IBG,
    IBG + 1,
    IBG + 2,
    IBA,
    IBA + 1,
    IBA + 2,
    ICTH,
    ICTH + 1,
    ICTH + 2,
    ICP,
    ICP + 1,
    ICP + 2,
];

/// The error states whose dynamics rows are non-zero, in the order of [`StepBlocks`]' rows.
const ACTIVE: [usize; 12] = [
    IP,
    IP + 1,
    IP + 2,
    IV,
    IV + 1,
    IV + 2,
    ITH,
    ITH + 1,
    ITH + 2,
    IGM,
    IGM + 1,
    IGM + 2,
];

/// The non-zero blocks of `G = A dt`, as plain arrays (row-major 3×3).
struct StepBlocks {
    dt: f64,
    /// `−[C f̂]× dt`.
    v_th: [[f64; 3]; 3],
    /// `C dt` (enters negated).
    c: [[f64; 3]; 3],
    /// `[ω_ie]× dt`.
    w: [[f64; 3]; 3],
    /// `dt / τ` (enters negated).
    k: f64,
}

fn rows3(m: &Matrix3<f64>, dt: f64) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)] * dt))
}

impl StepBlocks {
    fn new(e: &ErrorDynamics, dt: f64) -> Self {
        Self {
            dt,
            v_th: rows3(&e.a_v_th, dt),
            c: rows3(&e.c, dt),
            w: rows3(&e.w_ie_x, dt),
            k: e.inv_tau * dt,
        }
    }

    /// `x(j) = Σ_k m[i][k]·y(k, j)` accumulated with `sign` into `out`, for the 3 columns of `p`
    /// starting at `col` (columns of a symmetric `P` are its rows).
    fn axpy3(out: &mut [f64; N], m: &[f64; 3], sign: f64, p: &[f64], col: usize) {
        for (k, &mk) in m.iter().enumerate() {
            let f = sign * mk;
            let src = &p[(col + k) * N..(col + k) * N + N];
            for (o, &x) in out.iter_mut().zip(src) {
                *o += f * x;
            }
        }
    }

    /// The 12 active rows of `B = G P` (`p` column-major and symmetric).
    fn rows_of_gp(&self, p: &[f64]) -> [[f64; N]; 12] {
        let mut b = [[0.0; N]; 12];
        for i in 0..3 {
            let col = &p[(IV + i) * N..(IV + i) * N + N];
            for (o, &x) in b[i].iter_mut().zip(col) {
                *o = self.dt * x;
            }
            Self::axpy3(&mut b[3 + i], &self.v_th[i], 1.0, p, ITH);
            Self::axpy3(&mut b[3 + i], &self.c[i], -1.0, p, IBA);
            Self::axpy3(&mut b[3 + i], &self.w[i], -2.0, p, IV);
            Self::axpy3(&mut b[6 + i], &self.w[i], -1.0, p, ITH);
            Self::axpy3(&mut b[6 + i], &self.c[i], -1.0, p, IBG);
            let col = &p[(IGM + i) * N..(IGM + i) * N + N];
            for (o, &x) in b[9 + i].iter_mut().zip(col) {
                *o = -self.k * x;
            }
        }
        b
    }

    /// One row of `B` times `Gᵀ`, at the active columns (the order of [`ACTIVE`]).
    fn row_times_gt(&self, r: &[f64; N]) -> [f64; 12] {
        let dot = |m: &[f64; 3], at: usize| m[0] * r[at] + m[1] * r[at + 1] + m[2] * r[at + 2];
        let mut e = [0.0; 12];
        for i in 0..3 {
            e[i] = self.dt * r[IV + i];
            e[3 + i] = dot(&self.v_th[i], ITH) - dot(&self.c[i], IBA) - 2.0 * dot(&self.w[i], IV);
            e[6 + i] = -dot(&self.w[i], ITH) - dot(&self.c[i], IBG);
            e[9 + i] = -self.k * r[IGM + i];
        }
        e
    }
}

/// Adds the discretised process noise: isotropic white noises rotate into isotropic blocks.
fn add_process_noise(p: &mut Cov, dt_s: f64, q: &ProcessNoise) {
    for k in 0..3 {
        p[(IV + k, IV + k)] += q.accel_psd * dt_s;
        p[(ITH + k, ITH + k)] += q.gyro_psd * dt_s;
        p[(IBG + k, IBG + k)] += q.gyro_bias_psd * dt_s;
        p[(IBA + k, IBA + k)] += q.accel_bias_psd * dt_s;
        p[(IGM + k, IGM + k)] += q.gm_psd[k] * dt_s;
    }
}

/// The integration-error variance one IMU interval shows, per axis: `|Δ|² dt² / 6` for the gyro
/// (rad²) and the accelerometer ((m/s)²), `Δ` the change between the interval's two samples.
/// For white noise of per-axis PSD `q`, `E|Δ|² = 6 q / dt` over three axes, so this is `q dt`;
/// for a sampled signal (vibration, a logged 10 Hz IMU of a manoeuvring aircraft) it is of the
/// order of what the interval's integration misses. Both profiles take it as process noise where
/// it exceeds the configured densities (`Eskf::observed_imu_noise`, `paper::observe_imu_noise`).
pub fn interval_noise_var(
    a: &uavnav_core::ImuSample,
    b: &uavnav_core::ImuSample,
    dt_s: f64,
) -> (f64, f64) {
    let dg = (b.gyro_radps - a.gyro_radps).norm_squared();
    let da = (b.accel_mps2 - a.accel_mps2).norm_squared();
    (dg * dt_s * dt_s / 6.0, da * dt_s * dt_s / 6.0)
}

/// Eq. G1: what integrating across a bridged IMU gap of `gap_s` between the samples `a` and `b`
/// (with their mean, as any interval is) cannot know, as variances per axis to add to the
/// attitude (rad²), velocity (m²/s²) and position (m²). What the mean misses is a rate or
/// specific force that changed in between, so the unseen rate's σ is the larger of
/// `EstimatorParams::bridge_rate_sigma_radps` and half the change from `a` to `b` (a vehicle that
/// was turning differently at each end of the gap did something the mean cannot say), and the
/// same for the specific force: `σ_θ² = (T max(σ_ω, |ω_b − ω_a| / 2))²` (at most 30°),
/// `σ_v² = (T σ_a)²`, `σ_p² = (T² σ_a / 2)²`.
pub fn gap_variances(
    params: &crate::EstimatorParams,
    a: &uavnav_core::ImuSample,
    b: &uavnav_core::ImuSample,
    gap_s: f64,
) -> [f64; 3] {
    let rate = params
        .bridge_rate_sigma_radps
        .max(0.5 * (b.gyro_radps - a.gyro_radps).norm());
    let accel = params
        .bridge_accel_sigma_mps2
        .max(0.5 * (b.accel_mps2 - a.accel_mps2).norm());
    [
        (rate * gap_s).min(30f64.to_radians()).powi(2),
        (accel * gap_s).powi(2),
        (0.5 * accel * gap_s * gap_s).powi(2),
    ]
}

/// Makes `p` exactly symmetric.
pub fn symmetrize(p: &mut Cov) {
    for i in 0..N {
        for j in (i + 1)..N {
            let m = 0.5 * (p[(i, j)] + p[(j, i)]);
            p[(i, j)] = m;
            p[(j, i)] = m;
        }
    }
}

/// Normal gravity in the local frame, evaluated exactly every `REFRESH_M` of travel and corrected
/// in between with the free-air vertical gradient (cheap enough for every IMU sample).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GravityCache {
    at_m: Vector3<f64>,
    g: Vector3<f64>,
}

/// Distance after which gravity is re-evaluated exactly, m.
pub const GRAVITY_REFRESH_M: f64 = 20.0;
/// Free-air gradient of normal gravity, (m/s²)/m (gravity grows going down).
pub const FREE_AIR_GRADIENT: f64 = 3.086e-6;

impl GravityCache {
    /// Evaluates gravity at `p`.
    pub fn new(frame: &uavnav_core::LocalFrame, p: &Vector3<f64>) -> Self {
        Self {
            at_m: *p,
            g: frame.gravity_ned(p),
        }
    }

    /// Gravity at `p`, refreshing the cache when far from its evaluation point.
    pub fn at(&mut self, frame: &uavnav_core::LocalFrame, p: &Vector3<f64>) -> Vector3<f64> {
        if (p - self.at_m).norm_squared() > GRAVITY_REFRESH_M * GRAVITY_REFRESH_M {
            *self = Self::new(frame, p);
        }
        self.peek(p)
    }

    /// Gravity at `p` from the cache without refreshing.
    pub fn peek(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.g + Vector3::new(0.0, 0.0, FREE_AIR_GRADIENT * (p.z - self.at_m.z))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    fn nominal() -> Nominal {
        Nominal {
            t_ns: 0,
            p: Vector3::new(120.0, -40.0, -200.0),
            v: Vector3::new(25.0, 12.0, -1.5),
            q: UnitQuaternion::from_euler_angles(0.1, -0.2, 2.0),
            bg: Vector3::new(1e-3, -2e-3, 5e-4),
            ba: Vector3::new(0.02, -0.01, 0.03),
            gm: Vector3::new(0.5, -0.3, 1.0),
            clone: None,
        }
    }

    /// A dense symmetric positive-definite matrix from a fixed pseudo-random `L Lᵀ`.
    fn spd(seed: u64) -> Cov {
        let mut x = seed;
        let l = Cov::from_fn(|_, _| {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((x >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        });
        let mut p = l * l.transpose() + Cov::identity() * 1e-3;
        symmetrize(&mut p);
        p
    }

    #[test]
    fn propagate_equals_dense_f_p_ft_plus_q() {
        let imu = ImuMean {
            gyro: Vector3::new(0.05, -0.02, 0.17),
            accel: Vector3::new(1.2, 2.5, -9.5),
        };
        let dynamics = ErrorDynamics::new(&nominal(), &imu, &earth_rate_ned(0.7), 300.0);
        let q = ProcessNoise {
            gyro_psd: 1e-6,
            accel_psd: 1e-3,
            gyro_bias_psd: 1e-9,
            accel_bias_psd: 1e-7,
            gm_psd: [0.01, 0.02, 0.03],
            gm_tau_s: 300.0,
        };
        for (seed, dt) in [(1, 0.01), (2, 0.005), (3, 0.1)] {
            let p0 = spd(seed);
            let f = dynamics.dense_f(dt);
            let mut want = f * p0 * f.transpose();
            add_process_noise(&mut want, dt, &q);
            let mut got = p0;
            dynamics.propagate(&mut got, dt, &q);
            let err = (got - want).abs().max();
            assert!(
                err < 1e-12 * p0.abs().max(),
                "seed {seed}: max error {err:e}"
            );
            assert_eq!(got, got.transpose(), "exactly symmetric");
        }
    }
}
