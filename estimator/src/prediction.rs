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

use crate::state::{Cov, IBA, IBG, IGM, IP, ITH, IV, N, Nominal, exp_q};

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

    /// `P ← F P Fᵀ + Q dt` with `F = I + A dt`, in place: `M = P + dt·A P` touches only the 12
    /// rows where `A` is non-zero, `P' = M + dt·M Aᵀ` only the same 12 columns (3×24 blocks, no
    /// 24×24 products).
    pub fn propagate(&self, p: &mut Cov, dt_s: f64, q: &ProcessNoise) {
        let (avth, c, wx, k) = (
            self.a_v_th * dt_s,
            self.c * dt_s,
            self.w_ie_x * dt_s,
            self.inv_tau * dt_s,
        );
        let d_p = p.fixed_rows::<3>(IV) * dt_s;
        let d_v = avth * p.fixed_rows::<3>(ITH)
            - c * p.fixed_rows::<3>(IBA)
            - 2.0 * wx * p.fixed_rows::<3>(IV);
        let d_th = -wx * p.fixed_rows::<3>(ITH) - c * p.fixed_rows::<3>(IBG);
        let d_gm = p.fixed_rows::<3>(IGM) * -k;
        {
            let mut blk = p.fixed_rows_mut::<3>(IP);
            blk += &d_p;
        }
        {
            let mut blk = p.fixed_rows_mut::<3>(IV);
            blk += &d_v;
        }
        {
            let mut blk = p.fixed_rows_mut::<3>(ITH);
            blk += &d_th;
        }
        {
            let mut blk = p.fixed_rows_mut::<3>(IGM);
            blk += &d_gm;
        }
        let e_p = p.fixed_columns::<3>(IV) * dt_s;
        let e_v = p.fixed_columns::<3>(ITH) * avth.transpose()
            - p.fixed_columns::<3>(IBA) * c.transpose()
            - 2.0 * p.fixed_columns::<3>(IV) * wx.transpose();
        let e_th =
            -p.fixed_columns::<3>(ITH) * wx.transpose() - p.fixed_columns::<3>(IBG) * c.transpose();
        let e_gm = p.fixed_columns::<3>(IGM) * -k;
        {
            let mut blk = p.fixed_columns_mut::<3>(IP);
            blk += &e_p;
        }
        {
            let mut blk = p.fixed_columns_mut::<3>(IV);
            blk += &e_v;
        }
        {
            let mut blk = p.fixed_columns_mut::<3>(ITH);
            blk += &e_th;
        }
        {
            let mut blk = p.fixed_columns_mut::<3>(IGM);
            blk += &e_gm;
        }
        add_process_noise(p, dt_s, q);
        symmetrize(p);
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
