//! Real images from `../shared/data` (skipped with a message when absent): KITTI 0→5 and 0→4
//! against the OXTS poses, the static EuRoC frames, and the EuRoC `lcd_pairs` 2→3 with a gyro
//! prior.

#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use uavnav_core::{CameraModel, Distortion, EgomotionSolver, ImageFormat, ImuSample, MotionPrior};
use uavnav_vision::prior::gyro_rotation;
use uavnav_vision::{FrontEnd, VisionParams, pair_error};

fn data_dir(sub: &str) -> Option<PathBuf> {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data")).join(sub);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("skipping: {} not found", p.display());
        None
    }
}

fn numbers(line: &str) -> Vec<f64> {
    line.split(|c: char| c.is_whitespace() || c == ',')
        .filter_map(|s| s.parse().ok())
        .collect()
}

fn calib_row(text: &str, key: &str) -> Vec<f64> {
    let line = text
        .lines()
        .find(|l| l.starts_with(&format!("{key}:")))
        .unwrap();
    numbers(&line[key.len() + 1..])
}

fn iso(r: &[f64], t: &[f64]) -> Isometry3<f64> {
    let m = Matrix3::from_row_slice(&r[..9]);
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&m));
    Isometry3::from_parts(Translation3::new(t[0], t[1], t[2]), q)
}

/// OXTS pose (KITTI devkit: Mercator with the scale of frame 0, `R = Rz(yaw) Ry(pitch) Rx(roll)`).
fn oxts_pose(v: &[f64], scale: f64) -> Isometry3<f64> {
    let er = 6_378_137.0;
    let (lat, lon, alt) = (v[0], v[1], v[2]);
    let mx = scale * lon.to_radians() * er;
    let my = scale * er * ((90.0 + lat).to_radians() / 2.0).tan().ln();
    let q = UnitQuaternion::from_euler_angles(v[3], v[4], v[5]);
    Isometry3::from_parts(Translation3::new(mx, my, alt), q)
}

#[test]
fn kitti_frames_0_to_5() {
    let Some(root) = data_dir("kitti_raw_2011_09_26_drive_0001_mini/2011_09_26") else {
        return;
    };
    let cam_txt = std::fs::read_to_string(root.join("calib_cam_to_cam.txt")).unwrap();
    let p = calib_row(&cam_txt, "P_rect_00");
    let camera = CameraModel {
        width: 1242,
        height: 375,
        fx: p[0],
        fy: p[5],
        cx: p[2],
        cy: p[6],
        distortion: Distortion::None,
    };
    let rrect = calib_row(&cam_txt, "R_rect_00");
    let rect_from_cam0 = iso(&rrect, &[0.0, 0.0, 0.0]);
    let iv = std::fs::read_to_string(root.join("calib_imu_to_velo.txt")).unwrap();
    let vc = std::fs::read_to_string(root.join("calib_velo_to_cam.txt")).unwrap();
    let velo_from_imu = iso(&calib_row(&iv, "R"), &calib_row(&iv, "T"));
    let cam0_from_velo = iso(&calib_row(&vc, "R"), &calib_row(&vc, "T"));
    let cam_from_imu = rect_from_cam0 * cam0_from_velo * velo_from_imu;
    let seq = root.join("2011_09_26_drive_0001_sync");
    let ox: Vec<Vec<f64>> = (0..5)
        .map(|k| {
            numbers(&std::fs::read_to_string(seq.join(format!("oxts/data/{k:010}.txt"))).unwrap())
        })
        .collect();
    let scale = ox[0][0].to_radians().cos();
    let mut world_from_cam: Vec<Isometry3<f64>> = ox
        .iter()
        .map(|v| oxts_pose(v, scale) * cam_from_imu.inverse())
        .collect();
    // OXTS stops at frame 4: extrapolate frame 5 with the 3→4 motion (straight, ~constant
    // speed; the camera gaps 3→4 and 4→5 are 103.1 and 103.0 ms). The alternatives agree with it
    // to ≤ 0.06° over 0→5: the 3→4 step scaled by the camera or OXTS time gaps, the OXTS body
    // rates of frame 4 (wx, wy, wz) over the camera gap, or those rates extrapolated linearly.
    let step = world_from_cam[3].inverse() * world_from_cam[4];
    world_from_cam.push(world_from_cam[4] * step);
    let frame = |k: usize| std::fs::read(seq.join(format!("image_00/data/{k:010}.png"))).unwrap();
    let truth = |a: usize, b: usize| world_from_cam[b].inverse() * world_from_cam[a];
    // consecutive pairs 0→1 … 4→5 (10 Hz), as the front end runs
    let mut fe = FrontEnd::new(&camera, Isometry3::identity(), VisionParams::default());
    let _ = fe.process(0, ImageFormat::Png, &frame(0), &MotionPrior::default());
    for k in 1..=5usize {
        let res = fe.process(
            k as i64 * 103_000_000,
            ImageFormat::Png,
            &frame(k),
            &MotionPrior::default(),
        );
        let ego = res
            .outcome
            .as_ref()
            .unwrap_or_else(|e| panic!("{}→{k}: no measurement: {e}", k - 1));
        let tr = truth(k - 1, k);
        let err = pair_error(ego, &tr.rotation, &tr.translation.vector);
        let (rot_deg, dir_deg) = (
            err.rot_err_rad.to_degrees(),
            err.t_dir_err_rad.unwrap_or(f64::NAN).to_degrees(),
        );
        eprintln!(
            "KITTI {}→{k}: {:?}, tracked {}, inliers {}, rotation err {rot_deg:.4}° (true {:.3}°), direction err {dir_deg:.3}°",
            k - 1,
            ego.solver,
            ego.tracked,
            ego.inliers,
            tr.rotation.angle().to_degrees()
        );
        assert!(rot_deg < 0.2, "{}→{k}: rotation err {rot_deg}°", k - 1);
        assert!(dir_deg < 3.0, "{}→{k}: direction err {dir_deg}°", k - 1);
    }
    // The direct pairs 0→4 (OXTS at both ends) and 0→5 (5.4 and 6.7 m of forward motion).
    // Near features change scale by 25–50 % and are lost; the survivors are mostly far, where
    // yaw and roll trade off against the focus of expansion, and a few consistent but wrong
    // tracks remain (aliased on the dashed lane marking, the rail sleepers, a pole's shadow:
    // they pass the forward–backward check). The far tracks fit the OXTS motion to ≈ 0.1 px; a
    // least-squares fit on the 1 px inliers of the best-counted RANSAC model bent towards the
    // wrong tracks instead and missed by 0.3° (over 40 RANSAC seeds 0→5: 0.34° median, 0.52° p90;
    // 0→4 alike, 0.32° median): the estimate, not the extrapolated reference, was off. The
    // essential solver now ranks models by MSAC cost and refines the best few robustly (see
    // `solve::refine_candidates`). Asserted over ten RANSAC seeds, not one.
    let params = |seed: u64| VisionParams {
        pyramid_levels: 4,
        max_features: 400,
        seed,
        ..VisionParams::default()
    };
    let direct = |a: usize, b: usize, seed: u64| {
        let mut fe = FrontEnd::new(&camera, Isometry3::identity(), params(seed));
        let _ = fe.process(0, ImageFormat::Png, &frame(a), &MotionPrior::default());
        let res = fe.process(
            (b - a) as i64 * 103_000_000,
            ImageFormat::Png,
            &frame(b),
            &MotionPrior::default(),
        );
        let ego = res
            .outcome
            .unwrap_or_else(|e| panic!("{a}→{b}: no measurement: {e}"));
        let tr = truth(a, b);
        let err = pair_error(&ego, &tr.rotation, &tr.translation.vector);
        (
            ego,
            err.rot_err_rad.to_degrees(),
            err.t_dir_err_rad.unwrap_or(f64::NAN).to_degrees(),
        )
    };
    let default_seed = VisionParams::default().seed;
    for b in [4usize, 5] {
        let (ego, rot_deg, dir_deg) = direct(0, b, default_seed);
        let tr = truth(0, b);
        eprintln!(
            "KITTI 0→{b} direct: {:?}, tracked {}, inliers {}, rotation err {rot_deg:.4}° (est {:?}° true {:?}°), direction err {dir_deg:.3}°",
            ego.solver,
            ego.tracked,
            ego.inliers,
            ego.cam1_from_cam0
                .scaled_axis()
                .map(f64::to_degrees)
                .as_slice(),
            tr.rotation.scaled_axis().map(f64::to_degrees).as_slice(),
        );
        assert!(rot_deg < 0.2, "0→{b}: rotation err {rot_deg}°");
        assert!(dir_deg < 3.0, "0→{b}: direction err {dir_deg}°");
    }
    let (mut rots, mut dirs): (Vec<f64>, Vec<f64>) = (0..10u64)
        .map(|k| {
            let (_, r, d) = direct(0, 5, default_seed + 7919 * k);
            (r, d)
        })
        .unzip();
    rots.sort_by(f64::total_cmp);
    dirs.sort_by(f64::total_cmp);
    eprintln!(
        "KITTI 0→5 over 10 RANSAC seeds: rotation err median {:.3}° max {:.3}°, direction err median {:.3}° max {:.3}°",
        rots[5], rots[9], dirs[5], dirs[9]
    );
    assert!(rots[9] < 0.2, "0→5: rotation errors over seeds {rots:?}");
    assert!(dirs[9] < 3.0, "0→5: direction errors over seeds {dirs:?}");
}

fn euroc_camera() -> CameraModel {
    CameraModel {
        width: 752,
        height: 480,
        fx: 458.654,
        fy: 457.296,
        cx: 367.215,
        cy: 248.375,
        distortion: Distortion::RadTan {
            k1: -0.28340811,
            k2: 0.07395907,
            p1: 0.00019359,
            p2: 1.76187114e-05,
        },
    }
}

fn euroc_body_from_cam0() -> Isometry3<f64> {
    let r = [
        0.0148655429818,
        -0.999880929698,
        0.00414029679422,
        0.999557249008,
        0.0149672133247,
        0.025715529948,
        -0.0257744366974,
        0.00375618835797,
        0.999660727178,
    ];
    iso(&r, &[-0.0216401454975, -0.064676986768, 0.00981073058949])
}

#[test]
fn euroc_static_frames_are_rotation_only() {
    let Some(root) = data_dir("euroc_v1_01_easy_kimera/mav0/cam0") else {
        return;
    };
    let list = std::fs::read_to_string(root.join("data.csv")).unwrap();
    let files: Vec<(i64, String)> = list
        .lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| {
            let mut it = l.split(',');
            Some((
                it.next()?.trim().parse().ok()?,
                it.next()?.trim().to_string(),
            ))
        })
        .take(12)
        .collect();
    let mut fe = FrontEnd::new(
        &euroc_camera(),
        euroc_body_from_cam0(),
        VisionParams::default(),
    );
    let mut worst = 0.0f64;
    for (k, (t_ns, f)) in files.iter().enumerate() {
        let data = std::fs::read(root.join("data").join(f)).unwrap();
        let res = fe.process(*t_ns, ImageFormat::Png, &data, &MotionPrior::default());
        if k == 0 {
            continue;
        }
        let ego = res
            .outcome
            .as_ref()
            .unwrap_or_else(|e| panic!("frame {k}: no measurement: {e}"));
        let ang = ego.cam1_from_cam0.angle().to_degrees();
        worst = worst.max(ang);
        assert_eq!(ego.solver, EgomotionSolver::RotationOnly, "frame {k}");
        assert!(ego.t_dir_cam1.is_none());
        assert!(ang <= 0.05, "frame {k}: rotation {ang}°");
    }
    eprintln!(
        "EuRoC static: {} pairs rotation-only, largest rotation {worst:.4}°",
        files.len() - 1
    );
}

#[test]
fn euroc_lcd_pair_2_to_3_with_gyro_prior() {
    let Some(root) = data_dir("euroc_v1_01_easy_kimera") else {
        return;
    };
    let poses = std::fs::read_to_string(root.join("lcd_pairs/poses_world_T_body.csv")).unwrap();
    let pose = |name: &str| -> (i64, Isometry3<f64>) {
        let line = poses.lines().find(|l| l.starts_with(name)).unwrap();
        let f: Vec<&str> = line.split(',').collect();
        let v: Vec<f64> = f[2..].iter().map(|s| s.trim().parse().unwrap()).collect();
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(v[3], v[4], v[5], v[6]));
        (
            f[1].trim().parse().unwrap(),
            Isometry3::from_parts(Translation3::new(v[0], v[1], v[2]), q),
        )
    };
    let (t2, w_b2) = pose("left_img_2/");
    let (t3, w_b3) = pose("left_img_3/");
    let imu_txt = std::fs::read_to_string(root.join("mav0/imu0/data.csv")).unwrap();
    let imu: Vec<ImuSample> = imu_txt
        .lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| {
            let v: Vec<f64> = l.split(',').filter_map(|s| s.trim().parse().ok()).collect();
            let t_ns: i64 = l.split(',').next()?.trim().parse().ok()?;
            (v.len() == 7).then(|| ImuSample {
                t_ns,
                gyro_radps: Vector3::new(v[1], v[2], v[3]),
                accel_mps2: Vector3::new(v[4], v[5], v[6]),
            })
        })
        .collect();
    let b_c = euroc_body_from_cam0();
    // 0.5 s apart (15.6°, 0.32 m at 2–4 m): the residual parallax after the rotation prediction
    // reaches ~50 px, so a deeper pyramid and a larger window than the 20 Hz defaults
    let params = VisionParams {
        pyramid_levels: 5,
        klt: uavnav_vision::klt::KltParams {
            half_window: 7,
            ..Default::default()
        },
        ..VisionParams::default()
    };
    let mut fe = FrontEnd::new(&euroc_camera(), b_c, params);
    // img_3 is 0.5 s *before* img_2: integrate t3→t2 and invert for body3_from_body2
    // gyro bias from the first 4 s, when the MAV stands still on the ground (≈0.08 rad/s on z:
    // 2.3° over these 0.5 s if ignored)
    let still: Vec<&ImuSample> = imu
        .iter()
        .take_while(|s| s.t_ns < imu[0].t_ns + 4_000_000_000)
        .collect();
    let bias = still.iter().fold(Vector3::zeros(), |a, s| a + s.gyro_radps) / still.len() as f64;
    let b2_from_b3 = gyro_rotation(&imu, t3, t2, &bias).unwrap();
    let prior = MotionPrior {
        cam1_from_cam0: Some(fe.cam_rotation_from_body(&b2_from_b3.inverse())),
        rot_sigma_rad: 0.01,
        ..MotionPrior::default()
    };
    let img = |k: u32| std::fs::read(root.join(format!("lcd_pairs/left_img_{k}.png"))).unwrap();
    let _ = fe.process(t2, ImageFormat::Png, &img(2), &MotionPrior::default());
    let res = fe.process(t3, ImageFormat::Png, &img(3), &prior);
    let truth = (w_b3 * b_c).inverse() * (w_b2 * b_c);
    let prior_err = (prior.cam1_from_cam0.unwrap() * truth.rotation.inverse())
        .angle()
        .to_degrees();
    eprintln!(
        "EuRoC lcd 2→3: gyro prior error {prior_err:.3}° (true rotation {:.2}°), tracked {}",
        truth.rotation.angle().to_degrees(),
        res.tracked
    );
    let ego = res
        .outcome
        .as_ref()
        .unwrap_or_else(|e| panic!("no measurement: {e}"));
    let err = pair_error(ego, &truth.rotation, &truth.translation.vector);
    eprintln!(
        "EuRoC lcd 2→3: solver {:?}, tracked {}, inliers {}, true rotation {:.2}°, gyro prior err {prior_err:.3}°, rotation err {:.3}°, direction err {:.2}°",
        ego.solver,
        ego.tracked,
        ego.inliers,
        truth.rotation.angle().to_degrees(),
        err.rot_err_rad.to_degrees(),
        err.t_dir_err_rad.unwrap_or(f64::NAN).to_degrees()
    );
    assert!(err.rot_err_rad.to_degrees() < 1.0);
}
