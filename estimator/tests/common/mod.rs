//! Test support: runs the estimator over a simulated flight, with an egomotion ORACLE synthesized
//! from the simulator truth (tests only — never a default path) until the vision crate lands.
#![allow(dead_code)]

use nalgebra::{Matrix3, Matrix6, Unit, UnitQuaternion, Vector3};
use uavnav_core::rng::Rng;
use uavnav_core::{Egomotion, EgomotionSolver, FilterProfile, TruthSample};
use uavnav_estimator::{Estimator, EstimatorParams, PoseOutput};
use uavnav_sim::{Flight, Scenario};

/// Noise of the synthetic egomotion.
#[derive(Debug, Clone, Copy)]
pub struct Oracle {
    /// Rotation noise per axis, rad.
    pub rot_sigma_rad: f64,
    /// Direction noise per tangent axis, rad.
    pub dir_sigma_rad: f64,
    /// Relative noise of a metric translation (None = direction only).
    pub metric_rel_sigma: Option<f64>,
    /// Scales the metric translation as the plane solver does, by the filter's own distance to
    /// the terrain (its motion prior at delivery) over the true one: `Some(true)` also reports
    /// that distance (`Egomotion::scale_distance_m`), `Some(false)` hides it. Needs
    /// `metric_rel_sigma`.
    pub plane_scaled: Option<bool>,
    /// Delivery latency after frame 1, ns.
    pub latency_ns: i64,
    /// Seed.
    pub seed: u64,
}

impl Default for Oracle {
    fn default() -> Self {
        Self {
            rot_sigma_rad: 0.01f64.to_radians(),
            dir_sigma_rad: 1f64.to_radians(),
            metric_rel_sigma: None,
            plane_scaled: None,
            latency_ns: 40_000_000,
            seed: 7,
        }
    }
}

/// Loads a scenario from the repository's `scenarios/` folder, optionally cut to `duration_s`.
pub fn scenario(name: &str, duration_s: Option<f64>) -> Scenario {
    let path = format!("{}/../scenarios/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap();
    let mut s = Scenario::from_toml_str(&text).unwrap();
    if let Some(d) = duration_s {
        s.duration_s = d;
    }
    s
}

/// The egomotion between two truth samples, with oracle noise.
pub fn synth_egomotion(
    flight: &Flight,
    a: &TruthSample,
    b: &TruthSample,
    o: &Oracle,
    rng: &mut Rng,
) -> Egomotion {
    let bfc = flight.body_from_cam();
    let r_bc = bfc.rotation;
    let t_bc = bfc.translation.vector;
    let r_true = r_bc.inverse() * b.nav_from_body.inverse() * a.nav_from_body * r_bc;
    let c0 = a.pos_ned_m + a.nav_from_body * t_bc;
    let c1 = b.pos_ned_m + b.nav_from_body * t_bc;
    let t_true = (b.nav_from_body * r_bc).inverse() * (c0 - c1);
    let rot = UnitQuaternion::from_scaled_axis(rng.gaussian3(o.rot_sigma_rad)) * r_true;
    let u = t_true.normalize();
    let helper = if u.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let b1 = u.cross(&helper).normalize();
    let b2 = u.cross(&b1);
    let dir =
        (u + b1 * (rng.gaussian() * o.dir_sigma_rad) + b2 * (rng.gaussian() * o.dir_sigma_rad))
            .normalize();
    let rot_cov = Matrix3::identity() * o.rot_sigma_rad.powi(2);
    let (t_m, t_cov) = match o.metric_rel_sigma {
        Some(rel) => {
            let s = rel * t_true.norm();
            (Some(t_true + rng.gaussian3(s)), Matrix3::identity() * s * s)
        }
        None => (
            None,
            (Matrix3::identity() - u * u.transpose()) * o.dir_sigma_rad.powi(2),
        ),
    };
    let mut joint = Matrix6::zeros();
    joint.fixed_view_mut::<3, 3>(0, 0).copy_from(&rot_cov);
    joint.fixed_view_mut::<3, 3>(3, 3).copy_from(&t_cov);
    Egomotion {
        t0_ns: a.t_ns,
        t1_ns: b.t_ns,
        cam1_from_cam0: rot,
        t_dir_cam1: Some(Unit::new_normalize(dir)),
        t_cam1_m: t_m,
        scale_distance_m: None,
        rot_cov,
        t_cov,
        joint_cov: joint,
        tracked: 200,
        inliers: 180,
        quality: 0.9,
        solver: EgomotionSolver::Essential,
    }
}

/// What to feed.
#[derive(Debug, Clone)]
pub struct RunCfg {
    pub profile: FilterProfile,
    pub gnss: bool,
    pub vision: Option<Oracle>,
    pub params: EstimatorParams,
}

impl RunCfg {
    pub fn new(profile: FilterProfile, gnss: bool, vision: Option<Oracle>) -> Self {
        Self {
            profile,
            gnss,
            vision,
            // the oracle's errors are white: no allowance for time-correlated errors
            params: EstimatorParams {
                vision_cov_scale: 1.0,
                paper_chain_cov_scale: 1.0,
                ..EstimatorParams::default()
            },
        }
    }
}

/// Runs one flight through the estimator; returns every output.
pub fn run(flight: &Flight, cfg: &RunCfg) -> Vec<PoseOutput> {
    let mut vc = flight.vehicle_config();
    vc.profile = cfg.profile;
    if cfg.vision.is_none() {
        vc.camera = None;
    }
    let mut est = Estimator::new(&vc, cfg.params.clone(), Some(flight.origin()));
    // (delivery time, egomotion, true camera-0 distance to the terrain)
    let mut egos: Vec<(i64, Egomotion, f64)> = Vec::new();
    if let Some(o) = cfg.vision {
        let mut rng = Rng::derive(o.seed, "oracle-egomotion");
        let n = flight.camera_times_ns().len();
        let frame = uavnav_core::LocalFrame::new(flight.origin());
        let bfc = flight.body_from_cam();
        for k in 1..n {
            let (Some(a), Some(b)) = (flight.camera_truth(k - 1), flight.camera_truth(k)) else {
                continue;
            };
            let m = synth_egomotion(flight, a, b, &o, &mut rng);
            let centre = a.pos_ned_m + a.nav_from_body * bfc.translation.vector;
            let d = frame.ned_to_lla(&centre).alt_m - vc.terrain_elevation_m;
            egos.push((b.t_ns + o.latency_ns, m, d));
        }
    }
    let gnss = if cfg.gnss {
        flight.gnss().to_vec()
    } else {
        Vec::new()
    };
    let (mut gi, mut ei) = (0, 0);
    let mut outs = Vec::with_capacity(flight.imu().len());
    for s in flight.imu() {
        while gi < gnss.len() && gnss[gi].t_ns <= s.t_ns {
            est.push_gnss(&gnss[gi]).unwrap();
            gi += 1;
        }
        while ei < egos.len() && egos[ei].0 <= s.t_ns {
            let (_, m, d_true) = &egos[ei];
            let mut m = m.clone();
            if let (Some(report), Some(t)) = (cfg.vision.and_then(|o| o.plane_scaled), m.t_cam1_m) {
                let d_hat = est.motion_prior(m.t0_ns, m.t1_ns).ground_distance_m;
                if let Some(d_hat) = d_hat {
                    m.t_cam1_m = Some(t * (d_hat / d_true));
                    m.scale_distance_m = report.then_some(d_hat);
                    m.solver = EgomotionSolver::Plane;
                }
            }
            est.push_egomotion(&m).unwrap();
            ei += 1;
        }
        if let Some(o) = est.push_imu(s).unwrap() {
            outs.push(o);
        }
    }
    outs
}

/// Feeds every GNSS fix, compass and barometer sample of the flight in time order before the
/// IMU sample they precede; returns the poses.
pub fn fly_all(est: &mut Estimator, f: &Flight) -> Vec<PoseOutput> {
    fly_where(est, f, |_| true, |_| true)
}

/// [`fly_all`], feeding only the GNSS fixes stamped at a time `gnss` keeps and the other samples
/// at a time `rest` keeps (an outage, a late first fix, a dropped link). An IMU sample the
/// estimator refuses as a time jump (a gap the caller cut, before the restart) gives no pose;
/// any other refusal fails the test.
pub fn fly_where(
    est: &mut Estimator,
    f: &Flight,
    gnss: impl Fn(i64) -> bool,
    rest: impl Fn(i64) -> bool,
) -> Vec<PoseOutput> {
    let (mut g, mut m, mut b) = (0, 0, 0);
    let mut out = Vec::new();
    for s in f.imu() {
        while g < f.gnss().len() && f.gnss()[g].t_ns <= s.t_ns {
            if gnss(f.gnss()[g].t_ns) {
                est.push_gnss(&f.gnss()[g]).unwrap();
            }
            g += 1;
        }
        while m < f.mag().len() && f.mag()[m].t_ns <= s.t_ns {
            if rest(f.mag()[m].t_ns) {
                est.push_mag(&f.mag()[m]).unwrap();
            }
            m += 1;
        }
        while b < f.baro().len() && f.baro()[b].t_ns <= s.t_ns {
            if rest(f.baro()[b].t_ns) {
                est.push_baro(&f.baro()[b]).unwrap();
            }
            b += 1;
        }
        if !rest(s.t_ns) {
            continue;
        }
        match est.push_imu(s) {
            Ok(p) => out.extend(p),
            Err(uavnav_estimator::InputError::TimeJump { .. }) => {}
            Err(e) => panic!("IMU sample at {} ns refused: {e}", s.t_ns),
        }
    }
    out
}

/// The GNSS outage windows of a scenario in ns.
pub fn outages_ns(s: &Scenario) -> Vec<(i64, i64)> {
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
