//! Every Jacobian against finite differences: the error dynamics `A` (F = I + A dt), the noise
//! mapping (G), and each measurement `H` (GNSS position, GNSS velocity, vision rotation, metric
//! translation, direction of travel).
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use nalgebra::{Isometry3, SMatrix, Translation3, UnitQuaternion, Vector3};
use uavnav_estimator::aid_sources::{gnss_pos, gnss_vel, vision};
use uavnav_estimator::prediction::{ErrorDynamics, ImuMean, integrate_nominal};
use uavnav_estimator::state::{ErrVec, N, Nominal, PoseClone};

fn nominal() -> Nominal {
    Nominal {
        t_ns: 0,
        p: Vector3::new(120.0, -40.0, -200.0),
        v: Vector3::new(25.0, 12.0, -1.5),
        q: UnitQuaternion::from_euler_angles(0.3, -0.1, 2.2),
        bg: Vector3::new(1e-3, -2e-3, 5e-4),
        ba: Vector3::new(0.02, -0.01, 0.03),
        gm: Vector3::new(0.5, -0.3, 1.0),
        clone: Some(PoseClone {
            t_ns: -100_000_000,
            q: UnitQuaternion::from_euler_angles(0.28, -0.12, 2.17),
            p: Vector3::new(117.6, -41.2, -199.8),
        }),
    }
}

/// `x ⊖ y` in the error-state convention.
fn diff(a: &Nominal, b: &Nominal) -> ErrVec {
    let mut d = ErrVec::zeros();
    d.fixed_rows_mut::<3>(0).copy_from(&(a.p - b.p));
    d.fixed_rows_mut::<3>(3).copy_from(&(a.v - b.v));
    d.fixed_rows_mut::<3>(6)
        .copy_from(&(a.q * b.q.inverse()).scaled_axis());
    d.fixed_rows_mut::<3>(9).copy_from(&(a.bg - b.bg));
    d.fixed_rows_mut::<3>(12).copy_from(&(a.ba - b.ba));
    d.fixed_rows_mut::<3>(15).copy_from(&(a.gm - b.gm));
    if let (Some(ca), Some(cb)) = (a.clone, b.clone) {
        d.fixed_rows_mut::<3>(18)
            .copy_from(&(ca.q * cb.q.inverse()).scaled_axis());
        d.fixed_rows_mut::<3>(21).copy_from(&(ca.p - cb.p));
    }
    d
}

fn perturbed(x: &Nominal, k: usize, h: f64) -> Nominal {
    let mut dx = ErrVec::zeros();
    dx[k] = h;
    let mut y = *x;
    y.inject(&dx);
    y
}

const G: Vector3<f64> = Vector3::new(0.0, 0.0, 9.80);

#[test]
fn error_dynamics_f_matches_finite_differences() {
    let x = nominal();
    let imu = ImuMean {
        gyro: Vector3::new(0.05, -0.02, 0.17),
        accel: Vector3::new(1.2, 2.5, -9.5),
    };
    let w_ie = Vector3::new(5.5e-5, 0.0, -4.8e-5);
    let tau = 300.0;
    let dt = 1e-3;
    let f = ErrorDynamics::new(&x, &imu, &w_ie, tau).dense_f(dt);
    let mut x1 = x;
    integrate_nominal(&mut x1, &imu, dt, &G, &w_ie, tau);
    let h = 1e-6;
    for k in 0..N {
        let mut xp = perturbed(&x, k, h);
        integrate_nominal(&mut xp, &imu, dt, &G, &w_ie, tau);
        let fd = diff(&xp, &x1) / h;
        let an = f.column(k);
        let err = (fd - an).norm();
        // First-order discretisation: the residual is O(dt²·|A|²) plus FD noise.
        assert!(
            err < 2e-4,
            "column {k}: fd {fd:?} vs F {an:?} (err {err:e})"
        );
    }
}

#[test]
fn noise_mapping_g_is_isotropic_rotation() {
    // v̇ noise enters as C n_a and θ̇ noise as −C n_g: the discrete Q blocks are σ² I because C is a
    // rotation. Check the mapping itself by perturbing the IMU input.
    let x = nominal();
    let c = *x.q.to_rotation_matrix().matrix();
    let imu = ImuMean {
        gyro: Vector3::new(0.05, -0.02, 0.17),
        accel: Vector3::new(1.2, 2.5, -9.5),
    };
    let (dt, h) = (1e-3, 1e-5);
    let w_ie = Vector3::zeros();
    let mut x1 = x;
    integrate_nominal(&mut x1, &imu, dt, &G, &w_ie, 300.0);
    for k in 0..3 {
        let mut d = Vector3::zeros();
        d[k] = h;
        let mut xa = x;
        integrate_nominal(
            &mut xa,
            &ImuMean {
                accel: imu.accel + d,
                ..imu
            },
            dt,
            &G,
            &w_ie,
            300.0,
        );
        let dv = (xa.v - x1.v) / (h * dt);
        assert!(
            (dv - c * Vector3::ith(k, 1.0)).norm() < 1e-3,
            "accel axis {k}: {dv:?}"
        );
        let mut xg = x;
        integrate_nominal(
            &mut xg,
            &ImuMean {
                gyro: imu.gyro + d,
                ..imu
            },
            dt,
            &G,
            &w_ie,
            300.0,
        );
        let dth = (xg.q * x1.q.inverse()).scaled_axis() / (h * dt);
        assert!(
            (dth - c * Vector3::ith(k, 1.0)).norm() < 1e-3,
            "gyro axis {k}: {dth:?}"
        );
    }
    let q = c * c.transpose();
    assert!((q - nalgebra::Matrix3::identity()).norm() < 1e-12);
}

/// Checks `∂(z − h(x ⊕ δ))/∂δ = −H` column by column.
fn check_h<const M: usize>(
    name: &str,
    x: &Nominal,
    h_an: &SMatrix<f64, M, N>,
    resid: impl Fn(&Nominal) -> SMatrix<f64, M, 1>,
    tol: f64,
) {
    let eps = 1e-6;
    let y0 = resid(x);
    for k in 0..N {
        let yk = resid(&perturbed(x, k, eps));
        let fd = -(yk - y0) / eps;
        let err = (fd - h_an.column(k)).norm();
        assert!(
            err < tol,
            "{name} column {k}: fd {fd:?} vs H {:?}",
            h_an.column(k).into_owned()
        );
    }
}

fn mount() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.3, -0.1, 0.2),
        UnitQuaternion::from_euler_angles(0.05, -0.03, 1.57),
    )
}

#[test]
fn gnss_position_h() {
    let x = nominal();
    let lever = Vector3::new(0.5, 2.0, -0.3);
    let z = x.p + x.q * lever + x.gm + Vector3::new(0.1, -0.2, 0.3);
    let (_, h) = gnss_pos::model(&x, &lever, &z);
    check_h(
        "gnss_pos",
        &x,
        &h,
        |s| gnss_pos::model(s, &lever, &z).0,
        1e-5,
    );
}

#[test]
fn gnss_velocity_h() {
    let x = nominal();
    let lever = Vector3::new(10.0, 10.0, 10.0);
    let gyro = Vector3::new(0.1, -0.2, 0.3);
    let w_ie = Vector3::new(5.5e-5, 0.0, -4.8e-5);
    let z = x.v + Vector3::new(0.1, 0.2, 0.0);
    let (_, h) = gnss_vel::model(&x, &lever, &gyro, &w_ie, &z);
    check_h(
        "gnss_vel",
        &x,
        &h,
        |s| gnss_vel::model(s, &lever, &gyro, &w_ie, &z).0,
        1e-5,
    );
}

#[test]
fn vision_rotation_h() {
    let x = nominal();
    let bfc = mount();
    let c0 = x.clone.unwrap();
    let meas = bfc.rotation.inverse() * x.q.inverse() * c0.q * bfc.rotation;
    let (_, h) = vision::rotation_model(&x, &c0, &bfc, &meas);
    check_h(
        "vision_rot",
        &x,
        &h,
        |s| vision::rotation_model(s, &s.clone.unwrap(), &bfc, &meas).0,
        1e-5,
    );
}

#[test]
fn vision_translation_h() {
    let x = nominal();
    let bfc = mount();
    let (_, h) = vision::translation_model(&x, &x.clone.unwrap(), &bfc);
    // The residual is z − t: its derivative is −H.
    check_h(
        "vision_t",
        &x,
        &h,
        |s| -vision::translation_model(s, &s.clone.unwrap(), &bfc).0,
        1e-5,
    );
}

#[test]
fn vision_direction_h() {
    let x = nominal();
    let bfc = mount();
    let (t, _) = vision::translation_model(&x, &x.clone.unwrap(), &bfc);
    let meas = (t.normalize() + Vector3::new(0.001, -0.002, 0.0005)).normalize();
    let (_, h, b) = vision::direction_model(&x, &x.clone.unwrap(), &bfc, &meas).unwrap();
    // Residual in the fixed tangent basis of the unperturbed prediction.
    check_h(
        "vision_dir",
        &x,
        &h,
        |s| {
            let (t, _) = vision::translation_model(s, &s.clone.unwrap(), &bfc);
            b.transpose() * (meas - t.normalize())
        },
        1e-5,
    );
}
