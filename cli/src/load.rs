//! The load generator: N vehicles replaying one recorded stream at its real rate, and the
//! measurement of what the service makes of it.
//!
//! Coordinated omission: every message has a *scheduled* send instant (run start + the vehicle's
//! start offset + the message's offset in the recording). Ingest-to-pose latency of a pose is its
//! arrival instant minus the scheduled instant of the IMU batch that carried its sample, never the
//! instant the batch was actually sent: when the sender is held back (back-pressure, a slow
//! service), the delay counts. How late the sends themselves were is recorded as the send lag.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use futures::FutureExt;
use hdrhistogram::Histogram;
use tokio::task::JoinHandle;

use crate::schedule::{TimedMessage, shift_payload};
use uavnav_client::Selector;
use uavnav_client::pb;
use uavnav_client::pb::sensor_envelope::Payload;
use uavnav_client::{Client, ClientError, IngestSender};

/// What one sender task returns: its latency histogram, (vehicle, last t_ns) pairs, messages sent.
type SenderResult = (Histogram<u64>, Vec<(usize, i64)>, u64);

/// One vehicle's recorded stream, looped when the run is longer than the recording.
#[derive(Debug)]
pub struct Recording {
    messages: Vec<TimedMessage>,
    /// Sensor time of the first message.
    t0_ns: i64,
    /// Time shift per lap (span + one sample interval), ns.
    period_ns: i64,
    /// (last sample offset, due offset) of every IMU batch, ascending.
    imu_due: Vec<(i64, i64)>,
    /// The first message is a configuration (not repeated on later laps).
    has_config: bool,
}

impl Recording {
    /// Wraps a schedule (see [`crate::schedule::build`]). Fails when it holds no IMU.
    pub fn new(messages: Vec<TimedMessage>) -> Result<Self, ClientError> {
        let has_config = matches!(
            messages.first().map(|m| &m.payload),
            Some(Payload::Config(_))
        );
        let sensor = messages
            .iter()
            .filter(|m| !matches!(m.payload, Payload::Config(_)));
        let t0_ns = sensor
            .clone()
            .map(|m| m.last_t_ns - m.offset_ns)
            .next()
            .unwrap_or(0);
        let imu_due: Vec<(i64, i64)> = sensor
            .clone()
            .filter(|m| matches!(m.payload, Payload::Imu(_)))
            .map(|m| (m.last_t_ns - t0_ns, m.offset_ns))
            .collect();
        if imu_due.is_empty() {
            return Err(ClientError::Closed("load recording without IMU"));
        }
        let span = sensor.map(|m| m.offset_ns).max().unwrap_or(0);
        let step = imu_due
            .windows(2)
            .map(|w| w[1].0 - w[0].0)
            .filter(|d| *d > 0)
            .min()
            .unwrap_or(5_000_000);
        Ok(Self {
            messages,
            t0_ns,
            period_ns: span + step,
            imu_due,
            has_config,
        })
    }

    /// Span of one lap, ns.
    pub fn period_ns(&self) -> i64 {
        self.period_ns
    }

    /// The same stream with every sensor time `dt_ns` later: a later run can drive the vehicles
    /// of an earlier one under the same ids, their sensor time going on forward.
    pub fn later_by(&self, dt_ns: i64) -> Recording {
        Recording {
            messages: self
                .messages
                .iter()
                .map(|m| TimedMessage {
                    payload: shift_payload(&m.payload, dt_ns),
                    last_t_ns: m.last_t_ns + dt_ns,
                    ..m.clone()
                })
                .collect(),
            t0_ns: self.t0_ns + dt_ns,
            period_ns: self.period_ns,
            imu_due: self.imu_due.clone(),
            has_config: self.has_config,
        }
    }

    /// Messages per lap (without the configuration).
    pub fn messages_per_lap(&self) -> usize {
        self.messages.len() - usize::from(self.has_config)
    }

    /// The `j`-th message of the looped stream: (due offset ns, payload).
    pub fn message(&self, j: usize) -> (i64, Payload) {
        if self.has_config && j == 0 {
            return (0, self.messages[0].payload.clone());
        }
        let base = usize::from(self.has_config);
        let per_lap = self.messages_per_lap();
        let (lap, i) = ((j - base) / per_lap, (j - base) % per_lap);
        let m = &self.messages[base + i];
        let shift = lap as i64 * self.period_ns;
        let payload = if lap == 0 {
            m.payload.clone()
        } else {
            shift_payload(&m.payload, shift)
        };
        (shift + m.offset_ns, payload)
    }

    /// Due offset of the `j`-th message of the looped stream, ns.
    fn due(&self, j: usize) -> i64 {
        if self.has_config && j == 0 {
            return 0;
        }
        let base = usize::from(self.has_config);
        let per_lap = self.messages_per_lap();
        let (lap, i) = ((j - base) / per_lap, (j - base) % per_lap);
        lap as i64 * self.period_ns + self.messages[base + i].offset_ns
    }

    /// Due offset of the IMU batch that carried sample `t_ns` (any lap), ns.
    pub fn due_of_sample(&self, t_ns: i64) -> Option<i64> {
        let rel = t_ns - self.t0_ns;
        if rel < 0 {
            return None; // an earlier run's sample (see `later_by`)
        }
        let lap = rel.div_euclid(self.period_ns);
        let base = rel - lap * self.period_ns;
        let i = self.imu_due.partition_point(|(t, _)| *t < base);
        self.imu_due
            .get(i)
            .map(|(_, due)| lap * self.period_ns + due)
    }
}

/// Shape of one run.
#[derive(Debug, Clone)]
pub struct LoadParams {
    /// Vehicles driven at once.
    pub vehicles: usize,
    /// How long messages are sent.
    pub duration: Duration,
    /// Vehicle ids are `{id_prefix}{index:05}`.
    pub id_prefix: String,
    /// Independent ingest streams (gRPC streams; vehicles are spread over them).
    pub streams: usize,
    /// Pose watch decimation (latency is measured on the poses received).
    pub decimation: u32,
    /// Vehicle start times are spread evenly over this window.
    pub stagger: Duration,
    /// After the last send, how long to wait for outstanding poses.
    pub drain: Duration,
    /// Counters the service already held for these ids before the run (an earlier run's
    /// vehicles driven again, as `--ramp` does): subtracted from the run's own.
    pub baseline: Arc<BTreeMap<String, pb::InputCounters>>,
}

impl Default for LoadParams {
    fn default() -> Self {
        Self {
            vehicles: 10,
            duration: Duration::from_secs(10),
            id_prefix: "load-".into(),
            streams: 4,
            decimation: 1,
            stagger: Duration::from_secs(1),
            drain: Duration::from_secs(2),
            baseline: Arc::default(),
        }
    }
}

/// Limits beyond which a run "fell behind real time" or "failed".
#[derive(Debug, Clone)]
pub struct Thresholds {
    /// Largest acceptable p99 ingest-to-pose latency.
    pub max_p99_latency: Duration,
    /// Largest acceptable p99 lateness of the sends themselves.
    pub max_p99_send_lag: Duration,
    /// Largest acceptable fraction of messages refused or lost.
    pub max_error_rate: f64,
}

impl Default for Thresholds {
    fn default() -> Self {
        Self {
            max_p99_latency: Duration::from_secs(1),
            max_p99_send_lag: Duration::from_millis(500),
            max_error_rate: 0.01,
        }
    }
}

/// Counters readable while the run goes (for a progress bar).
#[derive(Debug, Default)]
pub struct Live {
    /// Messages sent.
    pub sent: AtomicU64,
    /// Poses received.
    pub poses: AtomicU64,
    /// Send failures.
    pub send_errors: AtomicU64,
}

/// The service's own counters, summed over the run's vehicles (latest health of each).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
#[serde(rename_all = "camelCase")]
pub struct ServiceCounters {
    /// Vehicles that reported health.
    pub vehicles_reporting: u64,
    /// Inputs accepted.
    pub accepted: u64,
    /// Inputs rejected.
    pub rejected: u64,
    /// Inputs later than the reorder window.
    pub late: u64,
    /// Camera frames shed by the overload policy.
    pub shed: u64,
    /// Inputs dropped.
    pub dropped: u64,
}

/// Everything one run measured.
#[derive(Debug)]
pub struct LoadOutcome {
    /// The parameters.
    pub params: LoadParams,
    /// Wall time from the first scheduled send to the end of the drain.
    pub elapsed: Duration,
    /// Wall time of the send phase.
    pub send_elapsed: Duration,
    /// Messages scheduled within the duration.
    pub scheduled: u64,
    /// Messages sent.
    pub sent: u64,
    /// Encoded bytes sent.
    pub bytes: u64,
    /// Ingest-to-pose latency, ns (coordinated-omission correct).
    pub latency_ns: Histogram<u64>,
    /// Lateness of the sends, ns.
    pub send_lag_ns: Histogram<u64>,
    /// Poses received.
    pub poses: u64,
    /// Poses whose vehicle or sample was not ours (ignored).
    pub foreign_poses: u64,
    /// Vehicles that produced at least one pose.
    pub vehicles_with_poses: usize,
    /// Vehicles whose newest pose at the end lagged their newest sent sample by more than the latency bound.
    pub vehicles_behind: usize,
    /// Acks by status (`OK`, `LATE`, `PERMISSION_DENIED`, …).
    pub statuses: BTreeMap<String, u64>,
    /// Acks `PERMISSION_DENIED` (vehicles outside the caller's grants) by the service's reason.
    pub permission_denied: BTreeMap<String, u64>,
    /// Transport errors by message.
    pub errors: BTreeMap<String, u64>,
    /// Messages sent but never acknowledged (gRPC).
    pub unacked: u64,
    /// The service's counters (this run's share).
    pub service: ServiceCounters,
    /// Each vehicle's counters in its latest health report (cumulative since it was created).
    pub final_counters: BTreeMap<String, pb::InputCounters>,
    /// Whether poses are expected at all (false for the discarding sink).
    pub expects_poses: bool,
}

impl LoadOutcome {
    /// Messages refused, lost or failed, over messages sent.
    pub fn error_rate(&self) -> f64 {
        let refused: u64 = self
            .statuses
            .iter()
            .filter(|(k, _)| k.as_str() != "OK")
            .map(|(_, v)| v)
            .sum();
        let failed: u64 = self.errors.values().sum();
        (refused + failed + self.unacked) as f64 / (self.sent.max(1)) as f64
    }

    /// Messages sent per second of the send phase.
    pub fn rps(&self) -> f64 {
        self.sent as f64 / self.send_elapsed.as_secs_f64().max(1e-9)
    }

    /// Why the run did not keep up (empty = it did).
    pub fn failures(&self, t: &Thresholds) -> Vec<String> {
        let mut out = Vec::new();
        let lag99 = Duration::from_nanos(self.send_lag_ns.value_at_quantile(0.99));
        if lag99 > t.max_p99_send_lag {
            out.push(format!(
                "p99 send lag {lag99:?} > {:?} (sender held back)",
                t.max_p99_send_lag
            ));
        }
        if self.sent < self.scheduled {
            out.push(format!(
                "only {} of {} scheduled messages sent",
                self.sent, self.scheduled
            ));
        }
        // Shedding camera frames is the service's own overload signal: not sustained.
        if self.service.shed > 0 {
            out.push(format!(
                "the service shed {} camera frames (vision overloaded)",
                self.service.shed
            ));
        }
        // Not a capacity problem but a misconfigured run: say why instead of a bare error rate.
        let denied: u64 = self.permission_denied.values().sum();
        if denied > 0 {
            out.push(format!(
                "{denied} messages refused with PERMISSION_DENIED (the credentials' grants do not \
                 cover the vehicle ids; --id-prefix must be inside the fleet)"
            ));
        }
        let rate = self.error_rate();
        if rate > t.max_error_rate {
            out.push(format!("error rate {:.4} > {:.4}", rate, t.max_error_rate));
        }
        if self.expects_poses {
            let p99 = Duration::from_nanos(self.latency_ns.value_at_quantile(0.99));
            if self.latency_ns.is_empty() {
                out.push("no pose received".into());
            } else if p99 > t.max_p99_latency {
                out.push(format!(
                    "p99 ingest-to-pose latency {p99:?} > {:?}",
                    t.max_p99_latency
                ));
            }
            let silent = self.params.vehicles - self.vehicles_with_poses.min(self.params.vehicles);
            if silent > 0 {
                out.push(format!("{silent} vehicles produced no pose"));
            }
            if self.vehicles_behind > 0 {
                out.push(format!(
                    "{} vehicles' poses ended more than {:?} behind their inputs",
                    self.vehicles_behind, t.max_p99_latency
                ));
            }
        }
        out
    }
}

/// Per-vehicle pose bookkeeping.
#[derive(Debug, Clone, Copy, Default)]
struct VehicleSeen {
    last_pose_t_ns: Option<i64>,
    last_sent_t_ns: i64,
}

fn histogram() -> Histogram<u64> {
    // 1 µs … 1 h at 3 significant figures.
    Histogram::new_with_bounds(1_000, 3_600_000_000_000, 3)
        .expect("constant, valid histogram bounds")
}

/// Vehicle `k`'s start offset, ns.
fn start_offset_ns(k: usize, params: &LoadParams) -> i64 {
    let n = params.vehicles.max(1) as i64;
    params.stagger.as_nanos() as i64 * k as i64 / n
}

/// Runs one load test against `client`.
pub async fn run(
    client: &Client,
    rec: Arc<Recording>,
    params: LoadParams,
    live: Arc<Live>,
) -> Result<LoadOutcome, ClientError> {
    let expects_poses = !matches!(client.endpoint(), uavnav_client::Endpoint::Discard);
    let sel = Selector::prefix(params.id_prefix.clone()).with_decimation(params.decimation);
    let mut poses = client.watch_poses(sel.clone()).await?;
    let mut health = client
        .watch_health(Selector::prefix(params.id_prefix.clone()))
        .await?;
    // Zenoh subscriptions need a moment to propagate before the first put.
    if client.zenoh_session().is_some() {
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
    let streams = params.streams.clamp(1, params.vehicles.max(1));
    let mut ingests = Vec::with_capacity(streams);
    for _ in 0..streams {
        ingests.push(client.ingest().await?);
    }
    let start = Instant::now() + Duration::from_millis(50);
    let duration_ns = params.duration.as_nanos() as i64;
    let mut senders: Vec<JoinHandle<SenderResult>> = Vec::new();
    for (s, ing) in ingests.iter().enumerate() {
        let vehicles: Vec<usize> = (s..params.vehicles).step_by(streams).collect();
        senders.push(tokio::spawn(send_loop(
            ing.sender(),
            Arc::clone(&rec),
            params.clone(),
            vehicles,
            start,
            duration_ns,
            Arc::clone(&live),
        )));
    }

    // Receive poses and health until the senders are done plus the drain time.
    let mut seen = vec![VehicleSeen::default(); params.vehicles];
    let mut latency = histogram();
    let (mut pose_count, mut foreign) = (0u64, 0u64);
    let mut latest_health: BTreeMap<String, pb::VehicleHealth> = BTreeMap::new();
    let senders_done = futures::future::join_all(senders);
    tokio::pin!(senders_done);
    let mut send_results = None;
    let mut drain_deadline: Option<tokio::time::Instant> = None;
    'run: loop {
        let deadline = drain_deadline
            .unwrap_or_else(|| tokio::time::Instant::now() + Duration::from_secs(3600));
        tokio::select! {
            r = &mut senders_done, if send_results.is_none() => {
                send_results = Some(r);
                drain_deadline = Some(tokio::time::Instant::now() + if expects_poses { params.drain } else { Duration::ZERO });
            }
            p = poses.next() => {
                // This pose, then every pose already received, without going back through the
                // select (at fleet scale poses arrive at IMU rate for every vehicle).
                let mut p = p;
                loop {
                    match p {
                        Some(Ok(p)) => {
                            let now = Instant::now();
                            live.poses.fetch_add(1, Ordering::Relaxed);
                            match vehicle_index(&p.vehicle_id, &params).zip(rec.due_of_sample(p.t_ns)) {
                                Some((k, due)) => {
                                    pose_count += 1;
                                    let scheduled = start + Duration::from_nanos((start_offset_ns(k, &params) + due).max(0) as u64);
                                    let lat = now.saturating_duration_since(scheduled).as_nanos() as u64;
                                    let _ = latency.record(lat.max(1));
                                    let s = &mut seen[k];
                                    s.last_pose_t_ns = Some(s.last_pose_t_ns.map_or(p.t_ns, |t| t.max(p.t_ns)));
                                }
                                None => foreign += 1,
                            }
                        }
                        Some(Err(e)) => return Err(e),
                        None => break 'run,
                    }
                    match poses.next().now_or_never() {
                        Some(next) => p = next,
                        None => break,
                    }
                }
            },
            h = health.next() => if let Some(Ok(h)) = h {
                latest_health.insert(h.vehicle_id.clone(), h);
            },
            _ = tokio::time::sleep_until(deadline), if drain_deadline.is_some() => break,
        }
    }
    let elapsed = start.elapsed();
    let mut send_lag = histogram();
    let mut send_elapsed = Duration::ZERO;
    for r in send_results.unwrap_or_default() {
        match r {
            Ok((lag, last_sent, elapsed_ns)) => {
                let _ = send_lag.add(&lag);
                for (k, t) in last_sent {
                    seen[k].last_sent_t_ns = t;
                }
                send_elapsed = send_elapsed.max(Duration::from_nanos(elapsed_ns));
            }
            Err(e) => {
                return Err(ClientError::Closed(if e.is_panic() {
                    "load sender panicked"
                } else {
                    "load sender cancelled"
                }));
            }
        }
    }
    let mut stats = Vec::new();
    for ing in ingests {
        stats.push(ing.finish(Duration::from_secs(5)).await);
    }
    let mut outcome = LoadOutcome {
        scheduled: scheduled_count(&rec, &params),
        sent: stats.iter().map(|s| s.sent.load(Ordering::Relaxed)).sum(),
        bytes: stats.iter().map(|s| s.bytes.load(Ordering::Relaxed)).sum(),
        unacked: 0,
        statuses: BTreeMap::new(),
        permission_denied: BTreeMap::new(),
        errors: BTreeMap::new(),
        elapsed,
        send_elapsed,
        latency_ns: latency,
        send_lag_ns: send_lag,
        poses: pose_count,
        foreign_poses: foreign,
        vehicles_with_poses: seen.iter().filter(|s| s.last_pose_t_ns.is_some()).count(),
        vehicles_behind: 0,
        service: service_counters(&latest_health, &params.baseline),
        final_counters: latest_health
            .iter()
            .filter_map(|(id, h)| Some((id.clone(), h.counters?)))
            .collect(),
        expects_poses,
        params: params.clone(),
    };
    for s in &stats {
        for (k, v) in s.statuses() {
            *outcome.statuses.entry(k).or_default() += v;
        }
        for (k, v) in s.errors() {
            *outcome.errors.entry(k).or_default() += v;
        }
        for (k, v) in s.permission_denied() {
            *outcome.permission_denied.entry(k).or_default() += v;
        }
        if matches!(client.endpoint(), uavnav_client::Endpoint::Grpc { .. }) {
            outcome.unacked += s
                .sent
                .load(Ordering::Relaxed)
                .saturating_sub(s.acked.load(Ordering::Relaxed));
        }
    }
    let bound_ns = Thresholds::default().max_p99_latency.as_nanos() as i64;
    outcome.vehicles_behind = seen
        .iter()
        .filter(|s| {
            s.last_pose_t_ns
                .is_some_and(|t| s.last_sent_t_ns - t > bound_ns)
        })
        .count();
    Ok(outcome)
}

fn vehicle_index(id: &str, params: &LoadParams) -> Option<usize> {
    let k: usize = id.strip_prefix(&params.id_prefix)?.parse().ok()?;
    (k < params.vehicles).then_some(k)
}

/// Messages due within the duration over all vehicles.
fn scheduled_count(rec: &Recording, params: &LoadParams) -> u64 {
    let d = params.duration.as_nanos() as i64;
    let mut n = 0u64;
    for k in 0..params.vehicles {
        let off = start_offset_ns(k, params);
        let mut j = 0;
        while rec.due(j) + off < d {
            n += 1;
            j += 1;
        }
    }
    n
}

/// Vehicle id of index `k`.
pub fn vehicle_id(prefix: &str, k: usize) -> String {
    format!("{prefix}{k:05}")
}

/// Sends the messages of `vehicles` on schedule. Returns the send-lag histogram, each vehicle's
/// newest sent IMU sample time and the send phase's length.
async fn send_loop(
    sender: IngestSender,
    rec: Arc<Recording>,
    params: LoadParams,
    vehicles: Vec<usize>,
    start: Instant,
    duration_ns: i64,
    live: Arc<Live>,
) -> (Histogram<u64>, Vec<(usize, i64)>, u64) {
    let ids: Vec<String> = vehicles
        .iter()
        .map(|k| vehicle_id(&params.id_prefix, *k))
        .collect();
    let mut last_sent = vec![0i64; vehicles.len()];
    let mut lag = histogram();
    // (due ns since start, local vehicle index, message index)
    let mut heap: BinaryHeap<Reverse<(i64, usize, usize)>> = BinaryHeap::new();
    for (i, k) in vehicles.iter().enumerate() {
        let due = start_offset_ns(*k, &params);
        if due < duration_ns {
            heap.push(Reverse((due, i, 0)));
        }
    }
    while let Some(Reverse((due, i, j))) = heap.pop() {
        let scheduled = start + Duration::from_nanos(due.max(0) as u64);
        tokio::time::sleep_until(scheduled.into()).await;
        let (_, payload) = rec.message(j);
        let imu_t = match &payload {
            Payload::Imu(b) => b.samples.last().map(|s| s.t_ns),
            _ => None,
        };
        let sent = sender.send(&ids[i], payload).await;
        let _ = lag.record(
            (Instant::now()
                .saturating_duration_since(scheduled)
                .as_nanos() as u64)
                .max(1),
        );
        match sent {
            Ok(()) => {
                live.sent.fetch_add(1, Ordering::Relaxed);
                if let Some(t) = imu_t {
                    last_sent[i] = t;
                }
            }
            Err(_) => {
                live.send_errors.fetch_add(1, Ordering::Relaxed);
            }
        }
        let off = start_offset_ns(vehicles[i], &params);
        let next_due = off + rec.due(j + 1);
        if next_due < duration_ns {
            heap.push(Reverse((next_due, i, j + 1)));
        }
    }
    let elapsed = start.elapsed().as_nanos() as u64;
    (lag, vehicles.into_iter().zip(last_sent).collect(), elapsed)
}

fn service_counters(
    latest: &BTreeMap<String, pb::VehicleHealth>,
    baseline: &BTreeMap<String, pb::InputCounters>,
) -> ServiceCounters {
    let mut c = ServiceCounters::default();
    for h in latest.values() {
        c.vehicles_reporting += 1;
        if let Some(k) = &h.counters {
            let b = baseline.get(&h.vehicle_id).cloned().unwrap_or_default();
            c.accepted += k.accepted.saturating_sub(b.accepted);
            c.rejected += k.rejected.saturating_sub(b.rejected);
            c.late += k.late.saturating_sub(b.late);
            c.shed += k.shed.saturating_sub(b.shed);
            c.dropped += k.dropped.saturating_sub(b.dropped);
        }
    }
    c
}
