//! The camera egomotion measurement: what the vision front end hands to the estimator.
//!
//! Defined here so that the vision and estimator crates share it without depending on each other.

use nalgebra::{Matrix3, Matrix6, Unit, UnitQuaternion, Vector3};

/// Which geometric solver produced an egomotion measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EgomotionSolver {
    /// The paper's normalized 8-point essential matrix + Huang–Faugeras factorization.
    Essential,
    /// Plane-aware solver using the ground normal from the attitude estimate.
    Plane,
    /// Rotation only (no translation observable, e.g. static camera).
    RotationOnly,
}

impl EgomotionSolver {
    /// Name for CSV columns and logs.
    pub fn as_str(self) -> &'static str {
        match self {
            EgomotionSolver::Essential => "essential",
            EgomotionSolver::Plane => "plane",
            EgomotionSolver::RotationOnly => "rotation",
        }
    }
}

/// Relative motion of the camera between two frames, with its first-order covariance.
///
/// Geometry: a point with coordinates `x0` in camera frame 0 has `x1 = cam1_from_cam0 · x0 + t`
/// in camera frame 1, where `t` is the translation expressed in camera frame 1 (the paper's
/// `r_21^{c2}` up to sign conventions: here it is exactly the `t` of `x1 = R x0 + t`).
#[derive(Debug, Clone, PartialEq)]
pub struct Egomotion {
    /// Time of frame 0, ns.
    pub t0_ns: i64,
    /// Time of frame 1, ns.
    pub t1_ns: i64,
    /// Rotation taking camera-0 coordinates into camera-1 coordinates.
    pub cam1_from_cam0: UnitQuaternion<f64>,
    /// Unit direction of `t` (camera-1 frame); `None` when translation is not observable.
    pub t_dir_cam1: Option<Unit<Vector3<f64>>>,
    /// Metric `t` (camera-1 frame, m) when the scene distance is known (terrain model), else `None`.
    pub t_cam1_m: Option<Vector3<f64>>,
    /// The camera-0 distance to the terrain plane that scaled `t_cam1_m`, m, when the scale came
    /// from the motion prior (the plane solver measures `t / d` and multiplies by this `d`): the
    /// metric translation is then proportional to the estimator's own height above the terrain,
    /// and the estimator models that dependence (`aid_sources::vision::PlaneScale`). `None` when
    /// the scale does not come from a prior distance.
    pub scale_distance_m: Option<f64>,
    /// Covariance of the rotation error `δθ` (rad²), with `R_meas = Exp(δθ) · R_true`, camera-1 frame.
    pub rot_cov: Matrix3<f64>,
    /// Covariance of the translation: of the unit direction (rank 2) or of the metric `t` when
    /// `t_cam1_m` is set, camera-1 frame.
    pub t_cov: Matrix3<f64>,
    /// Joint 6×6 covariance [δθ; δt] when the solver provides cross terms (else block-diagonal).
    pub joint_cov: Matrix6<f64>,
    /// Features tracked from frame 0 into frame 1.
    pub tracked: u32,
    /// Inliers of the robust solver.
    pub inliers: u32,
    /// Quality score in [0, 1] (1 = best).
    pub quality: f64,
    /// Solver used.
    pub solver: EgomotionSolver,
}

/// What the estimator knows about the motion between two frames, handed to the vision front end
/// to predict the optical flow (paper section IV-A) and to pick the plane-aware solver.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MotionPrior {
    /// Rotation from camera-0 to camera-1 coordinates integrated from the gyros, if known.
    pub cam1_from_cam0: Option<UnitQuaternion<f64>>,
    /// 1-σ uncertainty of that rotation per axis, rad.
    pub rot_sigma_rad: f64,
    /// Unit normal of the terrain plane (the Earth-surface model at the terrain elevation), pointing
    /// from the camera towards the ground (NED "down"), in camera-0 coordinates.
    pub ground_normal_cam0: Option<Unit<Vector3<f64>>>,
    /// Perpendicular distance from the camera-0 centre to the terrain plane, m.
    pub ground_distance_m: Option<f64>,
    /// Predicted translation `t` (x1 = R x0 + t), camera-1 frame, m, from the velocity estimate.
    pub t_cam1_m: Option<Vector3<f64>>,
}
