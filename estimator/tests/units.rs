//! Property and unit tests on the maths and the pure helpers.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use proptest::prelude::*;
use uavnav_estimator::aid_sources::chi2_gate;
use uavnav_estimator::init::attitude_from_gravity;
use uavnav_estimator::output::{euler_rate_matrix, euler_sigma};
use uavnav_estimator::paper::heading_without_sideslip;

#[test]
fn chi2_gate_close_to_tables() {
    // χ² quantiles at p = 0.9995 (z = 3.29): 12.12 (1 dof), 15.20 (2), 17.73 (3).
    for (dof, exact) in [(1, 12.12), (2, 15.20), (3, 17.73)] {
        let g = chi2_gate(dof, 3.29);
        assert!(
            (g - exact).abs() / exact < 0.05,
            "dof {dof}: {g} vs {exact}"
        );
    }
}

proptest! {
    #[test]
    fn levelling_recovers_roll_pitch(roll in -1.0f64..1.0, pitch in -1.0f64..1.0, yaw in -3.0f64..3.0,
                                     ax in -5.0f64..5.0, ay in -5.0f64..5.0) {
        let q = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
        let g = Vector3::new(0.0, 0.0, 9.81);
        let a = Vector3::new(ax, ay, 0.0);
        let f_b = q.inverse() * (a - g);
        let est = attitude_from_gravity(&f_b, &(g - a), yaw).unwrap();
        // The specific force direction is reproduced exactly.
        prop_assert!((est * f_b - (a - g)).norm() < 1e-9);
        let (r, p, _) = est.euler_angles();
        if ax == 0.0 && ay == 0.0 {
            prop_assert!((r - roll).abs() < 1e-9 && (p - pitch).abs() < 1e-9);
        }
    }

    #[test]
    fn euler_sigma_maps_body_errors(roll in -1.0f64..1.0, pitch in -1.2f64..1.2, yaw in -3.0f64..3.0) {
        // A nav-frame attitude covariance σ² I gives Euler σ = σ·‖row of J‖ (J from eq. 31).
        let q = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
        let s = euler_sigma(&q, &(Matrix3::identity() * 1e-6));
        let j = euler_rate_matrix(roll, pitch);
        for k in 0..3 {
            prop_assert!((s[k] - 1e-3 * j.row(k).norm()).abs() < 1e-9);
        }
    }

    #[test]
    fn no_sideslip_heading(roll in -0.6f64..0.6, pitch in -0.3f64..0.3, yaw in -3.0f64..3.0, alpha in -0.1f64..0.1) {
        let q = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
        let v_b = Vector3::new(30.0 * alpha.cos(), 0.0, 30.0 * alpha.sin());
        let y = heading_without_sideslip(roll, pitch, &(q * v_b));
        prop_assert!(uavnav_core::rotation::wrap_pi(y - yaw).abs() < 1e-7);
    }
}

#[test]
fn euler_rate_matrix_matches_quaternion_kinematics() {
    // Integrating a body rate for a short time changes the Euler angles by J ω dt.
    let (roll, pitch, yaw) = (0.3, -0.4, 1.0);
    let q = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
    let w = Vector3::new(0.2, -0.1, 0.3);
    let dt = 1e-6;
    let (r2, p2, y2) = (q * UnitQuaternion::from_scaled_axis(w * dt)).euler_angles();
    let fd = Vector3::new(r2 - roll, p2 - pitch, y2 - yaw) / dt;
    assert!((fd - euler_rate_matrix(roll, pitch) * w).norm() < 1e-5);
}

#[test]
fn linearised_lla_is_millimetre_accurate() {
    let frame = uavnav_core::LocalFrame::new(uavnav_core::Lla::from_deg(41.1, 14.2, 250.0));
    let mut lin =
        uavnav_estimator::output::LlaLinearizer::new(frame, &Vector3::new(3000.0, -2000.0, -100.0));
    for k in 0..200 {
        let p = Vector3::new(
            3000.0 + 0.7 * k as f64,
            -2000.0 - 0.3 * k as f64,
            -100.0 + 0.05 * k as f64,
        );
        let a = lin.lla(&p);
        let exact = frame.ned_to_lla(&p);
        let back = frame.lla_to_ned(&a);
        assert!((back - p).norm() < 2e-3, "{k}: {:?}", back - p);
        assert!((a.alt_m - exact.alt_m).abs() < 2e-3);
    }
}
