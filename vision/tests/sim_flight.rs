//! Accuracy on simulated flights (uavnav-sim renderer, JPEG frames) at 150 m above the terrain:
//! relative rotation and translation direction against truth, with a realistic prior (gyro
//! integrated from the noisy IMU, ground normal and height from a slightly wrong attitude and
//! altitude, velocity with noise).

#![allow(clippy::unwrap_used)]

use nalgebra::{Isometry3, Unit, UnitQuaternion, Vector3};
use uavnav_core::rng::Rng;
use uavnav_core::{EgomotionSolver, MotionPrior};
use uavnav_sim::{Flight, Scenario};
use uavnav_vision::prior::gyro_rotation;
use uavnav_vision::{
    FrontEnd, Method, PairError, SolveParams, VisionParams, error_stats, pair_error,
};

fn flight(name: &str) -> Option<Flight> {
    let path = format!("{}/../scenarios/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).ok()?;
    Flight::new(&Scenario::from_toml_str(&text).ok()?).ok()
}

/// Camera pose in the local NED frame at frame `k`.
fn nav_from_cam(f: &Flight, k: usize) -> Isometry3<f64> {
    let t = f.camera_truth(k).expect("frame");
    let mount = f.body_from_cam();
    Isometry3::from_parts(
        f.camera_position_ned(k).expect("pos").into(),
        t.nav_from_body * mount.rotation,
    )
}

/// Errors of the front end over frames `range` (consecutive pairs).
fn run(
    f: &Flight,
    frames: &[uavnav_core::CameraFrame],
    range: std::ops::Range<usize>,
    method: Method,
    aid: bool,
    rng: &mut Rng,
) -> (Vec<PairError>, usize, Vec<EgomotionSolver>) {
    let params = VisionParams {
        imu_aid: aid,
        solve: SolveParams {
            method,
            ..SolveParams::default()
        },
        ..VisionParams::default()
    };
    let mut fe = FrontEnd::new(&f.camera_model(), f.body_from_cam(), params);
    let elev = f.terrain().elevation_m();
    let (mut errs, mut missing, mut solvers) = (Vec::new(), 0usize, Vec::new());
    let times = f.camera_times_ns();
    for k in range.clone() {
        let frame = &frames[k - range.start];
        let prior = if k == range.start {
            MotionPrior::default()
        } else {
            let (c0, c1) = (nav_from_cam(f, k - 1), nav_from_cam(f, k));
            let b1_from_b0 =
                gyro_rotation(f.imu(), times[k - 1], times[k], &Vector3::zeros()).expect("imu");
            // attitude error ~0.3°, height error ~2 m, velocity error ~0.2 m/s
            let att_err = UnitQuaternion::from_scaled_axis(rng.gaussian3(0.3f64.to_radians()));
            let down_nav = Vector3::z();
            let n_cam0 = (att_err * c0.rotation).inverse() * down_nav;
            let height = f.local_frame().ned_to_lla(&c0.translation.vector).alt_m - elev
                + 2.0 * rng.gaussian();
            let rel = c1.inverse() * c0;
            MotionPrior {
                cam1_from_cam0: Some(fe.cam_rotation_from_body(&b1_from_b0)),
                rot_sigma_rad: 1e-3,
                ground_normal_cam0: Some(Unit::new_normalize(n_cam0)),
                ground_distance_m: Some(height),
                t_cam1_m: Some(rel.translation.vector + rng.gaussian3(0.02)),
            }
        };
        let res = fe.process(frame.t_ns, frame.format, &frame.data, &prior);
        if k == range.start {
            continue;
        }
        match res.outcome {
            Ok(e) => {
                let rel = nav_from_cam(f, k).inverse() * nav_from_cam(f, k - 1);
                errs.push(pair_error(&e, &rel.rotation, &rel.translation.vector));
                solvers.push(e.solver);
            }
            Err(_) => missing += 1,
        }
    }
    (errs, missing, solvers)
}

#[test]
fn smoke_flight_accuracy() {
    let Some(f) = flight("smoke") else {
        eprintln!("skipping: scenarios/smoke.toml not found or invalid");
        return;
    };
    let mut rng = Rng::new(77);
    let n = f.camera_times_ns().len();
    // straight (start), turning (middle) — 2 × 12 consecutive frames (rendering dominates the
    // test's time)
    let mut all = Vec::new();
    let mut first = Vec::new();
    for range in [0..12usize, (n / 2)..(n / 2 + 12)] {
        let frames: Vec<_> = range
            .clone()
            .map(|k| f.render_frame(k).expect("render"))
            .collect();
        let (errs, missing, solvers) =
            run(&f, &frames, range.clone(), Method::Auto, true, &mut rng);
        if range.start == 0 {
            first = frames;
        }
        let st = error_stats(&errs);
        eprintln!(
            "smoke {range:?} auto aided: missing {missing}, solvers {:?}\n{st}",
            solvers.iter().map(|s| s.as_str()).collect::<Vec<_>>()
        );
        assert_eq!(missing, 0);
        all.extend(errs);
    }
    let st = error_stats(&all);
    eprintln!("smoke overall (auto, aided):\n{st}");
    assert_eq!(st.t_over_90, 0);
    assert!(st.rot_median_deg <= 0.01, "{st}");
    assert!(st.rot_p95_deg <= 0.05, "{st}");
    assert!(st.t_median_deg <= 1.0, "{st}");
    assert!(st.t_p95_deg <= 3.0, "{st}");
    // the paper's essential solver on the same straight segment, for the record
    let (errs, missing, _) = run(&f, &first, 0..12, Method::Essential, true, &mut rng);
    eprintln!(
        "smoke 0..12 essential: missing {missing}\n{}",
        error_stats(&errs)
    );
}

#[test]
fn paper_flight_accuracy() {
    let Some(f) = flight("paper-small-lever") else {
        eprintln!("skipping: scenarios/paper-small-lever.toml not found or invalid");
        return;
    };
    let mut rng = Rng::new(78);
    let n = f.camera_times_ns().len();
    // 200 m above the terrain, one segment of 12 frames a third into the flight
    let range = (n / 3)..(n / 3 + 12);
    let frames: Vec<_> = range
        .clone()
        .map(|k| f.render_frame(k).expect("render"))
        .collect();
    let (errs, missing, solvers) = run(&f, &frames, range.clone(), Method::Auto, true, &mut rng);
    let st = error_stats(&errs);
    eprintln!(
        "paper-small-lever {range:?} auto aided: missing {missing}, solvers {:?}\n{st}",
        solvers.iter().map(|s| s.as_str()).collect::<Vec<_>>()
    );
    assert_eq!(missing, 0);
    assert_eq!(st.t_over_90, 0);
    assert!(st.rot_median_deg <= 0.01, "{st}");
    assert!(st.rot_p95_deg <= 0.05, "{st}");
    assert!(st.t_median_deg <= 1.0, "{st}");
    assert!(st.t_p95_deg <= 3.0, "{st}");
}
