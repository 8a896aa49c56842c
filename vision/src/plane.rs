//! Plane-aware egomotion (beyond the paper). Over flat ground the 8-point problem is nearly
//! degenerate (a planar scene has a "twin" motion that fits as well as the truth). With the
//! ground normal `n` (camera 0, pointing at the ground) and distance `d` from the attitude and
//! altitude estimate, a ground point satisfies `nᵀX0 = d`, so its depth is `z0 = d / nᵀx0`
//! and `x1 ∝ R x0 + t / z0 = (R + t nᵀ/d) x0`. Given `R` this is linear in the metric `t`
//! (a 2-point solver), and a small Gauss–Newton over `(R, t, n)` with a prior on `n` refines it
//! on all inliers. The scale comes from `d`, so `t` is metric.

use nalgebra::{Matrix2x3, Matrix3, Rotation3, SMatrix, SVector, Vector2, Vector3};

/// The plane geometry known a priori.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundPlane {
    /// Unit normal in camera 0, pointing from the camera towards the ground.
    pub normal: Vector3<f64>,
    /// Perpendicular camera–plane distance, m.
    pub distance_m: f64,
}

/// Depth of the plane point seen along `x0`, or `None` when the ray misses the plane.
#[inline]
pub fn plane_depth(g: &GroundPlane, x0: &Vector3<f64>) -> Option<f64> {
    let c = g.normal.dot(x0);
    (c > 1e-6).then(|| g.distance_m / c)
}

/// Predicted normalized point in camera 1 for the plane point along `x0`.
#[inline]
pub fn plane_transfer(
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
    n: &Vector3<f64>,
    d: f64,
    x0: &Vector3<f64>,
) -> Option<Vector2<f64>> {
    let c = n.dot(x0);
    if c <= 1e-6 {
        return None;
    }
    let p = r * x0 + t * (c / d);
    (p.z > 1e-9).then(|| Vector2::new(p.x / p.z, p.y / p.z))
}

/// Transfer error² (normalized units²) of one correspondence, infinite when the ray misses.
#[inline]
pub fn transfer_err_sq(
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
    g: &GroundPlane,
    x0: &Vector3<f64>,
    x1: &Vector3<f64>,
) -> f64 {
    match plane_transfer(r, t, &g.normal, g.distance_m, x0) {
        Some(p) => (p.x - x1.x).powi(2) + (p.y - x1.y).powi(2),
        None => f64::INFINITY,
    }
}

/// Least-squares metric `t` given `R` from the selected correspondences: two rows of
/// `[x1]× t = −z0 [x1]× R x0` per point. `None` if singular.
pub fn solve_translation(
    r: &Matrix3<f64>,
    g: &GroundPlane,
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    idx: &[usize],
) -> Option<Vector3<f64>> {
    let mut ata = Matrix3::zeros();
    let mut atb = Vector3::zeros();
    for &i in idx {
        let z0 = plane_depth(g, &x0[i])?;
        let (u, v) = (x1[i].x, x1[i].y);
        let a = Matrix2x3::new(0.0, -1.0, v, 1.0, 0.0, -u);
        let q = r * x0[i] * z0;
        let b = -(a * q);
        ata += a.transpose() * a;
        atb += a.transpose() * b;
    }
    ata.cholesky().map(|c| c.solve(&atb))
}

/// Result of the plane refinement.
#[derive(Debug, Clone)]
pub struct PlaneFit {
    /// `cam1_from_cam0`.
    pub r: Matrix3<f64>,
    /// Metric translation (camera 1), m.
    pub t: Vector3<f64>,
    /// Refined ground normal (camera 0).
    pub normal: Vector3<f64>,
    /// Covariance of `[δθ; t]` (rad², m²) from the Gauss–Newton normal matrix, with the
    /// residual scale of the data.
    pub cov: SMatrix<f64, 6, 6>,
    /// RMS transfer residual, normalized units.
    pub rms: f64,
}

/// Gauss–Newton over `(δθ, t, δn)` on the inliers' transfer errors, with the normal tied to its
/// prior by `normal_sigma_rad`. `sigma_floor` bounds the residual scale used in the covariance
/// from below (normalized units).
#[allow(clippy::too_many_arguments)] // geometry, prior, data and settings
pub fn refine_plane(
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
    g: &GroundPlane,
    normal_sigma_rad: f64,
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    idx: &[usize],
    iterations: usize,
    sigma_floor: f64,
) -> Option<PlaneFit> {
    type V8 = SVector<f64, 8>;
    type M8 = SMatrix<f64, 8, 8>;
    let (nb1, nb2) = crate::essential::tangent_basis(&g.normal);
    let (mut r, mut t, mut n) = (*r, *t, g.normal);
    let d = g.distance_m;
    let apply = |r: &Matrix3<f64>, t: &Vector3<f64>, n: &Vector3<f64>, s: &V8| {
        let rr = Rotation3::new(Vector3::new(s[0], s[1], s[2])).matrix() * r;
        let tt = t + Vector3::new(s[3], s[4], s[5]);
        let nn = (n + nb1 * s[6] + nb2 * s[7]).normalize();
        (rr, tt, nn)
    };
    let w_n = 1.0 / normal_sigma_rad.max(1e-9);
    // data rows weighted by 1/σ (σ = sigma_floor during the iterations) so the normal prior,
    // in units of its own σ, has the right relative weight
    let w_d2 = 1.0 / (sigma_floor * sigma_floor).max(1e-30);
    let mut jtj = M8::zeros();
    let mut sum_r2 = 0.0;
    for it in 0..=iterations {
        jtj = M8::zeros();
        let mut jtr = V8::zeros();
        sum_r2 = 0.0;
        let eps = 1e-7;
        let pert: [(Matrix3<f64>, Vector3<f64>, Vector3<f64>); 8] = std::array::from_fn(|k| {
            let mut s = V8::zeros();
            s[k] = eps;
            apply(&r, &t, &n, &s)
        });
        for &i in idx {
            let p0 = plane_transfer(&r, &t, &n, d, &x0[i])?;
            let res = p0 - Vector2::new(x1[i].x, x1[i].y);
            sum_r2 += res.norm_squared();
            let mut jac = SMatrix::<f64, 2, 8>::zeros();
            for (k, (rk, tk, nk)) in pert.iter().enumerate() {
                let pk = plane_transfer(rk, tk, nk, d, &x0[i])?;
                jac.set_column(k, &((pk - p0) / eps));
            }
            jtj += jac.transpose() * jac;
            jtr += jac.transpose() * res;
        }
        if it == iterations {
            break;
        }
        jtj *= w_d2;
        jtr *= w_d2;
        // prior on the normal: residual w_n · (tangent components of n − n_prior)
        let dn = n - g.normal;
        let pr = Vector2::new(nb1.dot(&dn), nb2.dot(&dn)) * w_n;
        for k in 0..2 {
            jtj[(6 + k, 6 + k)] += w_n * w_n;
            jtr[6 + k] += w_n * pr[k];
        }
        let step = (jtj + M8::identity() * 1e-15).cholesky()?.solve(&(-jtr));
        (r, t, n) = apply(&r, &t, &n, &step);
        if step.norm() < 1e-12 {
            break;
        }
    }
    let m = idx.len().max(1) as f64;
    let dof = (2.0 * m - 6.0).max(1.0);
    let sigma2 = (sum_r2 / dof).max(sigma_floor * sigma_floor);
    // last pass left the unweighted data normal matrix in `jtj`
    let mut info = jtj / sigma2;
    for k in 0..2 {
        info[(6 + k, 6 + k)] += w_n * w_n;
    }
    let cov8 = info.try_inverse()?;
    let cov = cov8.fixed_view::<6, 6>(0, 0).into_owned();
    Some(PlaneFit {
        r,
        t,
        normal: n,
        cov,
        rms: (sum_r2 / m).sqrt(),
    })
}
