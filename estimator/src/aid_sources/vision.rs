//! Vision egomotion between camera frames 0 and 1, fused against the pose clone at frame 0 and the
//! state at frame 1 (stochastic cloning).
//!
//! With `C_k` = nav_from_body, `R_bc`/`t_bc` = body_from_cam, camera centres `c_k = p_k + C_k t_bc`:
//! - rotation (the relative form of the paper's delta-attitudes, eq. 34):
//!   `cam1_from_cam0 = R_bcᵀ C_1ᵀ C_0 R_bc`, residual `Log(R_meas R_predᵀ)` in camera-1;
//! - translation (eq. 35's direction of motion): `t = R_bcᵀ C_1ᵀ (c_0 − c_1)`; either its direction
//!   (2-dof residual in the tangent plane of the predicted unit vector) or, with the terrain
//!   distance, the metric `t`.

use nalgebra::{Isometry3, Matrix3, SMatrix, UnitQuaternion, Vector2, Vector3};
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
    /// Covariance scale.
    pub cov_scale: f64,
    /// Gate, σ.
    pub gate_sigma: f64,
}

impl VisionSource {
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
            let (t, h) = translation_model(x, c0, body_from_cam);
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
