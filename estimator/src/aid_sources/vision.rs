//! Vision egomotion between camera frames 0 and 1, fused against the pose clone at frame 0 and the
//! state at frame 1 (stochastic cloning).
//!
//! With `C_k` = nav_from_body, `R_bc`/`t_bc` = body_from_cam, camera centres `c_k = p_k + C_k t_bc`:
//! - rotation (the relative form of the paper's delta-attitudes, eq. 34):
//!   `cam1_from_cam0 = R_bcᵀ C_1ᵀ C_0 R_bc`, residual `Log(R_meas R_predᵀ)` in camera-1;
//! - translation (eq. 35's direction of motion): `t = R_bcᵀ C_1ᵀ (c_0 − c_1)`; either its direction
//!   (2-dof residual in the tangent plane of the predicted unit vector) or, with the terrain
//!   distance, the metric `t`, which the plane solver scales by the filter's own height
//!   ([`metric_model`], eq. V2).

use nalgebra::{
    Isometry3, Matrix3, Matrix6, SMatrix, SVector, UnitQuaternion, Vector2, Vector3, Vector6,
};
use uavnav_core::Egomotion;
use uavnav_core::rotation::skew;

use super::{InnovDiag, UpdateOutcome, gated_update};
use crate::state::{Cov, ErrVec, ICP, ICTH, IP, ITH, N, Nominal, PoseClone};

/// Shortest baseline for which a direction of travel is used, m.
pub const MIN_BASELINE_M: f64 = 0.05;

/// Rotation residual (camera-1 frame, rad) and Jacobian.
pub fn rotation_model(
    x: &Nominal,
    c0: &PoseClone,
    body_from_cam: &Isometry3<f64>,
    meas: &UnitQuaternion<f64>,
) -> (Vector3<f64>, SMatrix<f64, 3, N>) {
    let r_bc = body_from_cam.rotation;
    let pred = r_bc.inverse() * x.q.inverse() * c0.q * r_bc;
    let y = (meas * pred.inverse()).scaled_axis();
    let r_c1n = (x.q * r_bc).inverse().to_rotation_matrix().into_inner();
    let mut h = SMatrix::<f64, 3, N>::zeros();
    h.fixed_view_mut::<3, 3>(0, ITH).copy_from(&(-r_c1n));
    h.fixed_view_mut::<3, 3>(0, ICTH).copy_from(&r_c1n);
    (y, h)
}

/// Predicted translation `t` (camera-1 frame) and its Jacobian.
pub fn translation_model(
    x: &Nominal,
    c0: &PoseClone,
    body_from_cam: &Isometry3<f64>,
) -> (Vector3<f64>, SMatrix<f64, 3, N>) {
    let t_bc = body_from_cam.translation.vector;
    let r_c1n = (x.q * body_from_cam.rotation)
        .inverse()
        .to_rotation_matrix()
        .into_inner();
    let a0 = c0.q * t_bc;
    let a1 = x.q * t_bc;
    let d = (c0.p + a0) - (x.p + a1);
    let t = r_c1n * d;
    let mut h = SMatrix::<f64, 3, N>::zeros();
    h.fixed_view_mut::<3, 3>(0, IP).copy_from(&(-r_c1n));
    h.fixed_view_mut::<3, 3>(0, ICP).copy_from(&r_c1n);
    h.fixed_view_mut::<3, 3>(0, ITH)
        .copy_from(&(r_c1n * (skew(&a1) + skew(&d))));
    h.fixed_view_mut::<3, 3>(0, ICTH)
        .copy_from(&(-r_c1n * skew(&a0)));
    (t, h)
}

/// Where a plane-scaled metric translation got its scale (eq. V2). The plane solver fits
/// `x1 ∝ R x0 + (t / d) nᵀx0` and so measures `t / d`; it multiplies by the motion prior's
/// distance `d̂` (the filter's height above the terrain when the frame was predicted). What it
/// reports is therefore `t_m = t · d̂ / d(x)`, with `d(x)` the camera-0 distance to the terrain at
/// the clone. Treating `t_m` as independent of the state made the filter count its own height
/// error as fresh velocity information at every frame: through a long GNSS outage with a
/// consumer-grade IMU the vision scale error followed the height error (correlation 0.71) and
/// the velocity error drifted 0.2–0.8 m/s outside its σ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneScale {
    /// `d̂`: the distance the solver scaled by, m.
    pub prior_distance_m: f64,
    /// `d(x)`: the camera-0 distance to the terrain plane at the clone, m.
    pub distance_m: f64,
}

impl PlaneScale {
    /// Shortest distance for which the scale is modelled, m.
    pub const MIN_DISTANCE_M: f64 = 1.0;
    /// Largest `d̂ / d` (or its inverse) that is modelled: beyond it the linearisation is far off
    /// and the plain model is used (the gate then judges the measurement).
    pub const MAX_RATIO: f64 = 2.0;

    /// The scale reference, or `None` when the distances are not usable.
    pub fn new(prior_distance_m: f64, distance_m: f64) -> Option<Self> {
        let ok = prior_distance_m >= Self::MIN_DISTANCE_M
            && distance_m >= Self::MIN_DISTANCE_M
            && (prior_distance_m / distance_m) <= Self::MAX_RATIO
            && (distance_m / prior_distance_m) <= Self::MAX_RATIO;
        ok.then_some(Self {
            prior_distance_m,
            distance_m,
        })
    }
}

/// The metric translation as the solver reports it (eq. V2): `t(x) · d̂ / d(x)` with a plane
/// scale, else `t(x)` ([`translation_model`]). `d(x)` grows with height: `∂d/∂p_down = −1` at the
/// clone, and the lever `a₀ = C₀ t_bc` turns with the clone's attitude (`δa₀ = −[a₀]× δθ₀`, so
/// `∂d/∂θ₀ = ([a₀]×)` row 3).
pub fn metric_model(
    x: &Nominal,
    c0: &PoseClone,
    body_from_cam: &Isometry3<f64>,
    scale: Option<&PlaneScale>,
) -> (Vector3<f64>, SMatrix<f64, 3, N>) {
    let (t, ht) = translation_model(x, c0, body_from_cam);
    let Some(s) = scale else {
        return (t, ht);
    };
    let k = s.prior_distance_m / s.distance_m;
    let a0 = c0.q * body_from_cam.translation.vector;
    let mut dd = SMatrix::<f64, 1, N>::zeros();
    dd[ICP + 2] = -1.0;
    dd.fixed_view_mut::<1, 3>(0, ICTH)
        .copy_from(&skew(&a0).fixed_rows::<1>(2));
    // ∂(k t)/∂x = k ∂t/∂x − (k / d) t ∂d/∂x
    let h = ht * k - t * dd * (k / s.distance_m);
    (t * k, h)
}

/// An orthonormal basis (3×2) of the plane perpendicular to the unit vector `u`.
pub fn tangent_basis(u: &Vector3<f64>) -> SMatrix<f64, 3, 2> {
    let helper = if u.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let b1 = u.cross(&helper).normalize();
    let b2 = u.cross(&b1);
    SMatrix::<f64, 3, 2>::from_columns(&[b1, b2])
}

/// Direction-of-travel residual (2-D, tangent plane of the predicted direction) and Jacobian;
/// `None` when the predicted baseline is too short to define a direction.
pub fn direction_model(
    x: &Nominal,
    c0: &PoseClone,
    body_from_cam: &Isometry3<f64>,
    meas_dir: &Vector3<f64>,
) -> Option<(Vector2<f64>, SMatrix<f64, 2, N>, SMatrix<f64, 3, 2>)> {
    let (t, ht) = translation_model(x, c0, body_from_cam);
    let n = t.norm();
    if n < MIN_BASELINE_M {
        return None;
    }
    let u = t / n;
    let j = (Matrix3::identity() - u * u.transpose()) / n;
    let b = tangent_basis(&u);
    let y = b.transpose() * (meas_dir - u);
    Some((y, b.transpose() * j * ht, b))
}

/// The vision aiding source (rotation and translation diagnostics).
#[derive(Debug, Clone, PartialEq)]
pub struct VisionSource {
    /// Relative rotation diagnostics.
    pub rot: InnovDiag,
    /// Translation (direction or metric) diagnostics.
    pub trans: InnovDiag,
    /// Measurements dropped because no clone existed at frame 0 (arrived too late).
    pub no_clone: u64,
}

impl Default for VisionSource {
    fn default() -> Self {
        Self {
            rot: InnovDiag::new(),
            trans: InnovDiag::new(),
            no_clone: 0,
        }
    }
}

/// What to fuse from one egomotion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VisionUse {
    /// Fuse the relative rotation.
    pub rotation: bool,
    /// Fuse the translation.
    pub translation: bool,
    /// Fuse rotation and translation in one update with the solver's joint covariance (their
    /// errors are strongly correlated: a small rotation and a small translation move the image
    /// alike), instead of two independent updates.
    pub joint: bool,
    /// Covariance scale.
    pub cov_scale: f64,
    /// Gate, σ.
    pub gate_sigma: f64,
    /// The scale reference of a plane-scaled metric translation, when known.
    pub scale: Option<PlaneScale>,
}

/// Which part of the egomotion a joint update can use.
enum JointKind {
    /// Rotation and metric translation: 6-dof.
    Metric(Vector3<f64>),
    /// Rotation and direction of travel: 5-dof.
    Direction(Vector3<f64>),
}

impl VisionSource {
    /// Fuses rotation and translation of `m` together against the joint covariance (6-dof with
    /// the metric translation, 5-dof with a direction); rotation alone when no translation is
    /// usable. The rotation diagnostics carry the joint test ratio; the translation diagnostics
    /// mirror the outcome with the translation part of the innovation.
    #[allow(clippy::too_many_arguments)]
    pub fn fuse_joint(
        &mut self,
        x: &Nominal,
        c0: &PoseClone,
        p: &mut Cov,
        body_from_cam: &Isometry3<f64>,
        m: &Egomotion,
        u: &VisionUse,
    ) -> Option<ErrVec> {
        let kind = match (m.t_cam1_m, m.t_dir_cam1) {
            (Some(t), _) => JointKind::Metric(t),
            (None, Some(d)) => JointKind::Direction(d.into_inner()),
            (None, None) => return self.fuse_rotation(x, c0, p, body_from_cam, m, u),
        };
        let (yr, hr) = rotation_model(x, c0, body_from_cam, &m.cam1_from_cam0);
        let c = m.joint_cov * u.cov_scale;
        let outcome = match kind {
            JointKind::Metric(tm) => {
                let (t, ht) = metric_model(x, c0, body_from_cam, u.scale.as_ref());
                let mut h = SMatrix::<f64, 6, N>::zeros();
                h.fixed_rows_mut::<3>(0).copy_from(&hr);
                h.fixed_rows_mut::<3>(3).copy_from(&ht);
                let y = Vector6::new(yr.x, yr.y, yr.z, tm.x - t.x, tm.y - t.y, tm.z - t.z);
                let r = c + Matrix6::from_diagonal(&Vector6::new(
                    1e-12, 1e-12, 1e-12, 1e-10, 1e-10, 1e-10,
                ));
                self.joint_update(p, &h, &r, &y, u, m.t1_ns)
            }
            JointKind::Direction(dir) => {
                let Some((yd, hd, b)) = direction_model(x, c0, body_from_cam, &dir) else {
                    return self.fuse_rotation(x, c0, p, body_from_cam, m, u);
                };
                // [δθ; δu] → [δθ; bᵀδu]
                let mut a = SMatrix::<f64, 5, 6>::zeros();
                a.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(&Matrix3::identity());
                a.fixed_view_mut::<2, 3>(3, 3).copy_from(&b.transpose());
                let mut h = SMatrix::<f64, 5, N>::zeros();
                h.fixed_rows_mut::<3>(0).copy_from(&hr);
                h.fixed_rows_mut::<2>(3).copy_from(&hd);
                let y = SVector::<f64, 5>::new(yr.x, yr.y, yr.z, yd.x, yd.y);
                let mut r = a * c * a.transpose();
                for k in 0..5 {
                    r[(k, k)] += if k < 3 { 1e-12 } else { 1e-10 };
                }
                self.joint_update(p, &h, &r, &y, u, m.t1_ns)
            }
        };
        match outcome {
            UpdateOutcome::Fused(dx) => Some(dx),
            _ => None,
        }
    }

    /// The gated joint update; mirrors its outcome into the translation diagnostics.
    fn joint_update<const M: usize>(
        &mut self,
        p: &mut Cov,
        h: &SMatrix<f64, M, N>,
        r: &SMatrix<f64, M, M>,
        y: &SVector<f64, M>,
        u: &VisionUse,
        t_ns: i64,
    ) -> UpdateOutcome {
        // translation part of S before the update changes P
        let mut t_var = [0.0; 3];
        for (k, v) in t_var.iter_mut().enumerate().take(M - 3) {
            let row = h.row(3 + k);
            *v = (row * *p * row.transpose())[0] + r[(3 + k, 3 + k)];
        }
        let out = gated_update(p, h, r, y, u.gate_sigma, t_ns, false, &mut self.rot);
        let t = &mut self.trans;
        t.innov = [0.0; 3];
        for k in 0..M - 3 {
            t.innov[k] = y[3 + k];
        }
        t.innov_var = t_var;
        t.test_ratio = self.rot.test_ratio;
        match out {
            UpdateOutcome::Fused(_) => {
                t.fused += 1;
                t.consecutive_rejects = 0;
                t.last_fused_t_ns = t_ns;
            }
            UpdateOutcome::Rejected => {
                if t.consecutive_rejects == 0 {
                    t.first_reject_t_ns = t_ns;
                }
                t.rejected += 1;
                t.consecutive_rejects += 1;
            }
            UpdateOutcome::Singular => {}
        }
        out
    }

    /// Fuses the rotation of `m`; returns the correction.
    pub fn fuse_rotation(
        &mut self,
        x: &Nominal,
        c0: &PoseClone,
        p: &mut Cov,
        body_from_cam: &Isometry3<f64>,
        m: &Egomotion,
        u: &VisionUse,
    ) -> Option<ErrVec> {
        let (y, h) = rotation_model(x, c0, body_from_cam, &m.cam1_from_cam0);
        let r = m.rot_cov * u.cov_scale + Matrix3::identity() * 1e-12;
        match gated_update(p, &h, &r, &y, u.gate_sigma, m.t1_ns, false, &mut self.rot) {
            UpdateOutcome::Fused(dx) => Some(dx),
            _ => None,
        }
    }

    /// Fuses the translation of `m` (metric when available, else direction); returns the correction.
    pub fn fuse_translation(
        &mut self,
        x: &Nominal,
        c0: &PoseClone,
        p: &mut Cov,
        body_from_cam: &Isometry3<f64>,
        m: &Egomotion,
        u: &VisionUse,
    ) -> Option<ErrVec> {
        let outcome = if let Some(tm) = m.t_cam1_m {
            let (t, h) = metric_model(x, c0, body_from_cam, u.scale.as_ref());
            let r = m.t_cov * u.cov_scale + Matrix3::identity() * 1e-10;
            gated_update(
                p,
                &h,
                &r,
                &(tm - t),
                u.gate_sigma,
                m.t1_ns,
                false,
                &mut self.trans,
            )
        } else if let Some(dir) = m.t_dir_cam1 {
            let (y, h, b) = direction_model(x, c0, body_from_cam, &dir.into_inner())?;
            let r =
                b.transpose() * m.t_cov * b * u.cov_scale + nalgebra::Matrix2::identity() * 1e-10;
            gated_update(p, &h, &r, &y, u.gate_sigma, m.t1_ns, false, &mut self.trans)
        } else {
            return None;
        };
        match outcome {
            UpdateOutcome::Fused(dx) => Some(dx),
            _ => None,
        }
    }
}
