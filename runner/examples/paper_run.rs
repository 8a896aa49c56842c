//! The whole chain on a simulated paper flight: simulator → rendered JPEG frames → vision front end
//! → estimator, through [`VehicleRunner`] inline (no service, no zenoh). Prints the accuracy
//! figures against the simulator truth, the vision statistics, every vision measurement compared
//! with the true camera motion, and the time spent in the runner.
//!
//! ```text
//! CARGO_TARGET_DIR=/work/target-runner cargo run --release -p uavnav-runner --example paper_run -- \
//!     scenarios/paper-small-lever.toml [--no-vision] [--profile paper] [--duration S] \
//!     [--frames-csv F] [--frame-cache DIR]
//! ```
//!
//! Calibration diagnostics (`support/calib.rs`): the vision errors against their own joint
//! covariance per eigen-direction, their biases and time correlation, the estimator's vision NIS,
//! attitude errors by segment and a yaw / gyro-bias / velocity-error series (`YAW_STEP_S`, 10 s).
//! Experiment switches: `--pixel-sigma PX`, `--metric-scale-sigma REL`, `--normal-sigma-deg D`
//! (vision solver), `--vision-cov-scale K`, `--joint` / `--separate` (estimator),
//! `--gyro-instability-psd Q` (paper profile: overrides `EstimatorParams::paper_gyro_instability_psd`,
//! whose default is derived from the simulated IMU; the paper table uses the default),
//! `--attitude-error-tau S` (paper: `EstimatorParams::paper_attitude_error_tau_s`),
//! `--chain-cov-scale K` (paper: `EstimatorParams::paper_chain_cov_scale`), `--direction-cov-scale K`
//! (paper: `EstimatorParams::paper_direction_cov_scale`), `--no-video-direction`
//! (paper: `EstimatorParams::paper_video_direction = false`, the paper's VIDEO-IMU(1) as written),
//! `--no-gnss-tilt` (paper: `EstimatorParams::paper_gnss_tilt = false`, no roll and pitch from the
//! GNSS acceleration while the video chain is not running).
//! The README "Results" table takes roll/pitch/yaw RMSE, the outage drift and "within 3σ" from the
//! first table row printed, and the position consistency from the `consistency:` line.
//!
//! `--frame-cache DIR` keeps the rendered JPEGs (`DIR/<t_ns>.jpg`) so that later runs skip the
//! renderer; without vision no frame is rendered (the runner gets empty frames and ignores them).
//!
//! The runner's wall and CPU time cover `push_inline` only (estimator + vision on this one thread);
//! the simulator renders frames on its own rayon pool between pushes, outside that time.
#![allow(clippy::unwrap_used, clippy::expect_used)] // examples may unwrap
#![allow(clippy::disallowed_methods)] // a timing tool: it measures wall time on purpose

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::time::{Duration, Instant};

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use uavnav_core::{
    CameraFrame, Egomotion, FilterProfile, ImageFormat, LocalFrame, SensorEvent, TruthSample,
};
use uavnav_report::accuracy::{AccuracyReport, truth_at};
use uavnav_runner::{PoseOutput, RunnerParams, VehicleRunner};
use uavnav_sim::{Flight, Scenario};
use uavnav_vision::{NoMeasurement, PairError, error_stats, pair_error};

#[path = "support/calib.rs"]
mod calib;

struct Args {
    scenario: String,
    vision: bool,
    profile: FilterProfile,
    duration_s: Option<f64>,
    frames_csv: Option<String>,
    frame_cache: Option<String>,
    pixel_sigma_px: Option<f64>,
    vision_cov_scale: Option<f64>,
    metric_scale_sigma: Option<f64>,
    attitude_error_tau_s: Option<f64>,
    joint: Option<bool>,
    normal_sigma_deg: Option<f64>,
    gyro_instability_psd: Option<f64>,
    chain_cov_scale: Option<f64>,
    direction_cov_scale: Option<f64>,
    video_direction: bool,
    gnss_tilt: bool,
}

const USAGE: &str = "usage: paper_run [SCENARIO.toml] [--no-vision] [--profile eskf|paper] [--duration S]
    [--frames-csv F] [--frame-cache DIR] [--pixel-sigma PX] [--metric-scale-sigma REL]
    [--normal-sigma-deg D] [--vision-cov-scale K] [--joint | --separate]
    [--gyro-instability-psd Q] [--chain-cov-scale K] [--direction-cov-scale K]
    [--no-video-direction] [--no-gnss-tilt]
Runs simulator -> rendered frames -> vision -> estimator on one scenario (default
scenarios/paper-small-lever.toml, profile eskf) and prints the accuracy row (roll/pitch/yaw RMSE
after 30 s, outage drift, share of samples within 3 sigma), consistency, vision statistics and time.";

fn parse_args() -> Args {
    let mut a = Args {
        scenario: "scenarios/paper-small-lever.toml".into(),
        vision: true,
        profile: FilterProfile::Eskf,
        duration_s: None,
        frames_csv: None,
        frame_cache: None,
        pixel_sigma_px: None,
        vision_cov_scale: None,
        metric_scale_sigma: None,
        attitude_error_tau_s: None,
        joint: None,
        normal_sigma_deg: None,
        gyro_instability_psd: None,
        chain_cov_scale: None,
        direction_cov_scale: None,
        video_direction: true,
        gnss_tilt: true,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--no-vision" => a.vision = false,
            "--profile" => {
                a.profile = match it.next().as_deref() {
                    Some("paper") => FilterProfile::Paper,
                    Some("eskf") => FilterProfile::Eskf,
                    other => panic!("--profile eskf|paper, got {other:?}"),
                }
            }
            "--duration" => a.duration_s = it.next().and_then(|s| s.parse().ok()),
            "--frames-csv" => a.frames_csv = it.next(),
            "--frame-cache" => a.frame_cache = it.next(),
            "--pixel-sigma" => a.pixel_sigma_px = it.next().and_then(|s| s.parse().ok()),
            "--vision-cov-scale" => a.vision_cov_scale = it.next().and_then(|s| s.parse().ok()),
            "--metric-scale-sigma" => {
                a.metric_scale_sigma = it.next().and_then(|s| s.parse().ok());
            }
            "--joint" => a.joint = Some(true),
            "--normal-sigma-deg" => a.normal_sigma_deg = it.next().and_then(|s| s.parse().ok()),
            "--separate" => a.joint = Some(false),
            "--gyro-instability-psd" => {
                a.gyro_instability_psd = it.next().and_then(|s| s.parse().ok());
            }
            "--attitude-error-tau" => {
                a.attitude_error_tau_s = it.next().and_then(|s| s.parse().ok());
            }
            "--chain-cov-scale" => a.chain_cov_scale = it.next().and_then(|s| s.parse().ok()),
            "--direction-cov-scale" => {
                a.direction_cov_scale = it.next().and_then(|s| s.parse().ok());
            }
            "--no-video-direction" => a.video_direction = false,
            "--no-gnss-tilt" => a.gnss_tilt = false,
            "--help" | "-h" => {
                println!("{USAGE}");
                std::process::exit(0);
            }
            flag if flag.starts_with('-') => {
                eprintln!("unknown flag {flag}\n{USAGE}");
                std::process::exit(2);
            }
            path => a.scenario = path.to_string(),
        }
    }
    a
}

/// The true camera motion between two truth samples, in the [`Egomotion`] convention
/// (`x1 = R x0 + t`): R = nav_from_cam1⁻¹·nav_from_cam0, t = nav_from_cam1⁻¹·(p_cam0 − p_cam1).
fn true_motion(
    flight: &Flight,
    a: &TruthSample,
    b: &TruthSample,
) -> (UnitQuaternion<f64>, Vector3<f64>) {
    let bfc = flight.body_from_cam();
    let nav_from_cam0 = a.nav_from_body * bfc.rotation;
    let nav_from_cam1 = b.nav_from_body * bfc.rotation;
    let p_cam0 = a.pos_ned_m + a.nav_from_body * bfc.translation.vector;
    let p_cam1 = b.pos_ned_m + b.nav_from_body * bfc.translation.vector;
    (
        nav_from_cam1.inverse() * nav_from_cam0,
        nav_from_cam1.inverse() * (p_cam0 - p_cam1),
    )
}

/// Normalised errors of one measurement against its own covariance (≈ dof on average when the
/// covariance is right): rotation (3 dof) and translation (direction: 2 dof; metric: 3 dof).
fn normalised_errors(
    ego: &Egomotion,
    r_true: &UnitQuaternion<f64>,
    t_true: &Vector3<f64>,
) -> (f64, Option<f64>) {
    let d_theta = (ego.cam1_from_cam0 * r_true.inverse()).scaled_axis();
    let nees_rot = ego
        .rot_cov
        .try_inverse()
        .map_or(f64::NAN, |inv| (d_theta.transpose() * inv * d_theta)[0]);
    let e_t = match (ego.t_cam1_m, ego.t_dir_cam1) {
        (Some(t), _) => Some(t - t_true),
        (None, Some(u)) if t_true.norm() > 1e-9 => Some(u.into_inner() - t_true.normalize()),
        _ => None,
    };
    let nees_t = e_t.map(|e| {
        let pinv: Matrix3<f64> = ego
            .t_cov
            .pseudo_inverse(1e-15)
            .unwrap_or_else(|_| Matrix3::zeros());
        (e.transpose() * pinv * e)[0]
    });
    (nees_rot, nees_t)
}

#[derive(Default)]
struct VisionEval {
    errors: Vec<PairError>,
    nees_rot: Vec<f64>,
    nees_t: Vec<f64>,
    metric_rel_err: Vec<f64>,
    nees_joint: Vec<f64>,
    max_corr: Vec<f64>,
    calib: calib::JointCalib,
    reasons: BTreeMap<&'static str, u64>,
    solvers: BTreeMap<String, u64>,
    csv: String,
}

impl VisionEval {
    fn add(&mut self, flight: &Flight, r: &uavnav_vision::FrameResult) {
        let ego = match &r.outcome {
            Ok(ego) => ego,
            Err(reason) => {
                *self.reasons.entry(reason_tag(reason)).or_default() += 1;
                return;
            }
        };
        *self.solvers.entry(format!("{:?}", ego.solver)).or_default() += 1;
        let (Some(a), Some(b)) = (
            truth_at(flight.truth(), ego.t0_ns),
            truth_at(flight.truth(), ego.t1_ns),
        ) else {
            return;
        };
        let (r_true, t_true) = true_motion(flight, &a, &b);
        let e = pair_error(ego, &r_true, &t_true);
        let (nr, nt) = normalised_errors(ego, &r_true, &t_true);
        if let Some(t) = ego.t_cam1_m {
            self.metric_rel_err
                .push((t - t_true).norm() / t_true.norm().max(1e-9));
            // joint [δθ; δt] against the joint covariance (6 expected) and the largest
            // rotation–translation correlation of the solver
            let d_theta = (ego.cam1_from_cam0 * r_true.inverse()).scaled_axis();
            let e = nalgebra::Vector6::new(
                d_theta.x,
                d_theta.y,
                d_theta.z,
                t.x - t_true.x,
                t.y - t_true.y,
                t.z - t_true.z,
            );
            if let Some(inv) = ego.joint_cov.try_inverse() {
                self.nees_joint.push((e.transpose() * inv * e)[0]);
            }
            self.calib.add(ego.t0_ns, &e, &ego.joint_cov, &t_true);
            let c = &ego.joint_cov;
            let corr = (0..3)
                .flat_map(|i| (3..6).map(move |j| (i, j)))
                .map(|(i, j)| (c[(i, j)] / (c[(i, i)] * c[(j, j)]).sqrt()).abs())
                .fold(0.0, f64::max);
            self.max_corr.push(corr);
        }
        let _ = writeln!(
            self.csv,
            "{},{},{:.6},{:.4},{:.3},{:.3},{},{},{:?}",
            ego.t1_ns,
            ego.t1_ns - ego.t0_ns,
            e.rot_err_rad.to_degrees(),
            e.t_dir_err_rad.map_or(f64::NAN, f64::to_degrees),
            nr,
            nt.unwrap_or(f64::NAN),
            ego.tracked,
            ego.inliers,
            ego.solver
        );
        self.errors.push(e);
        self.nees_rot.push(nr);
        if let Some(nt) = nt {
            self.nees_t.push(nt);
        }
    }
}

fn reason_tag(r: &NoMeasurement) -> &'static str {
    r.tag()
}

fn median(v: &[f64]) -> f64 {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return f64::NAN;
    }
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

fn mean(v: &[f64]) -> f64 {
    let s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    s.iter().sum::<f64>() / s.len().max(1) as f64
}

/// CPU time of the calling thread, from `/proc/thread-self/schedstat` (ns on CPU), if readable.
fn thread_cpu_ns() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

fn outages_ns(s: &Scenario) -> Vec<(i64, i64)> {
    s.gnss
        .outages
        .iter()
        .map(|w| {
            (
                s.t0_ns + (w.start_s * 1e9) as i64,
                s.t0_ns + (w.end_s * 1e9) as i64,
            )
        })
        .collect()
}

enum Ev {
    Other(SensorEvent),
    Frame(usize),
}

/// The flight's events in time order (ties: IMU, GNSS, camera), frames by index (rendered lazily).
fn merged_events(flight: &Flight) -> Vec<Ev> {
    let mut v: Vec<(i64, u8, Ev)> = Vec::new();
    v.extend(
        flight
            .imu()
            .iter()
            .map(|s| (s.t_ns, 0, Ev::Other(SensorEvent::Imu(*s)))),
    );
    v.extend(
        flight
            .gnss()
            .iter()
            .map(|f| (f.t_ns, 1, Ev::Other(SensorEvent::Gnss(*f)))),
    );
    v.extend(
        flight
            .camera_times_ns()
            .iter()
            .enumerate()
            .map(|(i, &t)| (t, 2, Ev::Frame(i))),
    );
    v.sort_by_key(|(t, k, _)| (*t, *k));
    v.into_iter().map(|(_, _, e)| e).collect()
}

fn cache_path(dir: &str, flight: &Flight, i: usize) -> String {
    format!("{dir}/{}.jpg", flight.camera_times_ns()[i])
}

/// Renders the missing frames of the cache on every core.
fn fill_cache(flight: &Flight, dir: &str) {
    std::fs::create_dir_all(dir).expect("cache dir");
    let n = flight.camera_times_ns().len();
    let missing: Vec<usize> = (0..n)
        .filter(|&i| !std::path::Path::new(&cache_path(dir, flight, i)).exists())
        .collect();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    std::thread::scope(|sc| {
        for k in 0..threads {
            let missing = &missing;
            sc.spawn(move || {
                for &i in missing.iter().skip(k).step_by(threads) {
                    let f = flight.render_frame(i).expect("frame renders");
                    let path = cache_path(dir, flight, i);
                    std::fs::write(format!("{path}.tmp"), &f.data[..]).expect("frame written");
                    std::fs::rename(format!("{path}.tmp"), path).expect("frame renamed");
                }
            });
        }
    });
}

fn frame(flight: &Flight, i: usize, vision: bool, cache: Option<&str>) -> CameraFrame {
    let t_ns = flight.camera_times_ns()[i];
    let data: std::sync::Arc<[u8]> = match (vision, cache) {
        (false, _) => std::sync::Arc::from(Vec::new()),
        (true, Some(dir)) => std::fs::read(cache_path(dir, flight, i))
            .expect("cached frame")
            .into(),
        (true, None) => return flight.render_frame(i).expect("frame renders"),
    };
    CameraFrame {
        t_ns,
        camera_id: 0,
        format: ImageFormat::Jpeg,
        data,
    }
}

fn main() {
    let args = parse_args();
    let text = std::fs::read_to_string(&args.scenario).expect("scenario file readable");
    let mut scenario = Scenario::from_toml_str(&text).expect("scenario parses");
    if let Some(d) = args.duration_s {
        scenario.duration_s = d;
    }
    let t_sim = Instant::now();
    let flight = Flight::new(&scenario).expect("scenario simulates");
    let sim_s = t_sim.elapsed().as_secs_f64();

    let mut config = flight.vehicle_config();
    config.profile = args.profile;
    let mut params = RunnerParams {
        use_vision: args.vision,
        ..RunnerParams::default()
    };
    if let Some(s) = args.pixel_sigma_px {
        params.vision.solve.pixel_sigma_px = s;
    }
    if let Some(s) = args.vision_cov_scale {
        params.estimator.vision_cov_scale = s;
    }
    if let Some(q) = args.gyro_instability_psd {
        params.estimator.paper_gyro_instability_psd = q;
    }
    if let Some(t) = args.attitude_error_tau_s {
        params.estimator.paper_attitude_error_tau_s = t;
    }
    if let Some(k) = args.chain_cov_scale {
        params.estimator.paper_chain_cov_scale = k;
    }
    if let Some(k) = args.direction_cov_scale {
        params.estimator.paper_direction_cov_scale = k;
    }
    params.estimator.paper_video_direction = args.video_direction;
    params.estimator.paper_gnss_tilt = args.gnss_tilt;
    if let Some(s) = args.metric_scale_sigma {
        params.vision.solve.metric_scale_sigma = s;
    }
    if let Some(d) = args.normal_sigma_deg {
        params.vision.solve.normal_sigma_rad = d.to_radians();
    }
    if let Some(j) = args.joint {
        params.estimator.vision_joint_update = j;
    }
    // the joint update's dimension (metric translation: 6) or rotation 3 + translation 3
    let (nis_rot_dof, nis_trans_dof) = if params.estimator.vision_joint_update {
        (6, 6)
    } else {
        (3, 3)
    };
    let mut nis = calib::NisTracker::new(params.estimator.gate_sigma);
    let mut runner = VehicleRunner::new(config, params, None);
    let truth_frame = LocalFrame::new(flight.origin());

    let mut poses: Vec<PoseOutput> = Vec::with_capacity(flight.imu().len());
    let mut eval = VisionEval::default();
    let mut runner_wall = Duration::ZERO;
    let mut runner_cpu_ns = 0u64;
    let mut events = 0u64;
    let t_total = Instant::now();
    if let (Some(dir), true) = (&args.frame_cache, args.vision) {
        fill_cache(&flight, dir);
    }
    for ev in merged_events(&flight) {
        let ev = match ev {
            Ev::Other(ev) => ev,
            Ev::Frame(i) => {
                SensorEvent::Camera(frame(&flight, i, args.vision, args.frame_cache.as_deref()))
            }
        };
        let frames_before = runner.vision_stats().frames;
        let c0 = thread_cpu_ns();
        let t0 = Instant::now();
        let out = runner.push_inline(ev);
        runner_wall += t0.elapsed();
        if let (Some(a), Some(b)) = (c0, thread_cpu_ns()) {
            runner_cpu_ns += b - a;
        }
        events += 1;
        match out {
            Ok(mut p) => {
                for o in &p {
                    nis.observe(o, nis_rot_dof, nis_trans_dof);
                }
                poses.append(&mut p);
            }
            Err(e) => eprintln!("refused: {e}"),
        }
        if runner.vision_stats().frames != frames_before
            && let Some(r) = runner.last_frame_result()
        {
            eval.add(&flight, r);
        }
    }
    let total_s = t_total.elapsed().as_secs_f64();

    // The runner's local frame starts at the first GNSS fix; the truth's at the scenario origin.
    for p in &mut poses {
        p.pos_ned_m = truth_frame.lla_to_ned(&p.lla);
    }
    let label = format!(
        "{}: {}, {}",
        scenario.name,
        match args.profile {
            FilterProfile::Eskf => "eskf",
            FilterProfile::Paper => "paper",
        },
        if args.vision {
            "GNSS+video"
        } else {
            "GNSS only"
        }
    );
    let report = AccuracyReport::compute(&label, &poses, flight.truth(), &outages_ns(&scenario));
    println!("{}", AccuracyReport::markdown_header());
    println!("{}", report.markdown_row());
    let c = &report.consistency;
    println!(
        "consistency: pos {:.1} %, vel {:.1} %, att {:.1} % within 3σ; mean NEES pos {:.2}, att {:.2} ({} samples)",
        100.0 * c.pos_within_3sigma,
        100.0 * c.vel_within_3sigma,
        100.0 * c.att_within_3sigma,
        c.mean_nees_pos,
        c.mean_nees_att,
        c.samples
    );
    for o in &report.outages {
        println!(
            "outage: horizontal error {:.1} m over {:.0} m flown = {:.2} %, stated σ_h {:.1} m",
            o.horizontal_error_m, o.distance_m, o.percent, o.stated_sigma_h_m
        );
    }

    let t_first = flight.truth().first().map_or(0, |t| t.t_ns);
    println!(
        "{}",
        calib::segment_errors(
            &poses,
            flight.truth(),
            t_first,
            &[(30.0, 120.0), (120.0, 240.0), (240.0, 250.0)]
        )
    );
    println!(
        "{}",
        calib::attitude_series(&poses, flight.truth(), t_first, 10.0)
    );
    println!(
        "{}",
        calib::yaw_series(
            &poses,
            flight.truth(),
            t_first,
            std::env::var("YAW_STEP_S")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(10.0)
        )
    );
    let h = runner.health();
    let s = runner.vision_stats();
    println!(
        "vision: frames {}, measurements {}, no measurement {} {:?}, refused {}, abandoned {}, solvers {:?}",
        s.frames,
        s.measurements,
        s.no_measurement,
        eval.reasons,
        s.refused,
        s.abandoned,
        eval.solvers
    );
    println!(
        "estimator vision gating: rot fused {} rejected {}; trans fused {} rejected {}; no clone {}; late {}",
        h.vision_rot.fused,
        h.vision_rot.rejected,
        h.vision_trans.fused,
        h.vision_trans.rejected,
        h.vision_no_clone,
        h.late_dropped
    );
    if !eval.errors.is_empty() {
        println!("{}", error_stats(&eval.errors));
        println!(
            "vision NEES (own covariance): rotation mean {:.2} median {:.2} (3 expected); translation mean {:.2} median {:.2} (dof expected)",
            mean(&eval.nees_rot),
            median(&eval.nees_rot),
            mean(&eval.nees_t),
            median(&eval.nees_t)
        );
        if !eval.metric_rel_err.is_empty() {
            println!(
                "metric translation: {} measurements, relative error median {:.4}; joint NEES mean {:.2} median {:.2} (6 expected); largest |corr(δθ, δt)| median {:.3}",
                eval.metric_rel_err.len(),
                median(&eval.metric_rel_err),
                mean(&eval.nees_joint),
                median(&eval.nees_joint),
                median(&eval.max_corr)
            );
            println!("{}", eval.calib.summary());
            println!("{}", eval.calib.windowed_means(20.0));
            for n in [10, 50, 200] {
                println!("{}", eval.calib.long_run_inflation(n));
            }
            println!(
                "{}",
                eval.calib.scale_vs_height(
                    &poses,
                    flight.truth(),
                    scenario.terrain.elevation_m,
                    &truth_frame
                )
            );
        }
        println!("{}", nis.summary(nis_rot_dof, nis_trans_dof));
    }
    println!(
        "time: simulate {sim_s:.2} s; runner {:.2} s wall, {:.2} s CPU on 1 thread ({} events, {} poses); total incl. frame loading {total_s:.2} s; {} cores available",
        runner_wall.as_secs_f64(),
        runner_cpu_ns as f64 * 1e-9,
        events,
        poses.len(),
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    if let Some(path) = args.frames_csv {
        let header =
            "t1_ns,dt_ns,rot_err_deg,t_dir_err_deg,nees_rot,nees_t,tracked,inliers,solver\n";
        std::fs::write(&path, format!("{header}{}", eval.csv)).expect("csv written");
    }
}
