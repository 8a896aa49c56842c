//! Speed targets: IMU propagation ≤ 2 µs per sample (the whole `push_imu`: output predictor,
//! horizon nominal integration, amortised covariance prediction), one GNSS update ≤ 10 µs (position
//! + velocity gated updates of the 24-state ESKF); also one joint vision update (10 Hz).
//!
//! `eskf_imu_fleet` runs `push_imu` as the service does, vehicles taking turns (2026-12-07: 0.93 µs
//! per sample for one vehicle, 1.26–1.57 µs for 2,000: the cost of a state that left the cache).
//!
//! `CARGO_TARGET_DIR=/work/target-estimator cargo bench -p uavnav-estimator --bench filter`
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::{UnitQuaternion, Vector3};
use uavnav_core::{FilterProfile, ImuSample};
use uavnav_estimator::aid_sources::gnss_pos::{GnssMeas, GnssPosSource, white_noise};
use uavnav_estimator::aid_sources::gnss_vel::GnssVelSource;
use uavnav_estimator::aid_sources::vision;
use uavnav_estimator::{Estimator, EstimatorParams};
use uavnav_sim::{Flight, Scenario};

fn flight() -> Flight {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../scenarios/paper-small-lever.toml"
    ))
    .expect("scenario file");
    let mut s = Scenario::from_toml_str(&text).expect("scenario parses");
    s.duration_s = 40.0;
    Flight::new(&s).expect("flight")
}

fn warmed_up(f: &Flight, profile: FilterProfile, until: usize) -> Estimator {
    let mut vc = f.vehicle_config();
    vc.profile = profile;
    vc.camera = None;
    let mut est = Estimator::new(&vc, EstimatorParams::default(), Some(f.origin()));
    let mut gi = 0;
    for s in &f.imu()[..until] {
        while gi < f.gnss().len() && f.gnss()[gi].t_ns <= s.t_ns {
            est.push_gnss(&f.gnss()[gi]).expect("fix");
            gi += 1;
        }
        est.push_imu(s).expect("imu");
    }
    est
}

fn bench(c: &mut Criterion) {
    let f = flight();
    let start = 4000; // 20 s in: initialised, GNSS fused
    const BATCH: usize = 400;
    let samples: Vec<ImuSample> = f.imu()[start..start + BATCH].to_vec();
    for (name, profile) in [
        ("eskf", FilterProfile::Eskf),
        ("paper", FilterProfile::Paper),
    ] {
        let est = warmed_up(&f, profile, start);
        let mut g = c.benchmark_group(format!("{name}_imu"));
        g.throughput(Throughput::Elements(BATCH as u64));
        g.bench_function("push_imu x400 (no measurements)", |b| {
            b.iter_batched(
                || est.clone(),
                |mut e| {
                    for s in &samples {
                        let _ = std::hint::black_box(e.push_imu(s));
                    }
                    e
                },
                BatchSize::SmallInput,
            )
        });
        g.finish();
    }
    fleet(c, &f, start);
    let est = warmed_up(&f, FilterProfile::Eskf, start);
    let eskf = est.eskf().expect("eskf profile");
    let x = *eskf.nominal().expect("initialised");
    let p0 = *eskf.covariance();
    let lever = Vector3::new(0.0, 2.0, 0.0);
    let m = GnssMeas {
        t_ns: x.t_ns,
        pos_ned_m: x.p + x.q * lever + Vector3::new(0.3, -0.2, 0.5),
        vel_ned_mps: Some(x.v + Vector3::new(0.02, 0.01, -0.03)),
        vel_h_mps: Some((x.v + Vector3::new(0.02, 0.01, -0.03)).xy()),
        sigma_h_m: 1.58,
        sigma_v_m: 2.6,
        sigma_vel_mps: 0.05,
    };
    // One covariance prediction (every `cov_period_s`, 20 ms: every fourth IMU sample at 200 Hz;
    // its cost does not depend on the interval).
    let dynamics = uavnav_estimator::prediction::ErrorDynamics::new(
        &x,
        &uavnav_estimator::prediction::ImuMean {
            gyro: Vector3::new(0.01, -0.02, 0.05),
            accel: Vector3::new(0.3, -0.1, -9.7),
        },
        &Vector3::new(5e-5, 0.0, -4e-5),
        300.0,
    );
    let noise = uavnav_estimator::prediction::ProcessNoise {
        gyro_psd: 1e-8,
        accel_psd: 1e-4,
        gyro_bias_psd: 1e-12,
        accel_bias_psd: 1e-8,
        gm_psd: [0.01, 0.01, 0.02],
        gm_tau_s: 300.0,
    };
    c.bench_function("eskf_cov_propagate (24 states, 10 ms)", |b| {
        b.iter_batched(
            || p0,
            |mut p| {
                dynamics.propagate(&mut p, 0.01, &noise);
                std::hint::black_box(p)
            },
            BatchSize::SmallInput,
        )
    });
    let r = white_noise(&m, 0.9, 0.05);
    let gyro = Vector3::new(0.01, -0.02, 0.05);
    let w_ie = Vector3::new(5e-5, 0.0, -4e-5);
    c.bench_function("eskf_gnss_update (pos+vel)", |b| {
        b.iter_batched(
            || (p0, GnssPosSource::default(), GnssVelSource::default()),
            |(mut p, mut sp, mut sv)| {
                let a = sp.fuse(&x, &mut p, &lever, &m, &r, 3.29, 5_000_000_000, &[]);
                let v = sv.fuse(
                    &x,
                    &mut p,
                    &lever,
                    &gyro,
                    1e-6,
                    &w_ie,
                    &m,
                    3.29,
                    5_000_000_000,
                    &[],
                );
                std::hint::black_box((a, v, p))
            },
            BatchSize::SmallInput,
        )
    });
    // One joint vision update (rotation + metric translation, 6-dof) against a pose clone.
    let mut xc = x;
    xc.clone = Some(uavnav_estimator::state::PoseClone {
        t_ns: x.t_ns - 100_000_000,
        q: x.q,
        p: x.p - x.v * 0.1,
    });
    let mut pc = p0;
    uavnav_estimator::state::augment_clone(&mut pc);
    let bfc = nalgebra::Isometry3::identity();
    let c0 = xc.clone.expect("clone");
    let (t, _) = vision::translation_model(&xc, &c0, &bfc);
    let mut cov = nalgebra::Matrix6::from_diagonal_element(1e-8);
    cov.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(nalgebra::Matrix3::identity() * 3e-4));
    let ego = uavnav_core::Egomotion {
        t0_ns: c0.t_ns,
        t1_ns: xc.t_ns,
        cam1_from_cam0: UnitQuaternion::identity(),
        t_dir_cam1: Some(nalgebra::Unit::new_normalize(t)),
        t_cam1_m: Some(t + Vector3::new(0.01, -0.01, 0.0)),
        scale_distance_m: None,
        rot_cov: cov.fixed_view::<3, 3>(0, 0).into_owned(),
        t_cov: cov.fixed_view::<3, 3>(3, 3).into_owned(),
        joint_cov: cov,
        tracked: 200,
        inliers: 180,
        quality: 0.9,
        solver: uavnav_core::EgomotionSolver::Plane,
    };
    let use_ = vision::VisionUse {
        rotation: true,
        translation: true,
        joint: true,
        cov_scale: 6.0,
        gate_sigma: 3.29,
        scale: vision::PlaneScale::new(200.0, 198.0),
    };
    c.bench_function("eskf_vision_update (joint 6-dof)", |b| {
        b.iter_batched(
            || (pc, vision::VisionSource::default()),
            |(mut p, mut src)| {
                let dx = src.fuse_joint(&xc, &c0, &mut p, &bfc, &ego, &use_);
                std::hint::black_box((dx, p))
            },
            BatchSize::SmallInput,
        )
    });

    // Heading sources, per IMU sample (the yaw bank) and per fused compass sample (issue target:
    // both together ≤ 1 µs per IMU sample).
    let mut bank = uavnav_estimator::yaw_estimator::YawEstimator::default();
    bank.fuse_velocity(0, nalgebra::Vector2::new(3.0, 1.0), 0.3);
    let (gyro, accel) = (
        Vector3::new(0.01, -0.02, 0.1),
        Vector3::new(0.3, -0.2, -9.7),
    );
    c.bench_function(
        "yaw_estimator_predict (5 hypotheses, one IMU sample)",
        |b| {
            b.iter(|| {
                bank.predict(&gyro, &accel, 0.005);
                std::hint::black_box(&bank);
            })
        },
    );
    let field = uavnav_core::magnetic::MagneticModel::field(
        &uavnav_core::Lla::from_deg(45.0, 7.0, 300.0),
        2026.0,
    );
    let m_b = x.q.inverse_transform_vector(&field.ned_t) * 0.7;
    c.bench_function("eskf_mag_heading_update", |b| {
        b.iter_batched(
            || {
                (
                    p0,
                    uavnav_estimator::aid_sources::mag_heading::MagHeadingSource::default(),
                )
            },
            |(mut p, mut src)| {
                let dx = src.fuse(&x, &mut p, &m_b, &field, 0.1, 0.17, 3.29, x.t_ns);
                std::hint::black_box((dx, p))
            },
            BatchSize::SmallInput,
        )
    });
    // The compass calibration (eq. M2), per compass sample it fuses (at most 5 Hz): a learning
    // calibration, 10 m up, the sample 200 ms after the last.
    let c_nb = x.q.to_rotation_matrix().into_inner();
    let p_th = p0
        .fixed_view::<3, 3>(uavnav_estimator::state::ITH, uavnav_estimator::state::ITH)
        .into_owned();
    let mut cal =
        uavnav_estimator::aid_sources::mag_calibration::MagCalibration::new(Default::default());
    cal.update(0, &m_b, &c_nb, &p_th, 0.0);
    cal.update(1, &m_b, &c_nb, &p_th, 10.0);
    c.bench_function("eskf_mag_calibration_update", |b| {
        b.iter_batched(
            || cal.clone(),
            |mut cal| {
                let applied = cal.update(200_000_001, &m_b, &c_nb, &p_th, 10.0);
                std::hint::black_box((applied, cal))
            },
            BatchSize::SmallInput,
        )
    });
}

/// `push_imu` as the service runs it: many vehicles, each taking a 20 ms message (4 samples) in
/// turn, so that a vehicle's state has left the cache by the time its next message comes. The
/// single-filter figure above runs with everything cached; this one is what a fleet pays.
#[allow(clippy::disallowed_methods)] // a bench times itself; the estimator it times reads no clock
fn fleet(c: &mut Criterion, f: &Flight, start: usize) {
    const PER_MESSAGE: usize = 4;
    const LAPS: usize = 100;
    let samples: Vec<ImuSample> = f.imu()[start..start + PER_MESSAGE * LAPS].to_vec();
    let est = warmed_up(f, FilterProfile::Eskf, start);
    let mut g = c.benchmark_group("eskf_imu_fleet");
    for vehicles in [1usize, 2000] {
        g.throughput(Throughput::Elements((vehicles * PER_MESSAGE) as u64));
        g.bench_function(
            format!("{vehicles} vehicles, 4 samples each in turn"),
            |b| {
                let mut fleet: Vec<Estimator> = Vec::new();
                let mut lap = LAPS;
                b.iter_custom(|iters| {
                    let mut spent = std::time::Duration::ZERO;
                    for _ in 0..iters {
                        if lap == LAPS {
                            // Each clone's filter on the heap on its own, as in the service's actors.
                            fleet = (0..vehicles).map(|_| est.clone()).collect();
                            // A clone's buffers are cut to their length: one untimed message lets
                            // them grow back to their steady size, as in a long-running service.
                            for e in &mut fleet {
                                for s in &samples[..PER_MESSAGE] {
                                    let _ = e.push_imu(s);
                                }
                            }
                            lap = 1;
                        }
                        let batch = &samples[lap * PER_MESSAGE..(lap + 1) * PER_MESSAGE];
                        let t0 = std::time::Instant::now();
                        for e in &mut fleet {
                            for s in batch {
                                let _ = std::hint::black_box(e.push_imu(s));
                            }
                        }
                        spent += t0.elapsed();
                        lap += 1;
                    }
                    spent
                })
            },
        );
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
