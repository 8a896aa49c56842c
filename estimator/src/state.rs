//! The error-state EKF's nominal state, error-state layout and the injection of a correction.
//!
//! Attitude error convention (global, nav frame): `R_true = Exp(δθ) · R_nom`, with `R` =
//! `nav_from_body`. The clone block holds the attitude and position at the previous camera frame
//! (stochastic cloning), so a relative-motion measurement can be fused against both ends.

use nalgebra::{SMatrix, SVector, UnitQuaternion, Vector3};

/// Error-state dimension.
pub const N: usize = 24;
/// Position error, NED, m.
pub const IP: usize = 0;
/// Velocity error, NED, m/s.
pub const IV: usize = 3;
/// Attitude error (global), rad.
pub const ITH: usize = 6;
/// Gyro bias error, rad/s.
pub const IBG: usize = 9;
/// Accelerometer bias error, m/s².
pub const IBA: usize = 12;
/// GNSS position error (Gauss–Markov), NED, m.
pub const IGM: usize = 15;
/// Cloned attitude error at the previous camera frame, rad.
pub const ICTH: usize = 18;
/// Cloned position error at the previous camera frame, m.
pub const ICP: usize = 21;

/// Names of the error states, for the covariance diagonal in [`crate::Health`].
pub const STATE_LABELS: [&str; N] = [
    "pn", "pe", "pd", "vn", "ve", "vd", "thn", "the", "thd", "bgx", "bgy", "bgz", "bax", "bay",
    "baz", "gmn", "gme", "gmd", "cthn", "cthe", "cthd", "cpn", "cpe", "cpd",
];

/// Error-state covariance.
pub type Cov = SMatrix<f64, N, N>;
/// Error-state vector.
pub type ErrVec = SVector<f64, N>;

/// A stochastic clone of the pose at a camera frame time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseClone {
    /// Frame time, ns.
    pub t_ns: i64,
    /// `nav_from_body` at that time.
    pub q: UnitQuaternion<f64>,
    /// Position at that time, NED, m.
    pub p: Vector3<f64>,
}

/// The nominal (full) state at the fusion horizon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nominal {
    /// Time of validity, ns.
    pub t_ns: i64,
    /// Position, NED, m.
    pub p: Vector3<f64>,
    /// Velocity, NED, m/s.
    pub v: Vector3<f64>,
    /// `nav_from_body`.
    pub q: UnitQuaternion<f64>,
    /// Gyro bias, rad/s.
    pub bg: Vector3<f64>,
    /// Accelerometer bias, m/s².
    pub ba: Vector3<f64>,
    /// GNSS position error estimate, m.
    pub gm: Vector3<f64>,
    /// Pose clone at the previous camera frame.
    pub clone: Option<PoseClone>,
}

/// Rotation vector → unit quaternion (the SO(3) exponential).
pub fn exp_q(dtheta: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_scaled_axis(*dtheta)
}

impl Nominal {
    /// Applies an error-state correction (the ESKF "injection"); the covariance reset Jacobian is
    /// taken as identity (the `−½[δθ]×` term is second order for the corrections we fuse).
    pub fn inject(&mut self, dx: &ErrVec) {
        self.p += dx.fixed_rows::<3>(IP);
        self.v += dx.fixed_rows::<3>(IV);
        self.q = exp_q(&dx.fixed_rows::<3>(ITH).into_owned()) * self.q;
        self.bg += dx.fixed_rows::<3>(IBG);
        self.ba += dx.fixed_rows::<3>(IBA);
        self.gm += dx.fixed_rows::<3>(IGM);
        if let Some(c) = self.clone.as_mut() {
            c.q = exp_q(&dx.fixed_rows::<3>(ICTH).into_owned()) * c.q;
            c.p += dx.fixed_rows::<3>(ICP);
        }
    }

    /// True if every component is finite.
    pub fn is_finite(&self) -> bool {
        self.p
            .iter()
            .chain(self.v.iter())
            .chain(self.bg.iter())
            .chain(self.ba.iter())
            .all(|x| x.is_finite())
            && self.q.coords.iter().all(|x| x.is_finite())
    }
}

/// Copies the current attitude/position error rows and columns into the clone block.
pub fn augment_clone(p: &mut Cov) {
    for (src, dst) in [(ITH, ICTH), (IP, ICP)] {
        for k in 0..3 {
            let row = p.row(src + k).into_owned();
            p.set_row(dst + k, &row);
        }
        for k in 0..3 {
            let col = p.column(src + k).into_owned();
            p.set_column(dst + k, &col);
        }
    }
    // The clone-clone block equals the source-source block (set by the column copy after the row
    // copy); enforce exact symmetry.
    *p = (*p + p.transpose()) * 0.5;
}

/// Sets the error state `i` to variance `var` with no correlation with any other state (a reset of
/// that state, or one whose past correlations are not to be trusted).
pub fn set_uncorrelated(p: &mut Cov, i: usize, var: f64) {
    p.row_mut(i).fill(0.0);
    p.column_mut(i).fill(0.0);
    p[(i, i)] = var;
}

/// Removes the clone block (zero covariance, no correlation).
pub fn clear_clone(p: &mut Cov) {
    for k in ICTH..N {
        p.row_mut(k).fill(0.0);
        p.column_mut(k).fill(0.0);
    }
}
