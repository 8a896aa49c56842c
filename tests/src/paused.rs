//! A paused-time harness for the vehicle actors: uavnavd's registry and ingest path
//! (`uavnavd::server::ingest_path`: no transports, no ports) under tokio's paused clock, so that
//! a test drives idle eviction, health periods and the reorder flush deterministically and in no
//! real time.
//!
//! Start a [`Fleet`] in a current-thread `#[tokio::test]` (tokio pauses time only there): it
//! pauses the clock. [`Fleet::run_for`] then lets time pass: a paused clock jumps to the next
//! timer whenever every task waits, so each actor's health tick, idle check and flush fires in
//! order, as it would in real time. The service reads its monotonic clock through tokio
//! (`uavnavd::vehicle::mono_now`), so what the actors measure is the paused time. The time gate's
//! wall clock is not paused: give each vehicle sensor times close together (as [`Fleet::imu`]
//! does), not as far apart as the paused time that passes.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::{broadcast, watch};
use uavnavd::Config;
use uavnavd::engine::SharedFactory;
use uavnavd::ingest::{Ingestor, Payload, Verdict};
use uavnavd::metrics::{Metrics, Transport};
use uavnavd::registry::Registry;

use crate::pb;

/// The first sensor time of every vehicle, ns.
pub const T0_NS: i64 = 1_000_000_000;
/// The sensor time between two IMU samples [`Fleet::imu`] sends (200 Hz), ns.
pub const IMU_DT_NS: i64 = 5_000_000;

/// The vehicles of a service without transports, on a paused clock.
#[derive(Debug)]
pub struct Fleet {
    ingestor: Ingestor,
    health: broadcast::Receiver<Arc<uavnavd::hub::HealthReport>>,
    /// Kept so that the service is not told to stop.
    _stop: watch::Sender<bool>,
    /// Each vehicle's next IMU sensor time.
    next_t_ns: HashMap<String, i64>,
}

impl Fleet {
    /// Pauses tokio's clock and starts the vehicles' side of the service for `config` with the
    /// product engine. Panics outside a current-thread runtime or when time is already paused.
    pub fn start(config: &Config) -> Self {
        Self::start_with(config, uavnavd::engine::default_factory())
    }

    /// [`Fleet::start`] with a given engine factory.
    pub fn start_with(config: &Config, factory: SharedFactory) -> Self {
        tokio::time::pause();
        let (ingestor, stop) = uavnavd::server::ingest_path(config, factory)
            .unwrap_or_else(|e| panic!("the harness's service did not start: {e:#}"));
        let health = ingestor.registry().ctx().hub.health.subscribe();
        Self {
            ingestor,
            health,
            _stop: stop,
            next_t_ns: HashMap::new(),
        }
    }

    /// The registry.
    pub fn registry(&self) -> &Arc<Registry> {
        self.ingestor.registry()
    }

    /// The service's metrics.
    pub fn metrics(&self) -> &Metrics {
        &self.registry().ctx().metrics
    }

    /// The ids of the live vehicles, sorted.
    pub fn ids(&self) -> Vec<String> {
        let live = self.registry().list("");
        live.iter().map(|h| h.shared.id.to_string()).collect()
    }

    /// Submits `n` level IMU samples of vehicle `id` as one batch, continuing its sensor time at
    /// 200 Hz from [`T0_NS`] (a new vehicle is admitted, or refused, on its first batch).
    pub async fn imu(&mut self, id: &str, n: usize) -> Verdict {
        let t = self.next_t_ns.entry(id.to_owned()).or_insert(T0_NS);
        let samples = (0..n as i64)
            .map(|i| crate::wire::imu(*t + i * IMU_DT_NS))
            .collect();
        let batch = pb::ImuBatch { samples };
        let verdict = self
            .ingestor
            .submit(Transport::Grpc, id, Payload::Imu(&batch))
            .await;
        if verdict.status == pb::IngestStatus::Accepted {
            *t += n as i64 * IMU_DT_NS;
        }
        verdict
    }

    /// Lets `d` of paused time pass, every timer firing in order.
    pub async fn run_for(&self, d: Duration) {
        tokio::time::sleep(d).await;
        // Actors whose timers fell due at the same instant as ours run before we look.
        for _ in 0..8 {
            tokio::task::yield_now().await;
        }
    }

    /// The health reports published so far (every vehicle's, oldest first) that the harness has
    /// not returned before.
    pub fn health_reports(&mut self) -> Vec<Arc<pb::VehicleHealth>> {
        self.tagged_health_reports()
            .into_iter()
            .map(|r| Arc::clone(&r.health))
            .collect()
    }

    /// As [`Self::health_reports`], with whether each repeats the vehicle's previous report.
    pub fn tagged_health_reports(&mut self) -> Vec<Arc<uavnavd::hub::HealthReport>> {
        let mut out = Vec::new();
        loop {
            match self.health.try_recv() {
                Ok(h) => out.push(h),
                Err(broadcast::error::TryRecvError::Lagged(n)) => {
                    panic!("the harness missed {n} health reports (ring overrun)")
                }
                Err(_) => return out,
            }
        }
    }
}
