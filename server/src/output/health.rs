//! Per-vehicle health reports, made by each actor at a fixed rate: mode, input rates, counters,
//! vision quality, innovation test ratios and ingest-to-pose latency over the last period.

use std::sync::Arc;
use std::time::Instant;

use uavnav_proto::v1 as pb;

use crate::vehicle::engine::EngineHealth;
use crate::vehicle::{INPUT_KINDS, InputKind, VehicleShared, VehicleStats, wall_ns};

/// The kinds in the order of [`HealthWindow`]'s counts.
const KINDS: [InputKind; INPUT_KINDS] = [
    InputKind::Imu,
    InputKind::Gnss,
    InputKind::Mag,
    InputKind::Baro,
    InputKind::Camera,
];

/// Latency samples kept per period (a uniform subsample beyond it keeps memory flat).
const MAX_LATENCY_SAMPLES: usize = 4096;

/// What one actor remembers between two health reports.
#[derive(Debug)]
pub struct HealthWindow {
    since: Instant,
    counts_at_start: [u64; INPUT_KINDS],
    latencies_s: Vec<f64>,
    latency_seen: u64,
    /// Vision quality is kept from report to report (a camera at 1 Hz must not flicker).
    last_vision: Option<pb::VisionQuality>,
}

impl HealthWindow {
    /// A window starting now.
    pub fn new(now: Instant) -> Self {
        Self {
            since: now,
            counts_at_start: [0; INPUT_KINDS],
            latencies_s: Vec::new(),
            latency_seen: 0,
            last_vision: None,
        }
    }

    /// Records one ingest-to-pose latency.
    pub fn latency(&mut self, latency_s: f64) {
        self.latency_seen += 1;
        if self.latencies_s.len() < MAX_LATENCY_SAMPLES {
            self.latencies_s.push(latency_s);
        } else {
            // Deterministic decimation: overwrite slots round-robin (no RNG on the hot path).
            let i = (self.latency_seen as usize) % MAX_LATENCY_SAMPLES;
            self.latencies_s[i] = latency_s;
        }
    }

    /// Builds the report for the period ending `now` and starts the next period.
    pub fn report(
        &mut self,
        shared: &VehicleShared,
        engine: &EngineHealth,
        reorder_depth: usize,
        now: Instant,
    ) -> pb::VehicleHealth {
        let st = &shared.stats;
        let counts = KINDS.map(|k| VehicleStats::get(st.of(k)));
        let dt_s = now.duration_since(self.since).as_secs_f64().max(1e-6);
        let rate = |k: InputKind| {
            let i = k as usize;
            counts[i].saturating_sub(self.counts_at_start[i]) as f64 / dt_s
        };
        let input_rates = pb::SensorRates {
            imu_hz: rate(InputKind::Imu),
            gnss_hz: rate(InputKind::Gnss),
            camera_hz: rate(InputKind::Camera),
            mag_hz: rate(InputKind::Mag),
            baro_hz: rate(InputKind::Baro),
        };
        let count = |k: InputKind| counts[k as usize];
        if engine.vision.is_some() {
            self.last_vision = engine.vision;
        }
        let report = pb::VehicleHealth {
            vehicle_id: shared.id.to_string(),
            t_ns: engine.t_ns,
            wall_ns: wall_ns(),
            mode: engine.mode as i32,
            input_rates: Some(input_rates),
            latency: Some(latency_stats(&mut self.latencies_s)),
            innovation_ratios: Some(engine.innovation),
            counters: Some(pb::InputCounters {
                accepted: st.accepted(),
                rejected: VehicleStats::get(&st.rejected),
                late: VehicleStats::get(&st.late),
                shed: VehicleStats::get(&st.shed),
                dropped: VehicleStats::get(&st.dropped),
                gnss_gate_rejections: engine.gnss_gate_rejections,
                vision_gate_rejections: engine.vision_gate_rejections,
                imu_accepted: count(InputKind::Imu),
                gnss_accepted: count(InputKind::Gnss),
                mag_accepted: count(InputKind::Mag),
                baro_accepted: count(InputKind::Baro),
                camera_accepted: count(InputKind::Camera),
                imu_clipped: engine.imu_clipped,
                imu_gaps_bridged: engine.imu_gaps_bridged,
            }),
            vision: if shared.camera().is_some() {
                self.last_vision
            } else {
                None
            },
            reorder_depth: reorder_depth.min(u32::MAX as usize) as u32,
            configured: shared.configured.load(std::sync::atomic::Ordering::Relaxed),
            gnss_velocity_delay_s: engine.gnss_velocity_delay_s,
            heading: engine.heading,
            imu_noise: engine.imu_noise,
        };
        self.since = now;
        self.counts_at_start = counts;
        self.latencies_s.clear();
        report
    }
}

/// One health report as it goes through the hub.
#[derive(Debug, Clone)]
pub struct HealthReport {
    /// The report.
    pub health: Arc<pb::VehicleHealth>,
    /// Nothing in it but the clocks differs from the vehicle's previous report: a quiet vehicle's
    /// periodic reminder that it is there. Zenoh publishes such repeats within a fleet-wide
    /// budget (`zenoh.repeat_health_per_s`), so that one watcher does not make an idle fleet's
    /// reminders cost in proportion to its size; gRPC watchers get every report.
    pub repeat: bool,
    /// The report's number: a vehicle's reports are numbered from 0 since its actor started
    /// (watches decimate by it).
    pub seq: u64,
}

/// Whether `new` says nothing that `prev` did not: the same vehicle, mode, rates, latencies,
/// test ratios, counters, vision quality, reorder depth, configuration, GNSS velocity delay,
/// heading status and IMU noise;
/// only the stream time
/// and the wall clock may differ.
pub fn repeats(prev: &pb::VehicleHealth, new: &pb::VehicleHealth) -> bool {
    // Destructured so that a field added to the message must be placed on one side or the other.
    let pb::VehicleHealth {
        vehicle_id,
        t_ns: _,
        wall_ns: _,
        mode,
        input_rates,
        latency,
        innovation_ratios,
        counters,
        vision,
        reorder_depth,
        configured,
        gnss_velocity_delay_s,
        heading,
        imu_noise,
    } = new;
    *vehicle_id == prev.vehicle_id
        && *mode == prev.mode
        && *input_rates == prev.input_rates
        && *latency == prev.latency
        && *innovation_ratios == prev.innovation_ratios
        && *counters == prev.counters
        && *vision == prev.vision
        && *reorder_depth == prev.reorder_depth
        && *configured == prev.configured
        && *gnss_velocity_delay_s == prev.gnss_velocity_delay_s
        && *heading == prev.heading
        && *imu_noise == prev.imu_noise
}

/// p50 / p99 / max of the samples (all zero when empty).
fn latency_stats(samples: &mut [f64]) -> pb::LatencyStats {
    if samples.is_empty() {
        return pb::LatencyStats::default();
    }
    samples.sort_by(f64::total_cmp);
    let at = |q: f64| samples[((samples.len() - 1) as f64 * q).round() as usize];
    pb::LatencyStats {
        p50_s: at(0.5),
        p99_s: at(0.99),
        max_s: samples[samples.len() - 1],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latency_percentiles() {
        let mut v: Vec<f64> = (1..=100).map(|i| i as f64 / 1000.0).collect();
        let s = latency_stats(&mut v);
        assert!((s.p50_s - 0.050).abs() < 0.0015);
        assert!((s.p99_s - 0.099).abs() < 0.0015);
        assert_eq!(s.max_s, 0.1);
    }

    #[test]
    fn a_quiet_vehicles_second_report_repeats_its_first_and_any_change_does_not() {
        let shared = VehicleShared::new("v".into());
        let t0 = Instant::now();
        let mut w = HealthWindow::new(t0);
        let engine = EngineHealth::default();
        let at = |s: u64| t0 + std::time::Duration::from_secs(s);
        VehicleStats::add(&shared.stats.imu, 200);
        let busy = w.report(&shared, &engine, 0, at(1));
        let first_quiet = w.report(&shared, &engine, 0, at(2));
        let second_quiet = w.report(&shared, &engine, 0, at(12));
        // The rates fell to zero: news.
        assert!(!repeats(&busy, &first_quiet));
        // Ten seconds later nothing but the clocks moved.
        assert_ne!(first_quiet.wall_ns, 0);
        assert!(repeats(&first_quiet, &second_quiet));
        // A refused input, a mode change or another vehicle is news.
        VehicleStats::add(&shared.stats.rejected, 1);
        let refused = w.report(&shared, &engine, 0, at(22));
        assert!(!repeats(&second_quiet, &refused));
        let mut moded = refused.clone();
        moded.mode += 1;
        assert!(!repeats(&refused, &moded));
        let mut other = refused.clone();
        other.vehicle_id = "w".into();
        assert!(!repeats(&refused, &other));
    }

    #[test]
    fn rates_over_the_period() {
        let shared = VehicleShared::new("v".into());
        let t0 = Instant::now();
        let mut w = HealthWindow::new(t0);
        VehicleStats::add(&shared.stats.imu, 200);
        VehicleStats::add(&shared.stats.gnss, 5);
        VehicleStats::add(&shared.stats.mag, 50);
        VehicleStats::add(&shared.stats.baro, 20);
        let r = w.report(
            &shared,
            &EngineHealth::default(),
            0,
            t0 + std::time::Duration::from_secs(2),
        );
        let rates = r.input_rates.unwrap();
        assert!((rates.imu_hz - 100.0).abs() < 1e-9 && (rates.gnss_hz - 2.5).abs() < 1e-9);
        assert!((rates.mag_hz - 25.0).abs() < 1e-9 && (rates.baro_hz - 10.0).abs() < 1e-9);
        let c = r.counters.unwrap();
        assert_eq!(c.accepted, 275);
        assert_eq!(
            (
                c.imu_accepted,
                c.gnss_accepted,
                c.mag_accepted,
                c.baro_accepted
            ),
            (200, 5, 50, 20)
        );
    }
}
