//! Egomotion from normalized correspondences: the per-frame solver choice.
//!
//! Rule (documented in [`Method`]):
//! 1. fit a pure rotation robustly; if the median residual parallax after it is below
//!    `static_parallax_px`, and the prior's translation does not move the ground by more than
//!    that either, the camera did not translate measurably → `RotationOnly`, `t_dir_cam1 = None`;
//! 2. `Plane` when asked, or under `Auto` when the prior has a ground normal and distance and the
//!    plane model explains at least `plane_min_inlier_fraction` of the tracks;
//! 3. otherwise the paper's `Essential` solver (8-point in RANSAC+LO, Huang–Faugeras,
//!    cheirality, covariance of IV-D, then a Sampson Gauss–Newton polish).

use std::fmt;
use std::str::FromStr;

use nalgebra::{Matrix3, Matrix6, Vector3};
use uavnav_core::rng::Rng;
use uavnav_core::{EgomotionSolver, MotionPrior};

use crate::NoMeasurement;
use crate::essential::{
    best_factorization, covariance_h, eight_point, propagate_to_motion, refine_sampson_robust,
    sampson_sq,
};
use crate::plane::{GroundPlane, refine_plane, transfer_err_sq};
use crate::robust::{
    HISTORY, RansacParams, ransac_essential, ransac_plane, ransac_rotation, rotation_err_sq,
};
use uavnav_core::rotation::skew;

/// Which solver to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Method {
    /// Always the paper's essential-matrix solver.
    Essential,
    /// Always the plane-aware solver (needs a ground prior, else no measurement).
    Plane,
    /// Plane when a ground prior exists and the plane explains the tracks, else essential.
    #[default]
    Auto,
}

impl FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "essential" => Ok(Method::Essential),
            "plane" => Ok(Method::Plane),
            "auto" => Ok(Method::Auto),
            other => Err(format!(
                "unknown method {other:?} (expected essential, plane or auto)"
            )),
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Method::Essential => "essential",
            Method::Plane => "plane",
            Method::Auto => "auto",
        })
    }
}

/// Solver settings (all angles/thresholds in pixels are converted with the focal length).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveParams {
    /// Solver choice. Default `Auto`.
    pub method: Method,
    /// Inlier threshold, px. Default 1.0.
    pub ransac_threshold_px: f64,
    /// RANSAC hypothesis cap. Default 200.
    pub ransac_max_iterations: usize,
    /// RANSAC confidence. Default 0.999.
    pub ransac_confidence: f64,
    /// Minimum inliers for a measurement. Default 15.
    pub min_inliers: usize,
    /// Median parallax below which the motion is reported rotation-only, px. Default 0.25.
    pub static_parallax_px: f64,
    /// Fraction of tracks the plane model must explain under `Auto`. Default 0.7.
    pub plane_min_inlier_fraction: f64,
    /// 1-σ of the prior ground normal, rad. Default 2°.
    pub normal_sigma_rad: f64,
    /// Gauss–Newton iterations of the final refinements. Default 5.
    pub refine_iterations: usize,
    /// Lower bound of the image noise used in covariances, px. Default 0.05. Every solver scales
    /// its covariance by the image noise estimated from its own residuals (KLT on the simulated
    /// paper flights: ≈ 0.09 px); this floor only guards against near-zero residuals.
    /// (It was 0.3 px, which made the covariances ≈ 11× too large in variance: measured NEES
    /// 0.25 for 3 expected.)
    pub pixel_sigma_px: f64,
    /// Relative 1-σ of the plane solver's metric scale beyond the image noise, added to the
    /// translation covariance as `σ² t tᵀ`. The solver takes the ground distance and the terrain
    /// plane as exact; on the simulated paper flights the scale error is 0.7 % rms and only
    /// weakly tied to the height error, and without this term the along-track translation /
    /// pitch-rotation pair is 6–14× overconfident in its thin direction. Default 0.005.
    pub metric_scale_sigma: f64,
}

impl Default for SolveParams {
    fn default() -> Self {
        Self {
            method: Method::Auto,
            ransac_threshold_px: 1.0,
            ransac_max_iterations: 200,
            ransac_confidence: 0.999,
            min_inliers: 15,
            static_parallax_px: 0.25,
            plane_min_inlier_fraction: 0.7,
            normal_sigma_rad: 2f64.to_radians(),
            refine_iterations: 5,
            pixel_sigma_px: 0.05,
            metric_scale_sigma: 0.005,
        }
    }
}

/// A solved relative motion (times and track count are added by the caller).
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// `cam1_from_cam0`.
    pub r: Matrix3<f64>,
    /// Unit translation direction, `None` for rotation-only.
    pub t_dir: Option<Vector3<f64>>,
    /// Metric translation when known.
    pub t_m: Option<Vector3<f64>>,
    /// Joint covariance `[δθ; δt]`.
    pub cov: Matrix6<f64>,
    /// Inliers.
    pub inliers: usize,
    /// Quality in [0, 1].
    pub quality: f64,
    /// Solver used.
    pub solver: EgomotionSolver,
}

/// Reused buffers for [`solve`].
#[derive(Debug, Default)]
pub struct SolveScratch {
    /// Inlier indices of the last solution.
    pub inliers: Vec<usize>,
    tmp: Vec<usize>,
    errs: Vec<f64>,
    /// Successive RANSAC bests of the essential solver.
    cands: Vec<Matrix3<f64>>,
}

/// Solves the egomotion for correspondences `x0[i] ↔ x1[i]` (normalized, undistorted).
/// `focal_px` converts pixel thresholds.
pub fn solve(
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    prior: &MotionPrior,
    focal_px: f64,
    p: &SolveParams,
    rng: &mut Rng,
    s: &mut SolveScratch,
) -> Result<Solution, NoMeasurement> {
    let n = x0.len();
    let thr = p.ransac_threshold_px / focal_px;
    let sigma_floor = p.pixel_sigma_px / focal_px;
    let rp = RansacParams {
        threshold: thr,
        max_iterations: p.ransac_max_iterations,
        confidence: p.ransac_confidence,
    };
    let r_prior = prior
        .cam1_from_cam0
        .map(|q| *q.to_rotation_matrix().matrix());
    // 1. rotation-only test
    let r_rot = ransac_rotation(x0, x1, r_prior.as_ref(), &rp, rng, &mut s.inliers);
    s.errs.clear();
    s.errs
        .extend((0..n).map(|i| rotation_err_sq(&r_rot, &x0[i], &x1[i])));
    let mid = n / 2;
    let median_parallax = if n > 0 {
        s.errs.select_nth_unstable_by(mid, f64::total_cmp).1.sqrt()
    } else {
        0.0
    };
    // Over a flat ground a small translation moves the image almost as a rotation does (the
    // plane-induced flow `t nᵀx / d` is nearly uniform near the optical axis), so a rotation
    // fit absorbs it and leaves little residual parallax: the "rotation" is then off by about
    // `|t| / d` while its covariance, from the residuals of ~200 points, claims far less
    // (a simulated hovering multirotor: rotation NEES median 9.8 for 3, 40 % of them gated, the
    // attitude 91 % within 3σ). When the prior predicts a translation that moves the ground by
    // more than the threshold, the plane solver, which estimates both, is used instead.
    let ground_flow_px = match (prior.t_cam1_m, prior.ground_distance_m) {
        (Some(t), Some(d)) if d.is_finite() && d > 0.0 => t.norm() / d * focal_px,
        _ => 0.0,
    };
    if median_parallax * focal_px < p.static_parallax_px && ground_flow_px < p.static_parallax_px {
        if s.inliers.len() < p.min_inliers {
            return Err(NoMeasurement::TooFewInliers {
                inliers: s.inliers.len() as u32,
            });
        }
        return Ok(rotation_only(&r_rot, x0, x1, &s.inliers, sigma_floor));
    }
    let ground = match (prior.ground_normal_cam0, prior.ground_distance_m) {
        (Some(nrm), Some(d)) if d.is_finite() && d > 0.0 => Some(GroundPlane {
            normal: nrm.into_inner(),
            distance_m: d,
        }),
        _ => None,
    };
    // 2. plane
    match (p.method, ground) {
        (Method::Plane, None) => return Err(NoMeasurement::NoGroundPrior),
        (Method::Plane | Method::Auto, Some(g)) => {
            let seed = r_prior.unwrap_or(r_rot);
            let fit = plane_solve(x0, x1, &seed, &g, p, &rp, sigma_floor, rng, s);
            let need = if p.method == Method::Auto {
                (p.plane_min_inlier_fraction * n as f64).ceil() as usize
            } else {
                0
            };
            match fit {
                Some(sol) if sol.inliers >= p.min_inliers.max(need) => return Ok(sol),
                _ if p.method == Method::Plane => {
                    return Err(NoMeasurement::Degenerate("plane model found no consensus"));
                }
                _ => {}
            }
        }
        _ => {}
    }
    // 3. essential
    essential_solve(x0, x1, r_prior.as_ref(), p, &rp, sigma_floor, rng, s)
}

/// Image noise (normalized units, per coordinate) estimated from the Sampson residuals of the
/// motion `(r, t)`: with noise σ on each coordinate of both images, E[Sampson²] = σ², and five
/// degrees of freedom are fitted.
fn sampson_sigma(
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    idx: &[usize],
) -> f64 {
    let e = uavnav_core::rotation::skew(t) * r;
    let sum: f64 = idx
        .iter()
        .map(|&i| sampson_sq(&e, &x0[i], &x1[i]))
        .filter(|d| d.is_finite())
        .sum();
    (sum / (idx.len() as f64 - 5.0).max(1.0)).sqrt()
}

fn quality(inliers: usize, n: usize) -> f64 {
    let ratio = inliers as f64 / n.max(1) as f64;
    (ratio * (inliers as f64 / 100.0).min(1.0)).clamp(0.0, 1.0)
}

fn rotation_only(
    r: &Matrix3<f64>,
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    idx: &[usize],
    sigma_floor: f64,
) -> Solution {
    // information of δθ from bearing residuals: Σ (I − b bᵀ) / σ²
    let mut info = Matrix3::zeros();
    let mut sum2 = 0.0;
    for &i in idx {
        let b = (r * x0[i]).normalize();
        info += Matrix3::identity() - b * b.transpose();
        sum2 += rotation_err_sq(r, &x0[i], &x1[i]);
    }
    let m = idx.len().max(1) as f64;
    let sigma2 = (sum2 / (2.0 * m - 3.0).max(1.0)).max(sigma_floor * sigma_floor);
    let rot_cov = info
        .try_inverse()
        .unwrap_or_else(|| Matrix3::identity() * 1e6)
        * sigma2;
    let mut cov = Matrix6::zeros();
    cov.fixed_view_mut::<3, 3>(0, 0).copy_from(&rot_cov);
    Solution {
        r: *r,
        t_dir: None,
        t_m: None,
        cov,
        inliers: idx.len(),
        quality: quality(idx.len(), x0.len()),
        solver: EgomotionSolver::RotationOnly,
    }
}

#[allow(clippy::too_many_arguments)]
fn plane_solve(
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    seed: &Matrix3<f64>,
    g: &GroundPlane,
    p: &SolveParams,
    rp: &RansacParams,
    sigma_floor: f64,
    rng: &mut Rng,
    s: &mut SolveScratch,
) -> Option<Solution> {
    // The seed rotation may be a little off (gyro drift): a loose first threshold, then refine.
    let loose = RansacParams {
        threshold: rp.threshold * 3.0,
        ..*rp
    };
    let t0 = ransac_plane(x0, x1, seed, g, &loose, rng, &mut s.inliers)?;
    if s.inliers.len() < 6 {
        return None;
    }
    let mut fit = refine_plane(
        seed,
        &t0,
        g,
        p.normal_sigma_rad,
        x0,
        x1,
        &s.inliers,
        p.refine_iterations,
        sigma_floor,
    )?;
    for _ in 0..2 {
        // Weigh the data against the normal prior with the image noise of the previous fit
        // (rms over two coordinates), not the floor, so the prior keeps its intended weight.
        let sigma_w = (fit.rms / std::f64::consts::SQRT_2).max(sigma_floor);
        let g2 = GroundPlane {
            normal: fit.normal,
            distance_m: g.distance_m,
        };
        let thr2 = rp.threshold * rp.threshold;
        s.inliers.clear();
        s.inliers.extend(
            (0..x0.len()).filter(|&i| transfer_err_sq(&fit.r, &fit.t, &g2, &x0[i], &x1[i]) < thr2),
        );
        if s.inliers.len() < 6 {
            return None;
        }
        fit = refine_plane(
            &fit.r,
            &fit.t,
            g,
            p.normal_sigma_rad,
            x0,
            x1,
            &s.inliers,
            p.refine_iterations,
            sigma_w,
        )?;
    }
    let tn = fit.t.norm();
    let mut cov = fit.cov;
    let scale_cov = fit.t * fit.t.transpose() * p.metric_scale_sigma.powi(2);
    cov.fixed_view_mut::<3, 3>(3, 3)
        .zip_apply(&scale_cov, |c, s| *c += s);
    Some(Solution {
        r: fit.r,
        t_dir: (tn > 1e-9).then(|| fit.t / tn),
        t_m: Some(fit.t),
        cov,
        inliers: s.inliers.len(),
        quality: quality(s.inliers.len(), x0.len()),
        solver: EgomotionSolver::Plane,
    })
}

#[allow(clippy::too_many_arguments)]
fn essential_solve(
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    r_prior: Option<&Matrix3<f64>>,
    p: &SolveParams,
    rp: &RansacParams,
    sigma_floor: f64,
    rng: &mut Rng,
    s: &mut SolveScratch,
) -> Result<Solution, NoMeasurement> {
    let thr2 = rp.threshold * rp.threshold;
    let found = ransac_essential(
        x0,
        x1,
        r_prior,
        rp,
        rng,
        &mut s.inliers,
        &mut s.tmp,
        &mut s.cands,
    );
    if found.is_none() {
        return Err(NoMeasurement::Degenerate("essential matrix: no consensus"));
    }
    if s.inliers.len() < p.min_inliers {
        return Err(NoMeasurement::TooFewInliers {
            inliers: s.inliers.len() as u32,
        });
    }
    let (r, t) = if p.refine_iterations == 0 {
        let ep =
            eight_point(x0, x1, &s.inliers).ok_or(NoMeasurement::Degenerate("8-point failed"))?;
        let (r_lin, t_lin, votes) = best_factorization(&ep.essential(), x0, x1, &s.inliers);
        if votes * 2 < s.inliers.len() {
            return Err(NoMeasurement::Degenerate(
                "cheirality: no factorization has most points in front",
            ));
        }
        (r_lin, t_lin)
    } else {
        refine_candidates(x0, x1, p, thr2, sigma_floor, s)?
    };
    // The paper's linear estimate (eqs. 13–17) and factorization (18–20) on the final inliers
    // give the covariance (IV-D); the reported motion is the refined one.
    let ep = eight_point(x0, x1, &s.inliers).ok_or(NoMeasurement::Degenerate("8-point failed"))?;
    let (r_lin, t_lin, _) = best_factorization(&ep.essential(), x0, x1, &s.inliers);
    let sigma = sampson_sigma(&r, &t, x0, x1, &s.inliers).max(sigma_floor);
    let cov_h = covariance_h(&ep, x0, x1, &s.inliers, sigma);
    let cov = propagate_to_motion(&ep.h(), &cov_h, &r_lin, &t_lin);
    Ok(Solution {
        r,
        t_dir: Some(t),
        t_m: None,
        cov,
        inliers: s.inliers.len(),
        quality: quality(s.inliers.len(), x0.len()),
        solver: EgomotionSolver::Essential,
    })
}

/// A refined candidate: `R`, `t̂` and its robust residual scale (normalized units).
type Fit = (Matrix3<f64>, Vector3<f64>, f64);

/// Refines each of the few lowest-cost RANSAC models (`s.cands`) and keeps the one that explains the
/// tracks best; leaves its inliers in `s.inliers`.
///
/// Each candidate: the 8-point on its inliers (eqs. 13–17), the factorization with most points
/// in front (18–20), then a robust (Cauchy) Sampson refinement and the inliers of the refined
/// motion, until that set settles. Why several: under forward motion with mostly far features
/// the rotation and the focus of expansion trade off, and a few consistent but wrong tracks
/// (aliased on lane dashes or rail sleepers, near features that changed scale) make a bent
/// motion a local optimum that a refinement started inside it does not leave; which optimum
/// the search ends in then depends on the RANSAC draws. The candidates are compared by the
/// MSAC cost truncated at 3σ̂ (σ̂: the smallest robust residual scale among them, between the
/// noise floor and the inlier threshold): the loose inlier threshold cannot tell a model that
/// fits the good tracks at ≈ 0.1 px from one that fits a few more at ≈ 0.5 px.
fn refine_candidates(
    x0: &[Vector3<f64>],
    x1: &[Vector3<f64>],
    p: &SolveParams,
    thr2: f64,
    sigma_floor: f64,
    s: &mut SolveScratch,
) -> Result<(Matrix3<f64>, Vector3<f64>), NoMeasurement> {
    let n = x0.len();
    // (R, t, robust residual scale) per usable candidate
    let mut fits: [Option<Fit>; HISTORY] = [None; HISTORY];
    let mut cheirality_failed = false;
    for (slot, k) in (0..s.cands.len()).rev().enumerate() {
        let e = s.cands[k];
        s.tmp.clear();
        s.tmp
            .extend((0..n).filter(|&i| sampson_sq(&e, &x0[i], &x1[i]) < thr2));
        if s.tmp.len() < p.min_inliers.max(8) {
            continue;
        }
        let (mut r, mut t, votes) = best_factorization(&e, x0, x1, &s.tmp);
        if votes * 2 < s.tmp.len() {
            cheirality_failed = true;
            continue;
        }
        for round in 0..3 {
            (r, t) = refine_sampson_robust(
                &r,
                &t,
                x0,
                x1,
                &s.tmp,
                p.refine_iterations,
                sigma_floor,
                &mut s.errs,
            );
            let e = skew(&t) * r;
            s.inliers.clear();
            s.inliers
                .extend((0..n).filter(|&i| sampson_sq(&e, &x0[i], &x1[i]) < thr2));
            if s.inliers == s.tmp || s.inliers.len() < p.min_inliers || round == 2 {
                break;
            }
            std::mem::swap(&mut s.tmp, &mut s.inliers);
        }
        let e = skew(&t) * r;
        s.errs.clear();
        s.errs
            .extend(s.tmp.iter().map(|&i| sampson_sq(&e, &x0[i], &x1[i]).sqrt()));
        let mid = s.errs.len() / 2;
        let med = *s.errs.select_nth_unstable_by(mid, f64::total_cmp).1;
        fits[slot] = Some((r, t, 1.4826 * med));
    }
    let sigma = fits
        .iter()
        .flatten()
        .map(|f| f.2)
        .fold(f64::INFINITY, f64::min);
    if !sigma.is_finite() {
        return Err(if cheirality_failed {
            NoMeasurement::Degenerate("cheirality: no factorization has most points in front")
        } else {
            NoMeasurement::TooFewInliers {
                inliers: s.inliers.len() as u32,
            }
        });
    }
    let tau2 = (3.0 * sigma.max(sigma_floor)).powi(2).min(thr2);
    let mut best: Option<(Matrix3<f64>, Vector3<f64>, f64)> = None;
    for (r, t, _) in fits.iter().flatten() {
        let e = skew(t) * r;
        let cost: f64 = (0..n)
            .map(|i| sampson_sq(&e, &x0[i], &x1[i]).min(tau2))
            .sum();
        if best.as_ref().is_none_or(|b| cost < b.2) {
            best = Some((*r, *t, cost));
        }
    }
    let Some((r, t, _)) = best else {
        return Err(NoMeasurement::Degenerate("essential matrix: no consensus"));
    };
    let e = skew(&t) * r;
    s.inliers.clear();
    s.inliers
        .extend((0..n).filter(|&i| sampson_sq(&e, &x0[i], &x1[i]) < thr2));
    if s.inliers.len() < p.min_inliers.max(8) {
        return Err(NoMeasurement::TooFewInliers {
            inliers: s.inliers.len() as u32,
        });
    }
    Ok((r, t))
}
