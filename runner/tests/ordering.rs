//! The ordering rule: a runner whose vision jobs come back late (as on the service's worker pool)
//! produces exactly the poses of a runner that runs vision inline.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::collections::VecDeque;

use uavnav_core::SensorEvent;
use uavnav_core::rng::Rng;
use uavnav_runner::{PoseOutput, RunnerParams, VehicleRunner, VisionDone, VisionJob};
use uavnav_sim::{Flight, Scenario};

fn smoke_events(seconds: f64) -> (Flight, Vec<SensorEvent>) {
    let text = include_str!("../../scenarios/smoke.toml");
    let scenario = Scenario::from_toml_str(text).expect("smoke scenario parses");
    let flight = Flight::new(&scenario).expect("smoke flight");
    let t_end = flight.imu()[0].t_ns + (seconds * 1e9) as i64;
    let events: Vec<SensorEvent> = flight
        .events()
        .map(|e| e.expect("event"))
        .take_while(|e| e.t_ns() < t_end)
        .collect();
    (flight, events)
}

fn inline_run(flight: &Flight, events: &[SensorEvent]) -> Vec<PoseOutput> {
    let mut r = VehicleRunner::new(
        flight.vehicle_config(),
        RunnerParams::default(),
        Some(flight.origin()),
    );
    let mut poses = Vec::new();
    for e in events {
        poses.extend(r.push_inline(e.clone()).expect("accepted"));
    }
    poses
}

/// Jobs come back after a random number of later events (0..40), like a busy worker pool.
fn pooled_run(flight: &Flight, events: &[SensorEvent], seed: u64) -> Vec<PoseOutput> {
    let mut r = VehicleRunner::new(
        flight.vehicle_config(),
        RunnerParams::default(),
        Some(flight.origin()),
    );
    let mut rng = Rng::new(seed);
    let mut poses = Vec::new();
    let mut out: VecDeque<(usize, VisionJob)> = VecDeque::new();
    let mut done: Vec<VisionDone> = Vec::new();
    for (i, e) in events.iter().enumerate() {
        let step = r.push(e.clone()).expect("accepted");
        poses.extend(step.poses);
        if let Some(job) = step.job {
            out.push_back((i + (rng.uniform() * 40.0) as usize, job));
        }
        while out.front().is_some_and(|(due, _)| *due <= i) {
            if let Some((_, job)) = out.pop_front() {
                done.push(job.run());
            }
        }
        for d in done.drain(..) {
            let mut step = r.finish_frame(d);
            poses.append(&mut step.poses);
            while let Some(job) = step.job.take() {
                out.push_back((i + (rng.uniform() * 40.0) as usize, job));
            }
        }
    }
    while let Some((_, job)) = out.pop_front() {
        let mut step = r.finish_frame(job.run());
        poses.append(&mut step.poses);
        if let Some(job) = step.job.take() {
            out.push_back((0, job));
        }
    }
    poses
}

#[test]
fn late_vision_results_give_the_inline_poses() {
    let (flight, events) = smoke_events(6.0);
    let a = inline_run(&flight, &events);
    assert!(a.len() > 800, "poses: {}", a.len());
    for seed in [1, 2] {
        let b = pooled_run(&flight, &events, seed);
        assert_eq!(a.len(), b.len(), "seed {seed}");
        assert!(a == b, "seed {seed}: pooled poses differ from inline");
    }
}

#[test]
fn frame_without_camera_config_is_refused_and_harmless() {
    let (flight, events) = smoke_events(2.0);
    let mut config = flight.vehicle_config();
    config.camera = None;
    let mut r = VehicleRunner::new(config, RunnerParams::default(), Some(flight.origin()));
    let mut refused = 0;
    for e in &events {
        match r.push_inline(e.clone()) {
            Ok(_) => {}
            Err(uavnav_runner::RunnerError::NoCamera { .. }) => refused += 1,
            Err(other) => panic!("unexpected refusal: {other}"),
        }
    }
    assert!(refused > 5);
}

#[test]
fn a_job_that_never_returns_is_abandoned_and_the_stream_flows_again() {
    let (flight, events) = smoke_events(6.0);
    let params = RunnerParams {
        max_held_events: 100,
        ..RunnerParams::default()
    };
    let mut r = VehicleRunner::new(flight.vehicle_config(), params, Some(flight.origin()));
    let mut poses = 0usize;
    let mut lost_jobs = Vec::new();
    for e in &events {
        let step = r.push(e.clone()).expect("accepted");
        poses += step.poses.len();
        // The worker never hands the job back (e.g. a pool that refused it).
        lost_jobs.extend(step.job);
    }
    assert!(r.vision_stats().abandoned > 0);
    assert!(r.held_events() <= 100, "held {}", r.held_events());
    assert!(
        poses > 500,
        "poses {poses}: IMU must keep flowing without vision results"
    );
}
