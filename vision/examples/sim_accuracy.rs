//! Accuracy and per-stage time of the front end on longer stretches of the simulated flights
//! than the tests use (developer aid for before/after comparisons of tracking changes).
//!
//! `cargo run --release -p uavnav-vision --example sim_accuracy -- [FRAME_CACHE_DIR]`
//!
//! Frames are rendered by uavnav-sim (slow) and cached as JPEG files in `FRAME_CACHE_DIR`
//! (default `/tmp/uavnav-vision-frames`), so repeated runs only time the front end. The prior is
//! the one of `tests/sim_flight.rs`: gyro integrated from the noisy IMU, ground normal and height
//! from a slightly wrong attitude and altitude, velocity with noise.
#![allow(clippy::disallowed_methods)] // a timing tool: it measures wall time on purpose

use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::{Isometry3, Unit, UnitQuaternion, Vector3};
use uavnav_core::rng::Rng;
use uavnav_core::{ImageFormat, MotionPrior};
use uavnav_sim::{Flight, Scenario};
use uavnav_vision::prior::gyro_rotation;
use uavnav_vision::{
    FrontEnd, Method, PairError, SolveParams, VisionParams, error_stats, pair_error,
};

fn flight(name: &str) -> Result<Flight, String> {
    let path = format!("{}/../scenarios/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{path}: {e}"))?;
    let sc = Scenario::from_toml_str(&text).map_err(|e| format!("{path}: {e}"))?;
    Flight::new(&sc).map_err(|e| format!("{path}: {e}"))
}

/// Camera pose in the local NED frame at frame `k`.
fn nav_from_cam(f: &Flight, k: usize) -> Option<Isometry3<f64>> {
    let t = f.camera_truth(k)?;
    Some(Isometry3::from_parts(
        f.camera_position_ned(k)?.into(),
        t.nav_from_body * f.body_from_cam().rotation,
    ))
}

/// JPEG of frame `k`, from the cache or rendered and cached.
fn frame_jpeg(f: &Flight, dir: &Path, k: usize) -> Result<Vec<u8>, String> {
    let file = dir.join(format!("{k:05}.jpg"));
    if let Ok(d) = std::fs::read(&file) {
        return Ok(d);
    }
    let fr = f.render_frame(k).map_err(|e| e.to_string())?;
    std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    std::fs::write(&file, &fr.data[..]).map_err(|e| e.to_string())?;
    Ok(fr.data.to_vec())
}

/// The prior of the pair `k−1 → k` (noisy like the estimator's).
fn prior(f: &Flight, fe: &FrontEnd, k: usize, rng: &mut Rng) -> Option<MotionPrior> {
    let times = f.camera_times_ns();
    let (c0, c1) = (nav_from_cam(f, k - 1)?, nav_from_cam(f, k)?);
    let b1_from_b0 = gyro_rotation(f.imu(), times[k - 1], times[k], &Vector3::zeros())?;
    let att_err = UnitQuaternion::from_scaled_axis(rng.gaussian3(0.3f64.to_radians()));
    let n_cam0 = (att_err * c0.rotation).inverse() * Vector3::z();
    let height = f.local_frame().ned_to_lla(&c0.translation.vector).alt_m
        - f.terrain().elevation_m()
        + 2.0 * rng.gaussian();
    let rel = c1.inverse() * c0;
    Some(MotionPrior {
        cam1_from_cam0: Some(fe.cam_rotation_from_body(&b1_from_b0)),
        rot_sigma_rad: 1e-3,
        ground_normal_cam0: Some(Unit::new_normalize(n_cam0)),
        ground_distance_m: Some(height),
        t_cam1_m: Some(rel.translation.vector + rng.gaussian3(0.02)),
    })
}

#[derive(Default)]
struct Tally {
    errs: Vec<PairError>,
    missing: usize,
    stages: Vec<[u64; 3]>,
}

fn run_segment(
    f: &Flight,
    frames: &[Vec<u8>],
    start: usize,
    params: VisionParams,
    seed: u64,
    tally: &mut Tally,
) {
    let mut rng = Rng::new(seed);
    let mut fe = FrontEnd::new(&f.camera_model(), f.body_from_cam(), params);
    let origin = Instant::now();
    fe.set_clock(Box::new(move || origin.elapsed().as_micros() as u64));
    let times = f.camera_times_ns();
    for (j, data) in frames.iter().enumerate() {
        let k = start + j;
        let pr = if j == 0 {
            MotionPrior::default()
        } else {
            prior(f, &fe, k, &mut rng).unwrap_or_default()
        };
        let res = fe.process(times[k], ImageFormat::Jpeg, data, &pr);
        if j == 0 {
            continue;
        }
        let t = res.timings;
        tally.stages.push([t.decode_us, t.track_us, t.solve_us]);
        match (res.outcome, nav_from_cam(f, k - 1), nav_from_cam(f, k)) {
            (Ok(e), Some(c0), Some(c1)) => {
                let rel = c1.inverse() * c0;
                tally
                    .errs
                    .push(pair_error(&e, &rel.rotation, &rel.translation.vector));
            }
            _ => tally.missing += 1,
        }
    }
}

fn median(v: &mut [u64]) -> u64 {
    v.sort_unstable();
    v.get(v.len() / 2).copied().unwrap_or(0)
}

fn main() -> Result<(), String> {
    let cache = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "/tmp/uavnav-vision-frames".into()),
    );
    let configs: [(&str, Method, bool); 3] = [
        ("auto aided", Method::Auto, true),
        ("essential aided", Method::Essential, true),
        ("auto unaided", Method::Auto, false),
    ];
    for (name, seg_len) in [("smoke", 40usize), ("paper-small-lever", 40)] {
        let f = flight(name)?;
        let n = f.camera_times_ns().len();
        let starts: Vec<usize> = (1..6).map(|i| i * n / 6 - seg_len / 2).collect();
        let dir = cache.join(name);
        let segs: Vec<(usize, Vec<Vec<u8>>)> = starts
            .iter()
            .map(|&s| {
                let fr = (s..s + seg_len)
                    .map(|k| frame_jpeg(&f, &dir, k))
                    .collect::<Result<Vec<_>, _>>()?;
                Ok((s, fr))
            })
            .collect::<Result<_, String>>()?;
        for (label, method, aid) in configs {
            let params = VisionParams {
                imu_aid: aid,
                solve: SolveParams {
                    method,
                    ..SolveParams::default()
                },
                ..VisionParams::default()
            };
            let mut tally = Tally::default();
            for (s, fr) in &segs {
                run_segment(&f, fr, *s, params, 1000 + *s as u64, &mut tally);
            }
            let col = |j: usize| tally.stages.iter().map(|s| s[j]).collect::<Vec<_>>();
            println!(
                "{name} {label}: {} pairs, missing {}; stage medians decode {} µs, track {} µs, solve {} µs\n{}",
                tally.stages.len(),
                tally.missing,
                median(&mut col(0)),
                median(&mut col(1)),
                median(&mut col(2)),
                error_stats(&tally.errs)
            );
        }
    }
    Ok(())
}
