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

/// The plane solver's scale `d̂ / d(x)` (eq. V2): `d(x)` is the clone camera's height above a
/// flat terrain 30 m below the origin (NED down = 30), the distance the solver used 3 % larger.
#[test]
fn vision_plane_scaled_metric_translation_h() {
    let x = nominal();
    let bfc = mount();
    let scale = |s: &Nominal| {
        let c0 = s.clone.unwrap();
        let centre = c0.p + c0.q * bfc.translation.vector;
        vision::PlaneScale::new(236.0, 30.0 - centre.z).unwrap()
    };
    let s0 = scale(&x);
    assert!((s0.prior_distance_m / s0.distance_m - 1.03).abs() < 0.01);
    let (t_scaled, h) = vision::metric_model(&x, &x.clone.unwrap(), &bfc, Some(&s0));
    let (t, _) = vision::translation_model(&x, &x.clone.unwrap(), &bfc);
    assert!((t_scaled - t * (s0.prior_distance_m / s0.distance_m)).norm() < 1e-12);
    check_h(
        "vision_t_scaled",
        &x,
        &h,
        |s| -vision::metric_model(s, &s.clone.unwrap(), &bfc, Some(&scale(s))).0,
        1e-5,
    );
    // A height change of the clone is now visible to the measurement (1 m → ≈ t / d).
    let c_pd = uavnav_estimator::state::ICP + 2;
    assert!(h.column(c_pd).norm() > 0.9 * t.norm() / s0.distance_m);
    // Distances that cannot be linearised are not modelled.
    assert!(vision::PlaneScale::new(100.0, 40.0).is_none());
    assert!(vision::PlaneScale::new(100.0, 0.5).is_none());
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

// ---- the joint vision update against the textbook Kalman update ----

/// A prior where the positions are known better than the vision translation (1 mm) and the
/// attitudes worse than the vision rotation (1 mrad): the correlated case then has to learn the
/// rotation through the translation. Small correlations everywhere keep it generic.
fn prior_cov() -> uavnav_estimator::state::Cov {
    use uavnav_estimator::state::{IBG, ICP, ICTH, IP, ITH};
    let sigma = |i: usize| match i {
        _ if (IP..IP + 3).contains(&i) || (ICP..ICP + 3).contains(&i) => 1e-3,
        _ if (ITH..ITH + 3).contains(&i) || (ICTH..ICTH + 3).contains(&i) => 1e-3,
        _ if (IBG..IBG + 3).contains(&i) => 1e-4,
        _ => 1e-2,
    };
    let a = SMatrix::<f64, N, N>::from_fn(|i, j| {
        let c = if i == j {
            1.0
        } else {
            ((i * 7 + j * 3) % 11) as f64 * 0.005
        };
        c * sigma(i)
    });
    a * a.transpose()
}

/// An egomotion equal to the prediction plus a small error, with the joint covariance `c`.
fn metric_ego(
    x: &Nominal,
    bfc: &Isometry3<f64>,
    c: nalgebra::Matrix6<f64>,
) -> uavnav_core::Egomotion {
    let c0 = x.clone.unwrap();
    let rot = bfc.rotation.inverse() * x.q.inverse() * c0.q * bfc.rotation;
    let (t, _) = vision::translation_model(x, &c0, bfc);
    let t_m = t + Vector3::new(0.004, -0.003, 0.002);
    uavnav_core::Egomotion {
        t0_ns: c0.t_ns,
        t1_ns: x.t_ns,
        cam1_from_cam0: UnitQuaternion::from_scaled_axis(Vector3::new(2e-5, -1e-5, 3e-5)) * rot,
        t_dir_cam1: Some(nalgebra::Unit::new_normalize(t_m)),
        t_cam1_m: Some(t_m),
        scale_distance_m: None,
        rot_cov: c.fixed_view::<3, 3>(0, 0).into_owned(),
        t_cov: c.fixed_view::<3, 3>(3, 3).into_owned(),
        joint_cov: c,
        tracked: 200,
        inliers: 180,
        quality: 0.9,
        solver: uavnav_core::EgomotionSolver::Plane,
    }
}

fn vision_use(joint: bool) -> vision::VisionUse {
    vision::VisionUse {
        rotation: true,
        translation: true,
        joint,
        cov_scale: 1.0,
        gate_sigma: 1e3,
        scale: None,
    }
}

/// A rotation–translation covariance with the plane solver's structure (|ρ| ≈ 0.98 between a
/// rotation and the translation it mimics).
fn correlated_cov(rho: f64) -> nalgebra::Matrix6<f64> {
    let (sr, st) = (6e-5, 0.018);
    let mut c = nalgebra::Matrix6::from_diagonal(&nalgebra::Vector6::new(
        sr * sr,
        sr * sr,
        sr * sr,
        st * st,
        st * st,
        st * st,
    ));
    c[(1, 3)] = rho * sr * st;
    c[(3, 1)] = rho * sr * st;
    c[(0, 4)] = -rho * sr * st;
    c[(4, 0)] = -rho * sr * st;
    c
}

#[test]
fn joint_update_without_cross_terms_equals_the_two_separate_updates() {
    let x = nominal();
    let bfc = mount();
    let m = metric_ego(&x, &bfc, correlated_cov(0.0));
    let c0 = x.clone.unwrap();
    let mut src = vision::VisionSource::default();
    let mut p_joint = prior_cov();
    src.fuse_joint(&x, &c0, &mut p_joint, &bfc, &m, &vision_use(true))
        .unwrap();
    // Separate updates at the same linearisation point (no injection in between).
    let mut p_sep = prior_cov();
    src.fuse_rotation(&x, &c0, &mut p_sep, &bfc, &m, &vision_use(false))
        .unwrap();
    src.fuse_translation(&x, &c0, &mut p_sep, &bfc, &m, &vision_use(false))
        .unwrap();
    let d = normalized_diff(&p_joint, &p_sep);
    assert!(d < 1e-6, "P differs by {d} (in units of σᵢσⱼ)");
    assert_eq!((src.rot.fused, src.trans.fused), (2, 2));
}

#[test]
fn joint_update_uses_the_rotation_translation_correlation() {
    let x = nominal();
    let bfc = mount();
    let c = correlated_cov(0.98);
    let m = metric_ego(&x, &bfc, c);
    let c0 = x.clone.unwrap();
    let p0 = prior_cov();
    let mut p = p0;
    let mut src = vision::VisionSource::default();
    let dx = src
        .fuse_joint(&x, &c0, &mut p, &bfc, &m, &vision_use(true))
        .unwrap();
    // Information form: P⁺ = (P⁻¹ + Hᵀ R⁻¹ H)⁻¹ with the full 6×6 R.
    let (_, hr) = vision::rotation_model(&x, &c0, &bfc, &m.cam1_from_cam0);
    let (_, ht) = vision::translation_model(&x, &c0, &bfc);
    let mut h = SMatrix::<f64, 6, N>::zeros();
    h.fixed_rows_mut::<3>(0).copy_from(&hr);
    h.fixed_rows_mut::<3>(3).copy_from(&ht);
    let r = c + nalgebra::Matrix6::from_diagonal(&nalgebra::Vector6::new(
        1e-12, 1e-12, 1e-12, 1e-10, 1e-10, 1e-10,
    ));
    let want = (p0.try_inverse().unwrap() + h.transpose() * r.try_inverse().unwrap() * h)
        .try_inverse()
        .unwrap();
    let d = normalized_diff(&p, &want);
    assert!(d < 1e-6, "P differs by {d} (in units of σᵢσⱼ)");
    // correction: δx = P⁺ Hᵀ R⁻¹ y
    let (yr, _) = vision::rotation_model(&x, &c0, &bfc, &m.cam1_from_cam0);
    let (t, _) = vision::translation_model(&x, &c0, &bfc);
    let tm = m.t_cam1_m.unwrap();
    let y = nalgebra::Vector6::new(yr.x, yr.y, yr.z, tm.x - t.x, tm.y - t.y, tm.z - t.z);
    let dx_want = want * h.transpose() * r.try_inverse().unwrap() * y;
    for k in 0..N {
        let s = want[(k, k)].sqrt();
        assert!((dx[k] - dx_want[k]).abs() < 1e-6 * s, "δx[{k}]");
    }
    // and it is not what ignoring the correlation gives
    let mut p_blind = p0;
    let m_blind = metric_ego(&x, &bfc, correlated_cov(0.0));
    vision::VisionSource::default()
        .fuse_joint(&x, &c0, &mut p_blind, &bfc, &m_blind, &vision_use(true))
        .unwrap();
    // The correlated translation pins the relative rotation it mimics (camera y here) much
    // better than the rotation alone: compare the posterior variance of that rotation.
    let rel_var = |p: &uavnav_estimator::state::Cov| (hr * p * hr.transpose())[(1, 1)];
    let (joint, blind) = (rel_var(&p), rel_var(&p_blind));
    assert!(
        joint < 0.3 * blind,
        "relative-rotation variance {joint} vs {blind} ignoring ρ"
    );
}

/// Largest |aᵢⱼ − bᵢⱼ| / √(bᵢᵢ bⱼⱼ).
fn normalized_diff(a: &uavnav_estimator::state::Cov, b: &uavnav_estimator::state::Cov) -> f64 {
    let mut m: f64 = 0.0;
    for i in 0..N {
        for j in 0..N {
            m = m.max((a[(i, j)] - b[(i, j)]).abs() / (b[(i, i)] * b[(j, j)]).sqrt());
        }
    }
    m
}

#[test]
fn paper_lever_arm_jacobian_matches_finite_differences() {
    // `∂(C(φ,θ,ψ) u)/∂(φ,θ,ψ)` of the paper profile's eqs. (32)–(33) linearization.
    use nalgebra::Rotation3;
    use uavnav_estimator::paper::attitude::lever_jacobian;
    let e = Vector3::new(0.4, -0.3, 2.5);
    let u = Vector3::new(10.0, -7.0, 3.0);
    let c_u = |e: &Vector3<f64>| Rotation3::from_euler_angles(e.x, e.y, e.z) * u;
    let h = lever_jacobian(&e, &u);
    let d = 1e-6;
    for k in 0..3 {
        let mut ep = e;
        let mut em = e;
        ep[k] += d;
        em[k] -= d;
        let num = (c_u(&ep) - c_u(&em)) / (2.0 * d);
        let err = (num - h.column(k)).norm();
        assert!(err < 1e-6, "column {k}: {num:?} vs {:?}", h.column(k));
    }
}

/// Eq. (F1) of `paper::attitude`: `∂(J(φ,θ) ω)/∂(φ,θ,ψ)` of eq. (31) against central differences.
#[test]
fn paper_euler_rate_jacobian_matches_finite_differences() {
    use uavnav_estimator::output::euler_rate_matrix;
    use uavnav_estimator::paper::attitude::euler_rate_jacobian;
    let e = Vector3::new(0.5, -0.3, 2.0);
    let w = Vector3::new(0.2, -0.15, 0.3);
    let f = |e: &Vector3<f64>| euler_rate_matrix(e.x, e.y) * w;
    let got = euler_rate_jacobian(&e, &w);
    let h = 1e-6;
    for k in 0..3 {
        let mut d = Vector3::zeros();
        d[k] = h;
        let num = (f(&(e + d)) - f(&(e - d))) / (2.0 * h);
        assert!(
            (got.column(k) - num).norm() < 1e-8,
            "column {k}: {} vs {num}",
            got.column(k)
        );
    }
}

/// Eqs. (C1)–(C2) of `paper::attitude`: the error of a chain of delta-rotations is a rotation
/// fixed in the navigation frame (it does not change as the vehicle turns), and its Euler-angle
/// image is `J(φ,θ) Cᵀ η`, which does change: a tilt error made heading north is a roll error
/// there and a pitch error after a 90° turn.
#[test]
fn paper_chain_error_is_fixed_in_the_navigation_frame() {
    use nalgebra::Rotation3;
    use uavnav_estimator::output::euler_rate_matrix;
    let c0 = Rotation3::from_euler_angles(0.1, 0.05, 0.0);
    // Initial error η_0 (NED) and a turn of 90° in small body-axis deltas, each with no error.
    let eta0 = Vector3::new(2e-3, -1e-3, 5e-4);
    let delta = Rotation3::from_scaled_axis(Vector3::new(
        0.01,
        0.003,
        std::f64::consts::FRAC_PI_2 / 50.0,
    ));
    let (mut c_true, mut c_chain) = (c0, Rotation3::new(eta0) * c0);
    for _ in 0..50 {
        c_true *= delta;
        c_chain *= delta;
    }
    let eta = (c_chain * c_true.inverse()).scaled_axis();
    assert!((eta - eta0).norm() < 1e-10, "η changed: {eta} vs {eta0}");
    let euler = |c: &Rotation3<f64>| {
        let (r, p, y) = c.euler_angles();
        Vector3::new(r, p, y)
    };
    let de = euler(&c_chain) - euler(&c_true);
    let e = euler(&c_true);
    let predicted = euler_rate_matrix(e.x, e.y) * c_true.matrix().transpose() * eta0;
    assert!(
        // first order: the residual is O(|η|²)
        (de - predicted).norm() < 1e-2 * eta0.norm(),
        "Euler error {de} vs J Cᵀ η {predicted}"
    );
    // The Euler-angle error did change with the turn (what constant Euler angles would miss).
    let de0 = euler(&(Rotation3::new(eta0) * c0)) - euler(&c0);
    assert!((de - de0).norm() > 1e-3, "{de} vs {de0}");
}

/// Eq. (D1) of `paper::attitude`: the course and flight-path angle of the video direction of
/// travel rotated into NED, `h(e) = [χ(C(e) u); γ(C(e) u)]`, and its Jacobian w.r.t. the Euler
/// angles `A(C u) ∂(C u)/∂e`, against central differences; and `A(x)` itself (the angles of the
/// GNSS-IMU velocity), in a climbing turn and in a descent heading south-west (course near ±π).
#[test]
fn paper_direction_of_travel_jacobian_matches_finite_differences() {
    use nalgebra::Vector2;
    use uavnav_estimator::paper::attitude::{course_path_angle, direction_model};
    let wrap = |a: f64| {
        (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
    };
    let cases = [
        (Vector3::new(0.4, -0.3, 2.5), Vector3::new(0.97, 0.05, 0.2)),
        (Vector3::new(-0.2, 0.1, -2.9), Vector3::new(0.9, -0.3, -0.1)),
        (Vector3::new(0.05, 0.02, 0.0), Vector3::new(1.0, 0.0, 0.0)),
    ];
    for (e, u) in cases {
        let u = u.normalize();
        let (_, h, _) = direction_model(&e, &u);
        let d = 1e-6;
        for k in 0..3 {
            let (mut ep, mut em) = (e, e);
            ep[k] += d;
            em[k] -= d;
            let (zp, zm) = (direction_model(&ep, &u).0, direction_model(&em, &u).0);
            let num = Vector2::new(wrap(zp.x - zm.x), zp.y - zm.y) / (2.0 * d);
            let err = (num - h.column(k)).norm();
            assert!(
                err < 1e-7,
                "e {e:?} column {k}: {num:?} vs {:?}",
                h.column(k)
            );
        }
        // A(x) for an un-normalised velocity (the angles do not depend on its length).
        let w = 25.0 * u + Vector3::new(0.3, -0.2, 0.1);
        let (_, a) = course_path_angle(&w);
        for k in 0..3 {
            let mut dw = Vector3::zeros();
            dw[k] = 1e-6;
            let (zp, zm) = (
                course_path_angle(&(w + dw)).0,
                course_path_angle(&(w - dw)).0,
            );
            let num = Vector2::new(wrap(zp.x - zm.x), zp.y - zm.y) / 2e-6;
            assert!(
                (num - a.column(k)).norm() < 1e-7,
                "w {w:?} column {k}: {num:?} vs {:?}",
                a.column(k)
            );
        }
    }
}
