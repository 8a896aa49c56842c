//! The paper's egomotion maths (section IV-B..D): the 8-point essential matrix on normalized
//! coordinates (eqs. 13–17), the Huang–Faugeras factorization (eqs. 18–20), cheirality by
//! triangulation with no depth cut-off, and the first-order covariance (eqs. 22–28).
//!
//! Points are normalized undistorted image coordinates `x = (u, v, 1)`; `x0` in camera 0,
//! `x1` in camera 1, and the motion is `X1 = R X0 + t`, so `x1ᵀ E x0 = 0` with `E = [t]× R`.

use nalgebra::{
    Matrix3, Rotation3, SMatrix, SVector, SymmetricEigen, Unit, UnitQuaternion, Vector3,
};
use uavnav_core::rotation::skew;

/// 9-vector (column-major `E`, eq. 13).
pub type Vec9 = SVector<f64, 9>;
/// 9×9 matrix.
pub type Mat9 = SMatrix<f64, 9, 9>;

/// One row of `A` (eq. 15) for the correspondence `x0 ↔ x1`: coefficient of `E_ij` is
/// `x1_i x0_j`, stored column-major like `e`.
#[inline]
pub fn design_row(x0: &Vector3<f64>, x1: &Vector3<f64>) -> Vec9 {
    let (u, v, up, vp) = (x0.x, x0.y, x1.x, x1.y);
    Vec9::from_column_slice(&[u * up, u * vp, u, v * up, v * vp, v, up, vp, 1.0])
}

/// Solution of eq. 16: the unit eigenvector `h` of `AᵀA` with the smallest eigenvalue, plus the
/// full eigen-decomposition (needed by the covariance, eq. 26).
///
/// "Normalized" 8-point: before building `A`, each image's points are translated to their
/// centroid and scaled to a mean distance of √2 (`x' = T x`, Hartley), which keeps `AᵀA`
/// well conditioned; `E = T1ᵀ E' T0` maps the solution back.
#[derive(Debug, Clone)]
pub struct EightPoint {
    /// Eigenvalues of `A'ᵀA'` (conditioned coordinates), ascending.
    pub eigenvalues: Vec9,
    /// Matching eigenvectors (columns).
    pub eigenvectors: Mat9,
    /// Conditioning transform of image 0.
    pub t0: Matrix3<f64>,
    /// Conditioning transform of image 1.
    pub t1: Matrix3<f64>,
}

impl EightPoint {
    /// `h'` (unit, eq. 16) in conditioned coordinates.
    pub fn h_conditioned(&self) -> Vec9 {
        self.eigenvectors.column(0).into_owned()
    }

    /// The linear map `vec(E) = K vec(E')`, `K = T0ᵀ ⊗ T1ᵀ` (column-major vec).
    pub fn uncondition_map(&self) -> Mat9 {
        let (a, b) = (self.t0.transpose(), self.t1.transpose());
        Mat9::from_fn(|r, c| a[(r / 3, c / 3)] * b[(r % 3, c % 3)])
    }

    /// `h = vec(E)/‖vec(E)‖` in normalized image coordinates.
    pub fn h(&self) -> Vec9 {
        (self.uncondition_map() * self.h_conditioned()).normalize()
    }

    /// `E = √2 · mat(h)` (eq. 17) — the √2 makes the two non-zero singular values ≈ 1.
    pub fn essential(&self) -> Matrix3<f64> {
        Matrix3::from_column_slice(self.h().as_slice()) * std::f64::consts::SQRT_2
    }
}

/// Isotropic conditioning transform of the selected points.
fn conditioning(x: &[Vector3<f64>], idx: &[usize]) -> Matrix3<f64> {
    let n = idx.len() as f64;
    let (mut cx, mut cy) = (0.0, 0.0);
    for &i in idx {
        cx += x[i].x;
        cy += x[i].y;
    }
    let (cx, cy) = (cx / n, cy / n);
    let mean_d = idx
        .iter()
        .map(|&i| ((x[i].x - cx).powi(2) + (x[i].y - cy).powi(2)).sqrt())
        .sum::<f64>()
        / n;
    let s = if mean_d > 1e-12 {
        std::f64::consts::SQRT_2 / mean_d
    } else {
        1.0
    };
    Matrix3::new(s, 0.0, -s * cx, 0.0, s, -s * cy, 0.0, 0.0, 1.0)
}

#[inline]
fn apply(t: &Matrix3<f64>, x: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(
        t[(0, 0)] * x.x + t[(0, 2)],
        t[(1, 1)] * x.y + t[(1, 2)],
        1.0,
    )
}

/// Builds `A'ᵀA'` from the selected correspondences and solves eq. 16. `None` with fewer than 8.
pub fn eight_point(x0: &[Vector3<f64>], x1: &[Vector3<f64>], idx: &[usize]) -> Option<EightPoint> {
    if idx.len() < 8 {
        return None;
    }
    let (t0, t1) = (conditioning(x0, idx), conditioning(x1, idx));
    let mut m = Mat9::zeros();
    for &i in idx {
        let a = design_row(&apply(&t0, &x0[i]), &apply(&t1, &x1[i]));
        m.syger(1.0, &a, &a, 1.0);
    }
    let eig = SymmetricEigen::new(m);
    let mut order: [usize; 9] = [0, 1, 2, 3, 4, 5, 6, 7, 8];
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let mut vals = Vec9::zeros();
    let mut vecs = Mat9::zeros();
    for (k, &o) in order.iter().enumerate() {
        vals[k] = eig.eigenvalues[o];
        vecs.set_column(k, &eig.eigenvectors.column(o));
    }
    Some(EightPoint {
        eigenvalues: vals,
        eigenvectors: vecs,
        t0,
        t1,
    })
}

/// Sampson distance² of a correspondence to the epipolar constraint (normalized units²).
#[inline]
pub fn sampson_sq(e: &Matrix3<f64>, x0: &Vector3<f64>, x1: &Vector3<f64>) -> f64 {
    let ex0 = e * x0;
    let etx1 = e.tr_mul(x1);
    let r = x1.dot(&ex0);
    let den = ex0.x * ex0.x + ex0.y * ex0.y + etx1.x * etx1.x + etx1.y * etx1.y;
    if den <= 1e-300 {
        f64::INFINITY
    } else {
        r * r / den
    }
}

/// The four factorizations `E = [t]× R` (eqs. 18–20): `R = β U R0 Vᵀ` or `β U R0ᵀ Vᵀ`,
/// `t = ±u₃` (unit). `β` is folded in by making `U`, `V` proper rotations.
pub fn factorize(e: &Matrix3<f64>) -> [(Matrix3<f64>, Vector3<f64>); 4] {
    let svd = e.svd(true, true);
    let mut u = svd.u.unwrap_or_else(Matrix3::identity);
    let mut vt = svd.v_t.unwrap_or_else(Matrix3::identity);
    // nalgebra does not sort singular values: put the smallest last.
    let s = svd.singular_values;
    let k = (0..3).min_by(|&a, &b| s[a].total_cmp(&s[b])).unwrap_or(2);
    if k != 2 {
        u.swap_columns(k, 2);
        vt.swap_rows(k, 2);
    }
    if u.determinant() < 0.0 {
        u = -u;
    }
    if vt.determinant() < 0.0 {
        vt = -vt;
    }
    let w = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
    let r1 = u * w * vt;
    let r2 = u * w.transpose() * vt;
    let t: Vector3<f64> = u.column(2).into_owned();
    [(r1, t), (r1, -t), (r2, t), (r2, -t)]
}

/// Depths `(z0, z1)` of the triangulated point (least squares on `z1 x1 = z0 R x0 + t`).
#[inline]
pub fn triangulate_depths(
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
    x0: &Vector3<f64>,
    x1: &Vector3<f64>,
) -> (f64, f64) {
    let a = r * x0;
    // [a, -x1] [z0; z1] = -t
    let (aa, ab, bb) = (a.dot(&a), -a.dot(x1), x1.dot(x1));
    let (ra, rb) = (-a.dot(t), x1.dot(t));
    let det = aa * bb - ab * ab;
    if det.abs() < 1e-300 {
        return (0.0, 0.0);
    }
    ((bb * ra - ab * rb) / det, (aa * rb - ab * ra) / det)
}

/// Counts correspondences triangulated in front of both cameras. No depth cut-off: points here
/// are 100–1000 baselines away, and a far point is still in front (a cut would reject all).
pub fn cheirality_votes(
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    idx: &[usize],
) -> usize {
    idx.iter()
        .filter(|&&i| {
            let (z0, z1) = triangulate_depths(r, t, &x0[i], &x1[i]);
            z0 > 0.0 && z1 > 0.0
        })
        .count()
}

/// Picks the factorization with the most points in front (ties: the first).
pub fn best_factorization(
    e: &Matrix3<f64>,
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    idx: &[usize],
) -> (Matrix3<f64>, Vector3<f64>, usize) {
    let mut best = (Matrix3::identity(), Vector3::z(), 0usize);
    let mut best_votes = None;
    for (r, t) in factorize(e) {
        let v = cheirality_votes(&r, &t, x0, x1, idx);
        if best_votes.is_none_or(|b| v > b) {
            best_votes = Some(v);
            best = (r, t, v);
        }
    }
    best
}

/// Rotation-vector difference `log(Ra · Rbᵀ)` (the `δθ` of `Ra = Exp(δθ) Rb`).
pub fn rot_diff(ra: &Matrix3<f64>, rb: &Matrix3<f64>) -> Vector3<f64> {
    // via the quaternion: robust when the product is only nearly orthonormal
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(ra * rb.transpose()))
        .scaled_axis()
}

/// First-order covariance of `h` (eqs. 22–28). With `M = AᵀA = Σ aᵢaᵢᵀ`, eigenpairs
/// `(λₖ, sₖ)` ascending and `h = s₁`, a perturbation gives
/// `δh = −S Δ Sᵀ δM h`, `Δ = diag(0, 1/(λ₂−λ₁), …)` (eq. 26), and
/// `δM h = Σᵢ [(aᵢᵀh) I + aᵢ hᵀ] δaᵢ` (the `[Fᵢⱼ] + [Gᵢⱼ]` of eqs. 24–25). Each `aᵢ` depends
/// on the four image coordinates with independent noise `σ²` (`σ` in normalized units), which
/// gives the block `Σᵢ = σ² Jᵢ Jᵢᵀ` of eq. 27. Returns `Σh` (`Σe = 2 Σh`, eq. 22).
///
/// Computed in the conditioned coordinates (noise scaled by each image's conditioning scale),
/// then mapped to `h = K h' / ‖K h'‖`.
pub fn covariance_h(
    ep: &EightPoint,
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    idx: &[usize],
    sigma: f64,
) -> Mat9 {
    let h = ep.h_conditioned();
    let s = &ep.eigenvectors;
    let mut delta = Mat9::zeros();
    for k in 1..9 {
        let gap = ep.eigenvalues[k] - ep.eigenvalues[0];
        delta[(k, k)] = if gap > 1e-300 { 1.0 / gap } else { 0.0 };
    }
    let p = s * delta * s.transpose();
    let mut acc = Mat9::zeros();
    for &i in idx {
        let (c0, c1) = (apply(&ep.t0, &x0[i]), apply(&ep.t1, &x1[i]));
        let (u, v, up, vp) = (c0.x, c0.y, c1.x, c1.y);
        let a = design_row(&c0, &c1);
        let ah = a.dot(&h);
        // Jᵢ: ∂a/∂(u, v, u', v')
        let mut j = SMatrix::<f64, 9, 4>::zeros();
        j[(0, 0)] = up;
        j[(1, 0)] = vp;
        j[(2, 0)] = 1.0;
        j[(3, 1)] = up;
        j[(4, 1)] = vp;
        j[(5, 1)] = 1.0;
        j[(0, 2)] = u;
        j[(3, 2)] = v;
        j[(6, 2)] = 1.0;
        j[(1, 3)] = u;
        j[(4, 3)] = v;
        j[(7, 3)] = 1.0;
        let mut cj = j * ah + a * (h.transpose() * j);
        // image noise σ in normalized units becomes s·σ in conditioned units
        for c in 0..2 {
            cj.column_mut(c).scale_mut(ep.t0[(0, 0)] * sigma);
            cj.column_mut(c + 2).scale_mut(ep.t1[(0, 0)] * sigma);
        }
        acc += cj * cj.transpose();
    }
    let cov_hc = p * acc * p.transpose();
    let k = ep.uncondition_map();
    let e = k * h;
    let en = e.norm();
    let hn = e / en;
    let jn = (Mat9::identity() - hn * hn.transpose()) / en;
    let m = jn * k;
    m * cov_hc * m.transpose()
}

/// Propagates `Σh` through the factorization to `[δθ; δt]` (6×6) by a central-difference
/// Jacobian of `h ↦ (R, t)` that follows the chosen branch `(r, t)`.
pub fn propagate_to_motion(
    h: &Vec9,
    cov_h: &Mat9,
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
) -> SMatrix<f64, 6, 6> {
    let eps = 1e-6;
    let mut jac = SMatrix::<f64, 6, 9>::zeros();
    for k in 0..9 {
        let mut f = [SVector::<f64, 6>::zeros(); 2];
        for (slot, sgn) in [1.0, -1.0].iter().enumerate() {
            let mut hp = *h;
            hp[k] += sgn * eps;
            let e = Matrix3::from_column_slice(hp.as_slice());
            let (rp, tp) = nearest_branch(&e, r, t);
            let dth = rot_diff(&rp, r);
            let dt = tp - t;
            f[slot] =
                SVector::<f64, 6>::from_column_slice(&[dth.x, dth.y, dth.z, dt.x, dt.y, dt.z]);
        }
        jac.set_column(k, &((f[0] - f[1]) / (2.0 * eps)));
    }
    jac * cov_h * jac.transpose()
}

/// The factorization of `e` closest to a reference branch.
fn nearest_branch(
    e: &Matrix3<f64>,
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
) -> (Matrix3<f64>, Vector3<f64>) {
    let mut best = (*r, *t);
    let mut best_d = f64::INFINITY;
    for (rc, tc) in factorize(e) {
        let d = rot_diff(&rc, r).norm() + (tc - t).norm();
        if d < best_d {
            best_d = d;
            best = (rc, tc);
        }
    }
    best
}

/// Tangent basis (two unit vectors ⟂ `t`).
pub fn tangent_basis(t: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let a = if t.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let b1 = t.cross(&a).normalize();
    let b2 = t.cross(&b1).normalize();
    (b1, b2)
}

/// Gauss–Newton refinement of `(R, t̂)` minimizing the Sampson errors of the inliers
/// (beyond the paper: the linear 8-point is not the maximum-likelihood estimate).
pub fn refine_sampson(
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    idx: &[usize],
    iterations: usize,
) -> (Matrix3<f64>, Vector3<f64>) {
    gauss_newton_sampson(r, t, x0, x1, idx, iterations, None)
}

/// [`refine_sampson`] with Cauchy weights (iteratively reweighted): each iteration weighs a
/// residual `d` by `1 / (1 + (d/c)²)`, `c = 2.385 σ̂` (95 % efficiency under Gaussian noise),
/// `σ̂ = 1.4826 · median |d|` over `idx`, floored at `sigma_floor` (normalized units).
///
/// Why: the inlier threshold of the robust search is loose compared with the accuracy of good
/// KLT tracks (≈ 0.1–0.2 px against 1 px), and under forward motion the rotation and the focus
/// of expansion trade off so that a few biased tracks inside the threshold (near features that
/// changed scale, road texture) tilt a least-squares fit by tenths of a degree. Each such track
/// keeps at most the influence of a track at `c`. `buf` is reused for the residuals.
#[allow(clippy::too_many_arguments)] // the refinement's inputs are all distinct
pub fn refine_sampson_robust(
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    idx: &[usize],
    iterations: usize,
    sigma_floor: f64,
    buf: &mut Vec<f64>,
) -> (Matrix3<f64>, Vector3<f64>) {
    gauss_newton_sampson(r, t, x0, x1, idx, iterations, Some((sigma_floor, buf)))
}

/// Signed Sampson residual of `x0 ↔ x1` under `e` (normalized units).
#[inline]
fn sampson_residual(e: &Matrix3<f64>, x0: &Vector3<f64>, x1: &Vector3<f64>) -> f64 {
    let ex0 = e * x0;
    let etx1 = e.tr_mul(x1);
    let den = (ex0.x * ex0.x + ex0.y * ex0.y + etx1.x * etx1.x + etx1.y * etx1.y).max(1e-300);
    x1.dot(&ex0) / den.sqrt()
}

/// The Gauss–Newton loop of [`refine_sampson`] and [`refine_sampson_robust`] (finite-difference
/// Jacobians on the 5-parameter manifold: rotation vector and two tangent directions of `t̂`).
fn gauss_newton_sampson(
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    idx: &[usize],
    iterations: usize,
    mut robust: Option<(f64, &mut Vec<f64>)>,
) -> (Matrix3<f64>, Vector3<f64>) {
    let (mut r, mut t) = (*r, t.normalize());
    let eps = 1e-7;
    for _ in 0..iterations {
        let (b1, b2) = tangent_basis(&t);
        let apply = |d: &SVector<f64, 5>| -> (Matrix3<f64>, Vector3<f64>) {
            let rr = Rotation3::new(Vector3::new(d[0], d[1], d[2])).matrix() * r;
            let tt = (t + b1 * d[3] + b2 * d[4]).normalize();
            (rr, tt)
        };
        // the essential matrices of the estimate and of its five perturbations, once per
        // iteration (not once per point)
        let e0 = skew(&t) * r;
        let mut ek = [Matrix3::zeros(); 5];
        for (k, e) in ek.iter_mut().enumerate() {
            let mut d = SVector::<f64, 5>::zeros();
            d[k] = eps;
            let (rk, tk) = apply(&d);
            *e = skew(&tk) * rk;
        }
        // Cauchy scale from the current residuals
        let c2 = match robust.as_mut() {
            Some((floor, buf)) => {
                buf.clear();
                buf.extend(
                    idx.iter()
                        .map(|&i| sampson_residual(&e0, &x0[i], &x1[i]).abs()),
                );
                if buf.is_empty() {
                    break;
                }
                let mid = buf.len() / 2;
                let med = *buf.select_nth_unstable_by(mid, f64::total_cmp).1;
                let c = 2.385 * (1.4826 * med).max(*floor);
                Some(c * c)
            }
            None => None,
        };
        let mut jtj = SMatrix::<f64, 5, 5>::zeros();
        let mut jtr = SVector::<f64, 5>::zeros();
        for &i in idx {
            let r0 = sampson_residual(&e0, &x0[i], &x1[i]);
            let mut g = SVector::<f64, 5>::zeros();
            for (k, e) in ek.iter().enumerate() {
                g[k] = (sampson_residual(e, &x0[i], &x1[i]) - r0) / eps;
            }
            let w = c2.map_or(1.0, |c2| 1.0 / (1.0 + r0 * r0 / c2));
            jtj += g * g.transpose() * w;
            jtr += g * (r0 * w);
        }
        let Some(step) = (jtj + SMatrix::<f64, 5, 5>::identity() * 1e-12)
            .cholesky()
            .map(|c| c.solve(&(-jtr)))
        else {
            break;
        };
        let (rn, tn) = apply(&step);
        r = rn;
        t = tn;
        if step.norm() < 1e-10 {
            break;
        }
    }
    (r, t)
}

/// Converts a rotation matrix to a unit quaternion.
pub fn to_quat(r: &Matrix3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(r))
}

/// Unit vector wrapper.
pub fn unit(v: &Vector3<f64>) -> Unit<Vector3<f64>> {
    Unit::new_normalize(*v)
}
