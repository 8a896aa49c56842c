//! The Zenoh output task: poses and health reports from the hub, put on the vehicles' keys only
//! while some remote subscriber wants them.
//!
//! | part | what |
//! |---|---|
//! | [`publish_outputs`] | the task: one loop over the hub's rings |
//! | [`Subscribers`] | whether any remote subscriber matches a leaf of some vehicle (`*/pose`, …) |
//! | [`RepeatBudget`] | the fleet-wide allowance of quiet vehicles' repeated health reports |
//!
//! Why not a publisher per vehicle, so that a subscriber on one vehicle's `pose` would not make
//! every vehicle's poses go out: each declared publisher puts its key in the session's routing
//! tree as a child of `uavnav/v1/vehicle`, and Zenoh routes every put on a key nobody declared
//! (the health reports, and every input a client puts) by comparing it with every child there.
//! Tried and measured (1,000 vehicles, one vehicle's pose and health watched, `cargo bench -p
//! uavnavd --bench fleet -- --vehicles 1000 --duration-s 10 --zenoh-watch-one`): the poses put
//! fell from 1,841,000 to the 1,841 wanted and the process from 1.26 / 1.24 to 0.91 / 0.86
//! cores, but the health puts (1,000 a second) took about 0.05 core more, some 50 µs each
//! where 6 µs were measured before with nothing declared there. Incoming samples on undeclared
//! keys are routed by the same walk, so a fleet fed over Zenoh would likely pay that on every
//! input message (55,000 a second at 1,000 vehicles; not measured). So poses stay gated by the
//! fleet-wide wildcard, and `uavnav_zenoh_poses_published_total` counts what goes out.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use prost::Message;
use tokio::sync::{broadcast, oneshot};
use tracing::{debug, warn};
use uavnav_proto::keys::{self, Leaf};
use uavnav_proto::v1 as pb;
use zenoh::Session;
use zenoh::bytes::Encoding;
use zenoh::pubsub::Publisher;

use crate::ingest::Ingestor;
use crate::metrics::Metrics;
use crate::output::hub::{HealthReport, PoseBatch};
use crate::transport::zenoh::encoding;
use crate::vehicle::mono_now;

/// What [`publish_outputs`] reads: the hub's rings.
#[derive(Debug)]
pub struct OutputFeeds {
    /// Every pose batch.
    pub poses: broadcast::Receiver<Arc<PoseBatch>>,
    /// Every health report.
    pub health: broadcast::Receiver<Arc<HealthReport>>,
}

/// Publishes every pose and health report on the vehicle's key (and the reports of a
/// vehicle without its configuration on its `unconfigured` key) until `done` fires, then
/// publishes what is left in the rings (the final health reports) and ends.
pub async fn publish_outputs(
    session: Session,
    feeds: OutputFeeds,
    repeat_health_per_s: f64,
    ingestor: Ingestor,
    mut done: oneshot::Receiver<()>,
) {
    let OutputFeeds {
        mut poses,
        mut health,
    } = feeds;
    let mut repeats = RepeatBudget::new(repeat_health_per_s);
    let metrics = ingestor.registry().ctx().metrics.clone();
    let watched = Subscribers::declare(&session, Leaf::Pose).await;
    let health_watched = Subscribers::declare(&session, Leaf::Health).await;
    let unconfigured_watched = Subscribers::declare(&session, Leaf::Unconfigured).await;
    let out = Outputs {
        session,
        pose_enc: encoding(Leaf::Pose.message_name()),
        health_enc: encoding(Leaf::Health.message_name()),
        metrics: metrics.clone(),
    };
    loop {
        tokio::select! {
            biased;
            r = health.recv() => match r {
                Ok(report) => {
                    let h = &report.health;
                    let on_health = health_watched.any();
                    let on_unconfigured = !h.configured && unconfigured_watched.any();
                    if (on_health || on_unconfigured)
                        && report.repeat
                        && !repeats.take(mono_now())
                    {
                        metrics.zenoh_health_repeats_skipped.inc();
                        continue;
                    }
                    if on_health {
                        out.health(h, Leaf::Health).await;
                    }
                    if on_unconfigured {
                        out.health(h, Leaf::Unconfigured).await;
                    }
                }
                Err(broadcast::error::RecvError::Lagged(n)) => {
                    metrics.zenoh_output_lagged.inc_by(n);
                }
                Err(broadcast::error::RecvError::Closed) => break,
            },
            r = poses.recv() => match r {
                Ok(b) if watched.any() => out.poses(&b).await,
                Ok(_) => {}
                Err(broadcast::error::RecvError::Lagged(n)) => {
                    metrics.zenoh_output_lagged.inc_by(n);
                }
                Err(broadcast::error::RecvError::Closed) => break,
            },
            _ = &mut done => break,
        }
    }
    while let Ok(b) = poses.try_recv() {
        if watched.any() {
            out.poses(&b).await;
        }
    }
    while let Ok(r) = health.try_recv() {
        out.health(&r.health, Leaf::Health).await;
    }
}

/// A flag that follows whether a remote subscriber matches `publisher`'s key: set from its
/// matching status now and kept current by a matching listener that lives as long as the
/// publisher. Without either, `true` (publishing for nobody is only slower).
async fn matching_flag(publisher: &Publisher<'static>, key: &str) -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(true));
    let f = Arc::clone(&flag);
    let listener = publisher
        .matching_listener()
        .callback(move |s| f.store(s.matching(), Ordering::Relaxed))
        .background()
        .await;
    match (listener, publisher.matching_status().await) {
        (Ok(()), Ok(status)) => flag.store(status.matching(), Ordering::Relaxed),
        (l, s) => warn!(
            key,
            listener = ?l.err(),
            status = ?s.err(),
            "matching status unavailable; publishing every output"
        ),
    }
    flag
}

/// The fleet-wide allowance of repeated health reports on Zenoh: a token bucket refilled at
/// `per_s`, holding one second's worth (at least one report, so that a rate below 1/s still
/// lets one through now and then). Repeats come from quiet vehicles, once every
/// ten health periods each, so without it one watcher would make an idle fleet's reminders cost
/// in proportion to the fleet (10,000 idle vehicles: 1,000 puts a second).
#[derive(Debug)]
struct RepeatBudget {
    per_s: f64,
    tokens: f64,
    at: Option<std::time::Instant>,
}

impl RepeatBudget {
    fn new(per_s: f64) -> Self {
        Self {
            per_s,
            tokens: Self::capacity(per_s),
            at: None,
        }
    }

    /// What the bucket holds when full: a second's worth, at least one report (none for 0).
    fn capacity(per_s: f64) -> f64 {
        if per_s > 0.0 { per_s.max(1.0) } else { 0.0 }
    }

    /// Takes one repeat's allowance at `now`, if there is one.
    fn take(&mut self, now: std::time::Instant) -> bool {
        if let Some(at) = self.at {
            let dt_s = now.saturating_duration_since(at).as_secs_f64();
            self.tokens = (self.tokens + dt_s * self.per_s).min(Self::capacity(self.per_s));
        }
        self.at = Some(now);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

/// Whether any Zenoh subscriber anywhere matches some vehicle's output key (`pose`, `health` or
/// `unconfigured`).
/// Poses come at IMU rate for the whole fleet: when nobody subscribes, encoding and routing each one
/// would cost more than estimating it. Health comes at 1 Hz per vehicle, which for an idle fleet of
/// 10,000 vehicles was most of a core spent routing reports nobody asked for: it is gated the same
/// way, so an idle vehicle costs nothing on Zenoh.
struct Subscribers {
    any: Arc<AtomicBool>,
    /// Kept for its matching listener (declared on the wildcard key, never put on).
    _publisher: Option<Publisher<'static>>,
}

impl Subscribers {
    async fn declare(session: &Session, leaf: Leaf) -> Self {
        let key = keys::vehicle_key("*", leaf);
        // Remote subscribers only: the service's own input subscriber (`uavnav/v1/vehicle/*/*`)
        // matches this key too, and it never wants poses.
        let publisher = match session
            .declare_publisher(key.clone())
            .allowed_destination(zenoh::sample::Locality::Remote)
            .await
        {
            Ok(p) => p,
            Err(e) => {
                // Without the listener, publish every pose (correct, only slower).
                warn!(key, error = %e, "no matching listener; publishing every output");
                return Self {
                    any: Arc::new(AtomicBool::new(true)),
                    _publisher: None,
                };
            }
        };
        let any = matching_flag(&publisher, &key).await;
        Self {
            any,
            _publisher: Some(publisher),
        }
    }

    fn any(&self) -> bool {
        self.any.load(Ordering::Relaxed)
    }
}

struct Outputs {
    session: Session,
    pose_enc: Encoding,
    health_enc: Encoding,
    metrics: Metrics,
}

impl Outputs {
    /// Every pose of the batch.
    async fn poses(&self, b: &PoseBatch) {
        let key = keys::vehicle_key(&b.vehicle_id, Leaf::Pose);
        for i in 0..b.poses.len() {
            if let Some(body) = b.encode_wire(i) {
                self.metrics.zenoh_poses_published.inc();
                self.put(key.clone(), body, &self.pose_enc).await;
            }
        }
    }

    /// A health report on `leaf` (`Health`, or `Unconfigured` for a vehicle without its
    /// configuration).
    async fn health(&self, h: &pb::VehicleHealth, leaf: Leaf) {
        self.put(
            keys::vehicle_key(&h.vehicle_id, leaf),
            h.encode_to_vec(),
            &self.health_enc,
        )
        .await;
    }

    /// Congestion control `Drop`: a link whose queue is full (a subscriber that stopped reading,
    /// or slower than the fleet's outputs) loses what it cannot take, and only that link: Zenoh
    /// marks it congested and drops for it at once, while every other link gets every sample.
    /// With `Block` this one task waited on the slowest link, up to Zenoh's 5 s before it closes
    /// a blocked link, and every subscriber went without poses meanwhile. Zenoh counts no such
    /// drops where the service can read them; what this task itself falls behind on is counted
    /// (`zenoh_output_lagged`).
    async fn put(&self, key: String, body: Vec<u8>, enc: &Encoding) {
        let put = self
            .session
            .put(&key, body)
            .encoding(enc.clone())
            // Not to this session's own input subscriber (`*/*` matches `*/pose`): only others.
            .allowed_destination(zenoh::sample::Locality::Remote)
            .congestion_control(zenoh::qos::CongestionControl::Drop);
        if let Err(e) = put.await {
            debug!(key, error = %e, "zenoh put failed");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::RepeatBudget;
    use std::time::{Duration, Instant};

    #[test]
    fn the_repeat_budget_allows_its_rate_and_no_more_however_many_ask() {
        let t0 = Instant::now();
        let mut b = RepeatBudget::new(100.0);
        // 10,000 quiet vehicles' repeats over 10 s (1,000 a second): 100 a second get through,
        // plus the first second's allowance.
        let allowed = (0..10_000)
            .filter(|&i| b.take(t0 + Duration::from_micros(i * 1000)))
            .count();
        assert!((1000..=1100).contains(&allowed), "{allowed}");
        // A budget of 0 lets nothing through.
        let mut none = RepeatBudget::new(0.0);
        assert!((0..100).all(|i| !none.take(t0 + Duration::from_secs(i))));
        // Below one a second: one every 1/rate seconds (10 s at 0.1/s), asked every second.
        let mut slow = RepeatBudget::new(0.1);
        let allowed = (0..100)
            .filter(|&i| slow.take(t0 + Duration::from_secs(i)))
            .count();
        assert!((10..=11).contains(&allowed), "{allowed}");
    }
}
