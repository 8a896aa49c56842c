//! What Zenoh dropped on its own: messages to a peer whose link stayed congested longer than
//! `zenoh.stalled_link_ms` (congestion control `Drop`, set on every output) never reach the
//! service's code, so they are read from Zenoh's transport statistics and counted in
//! `uavnav_zenoh_dropped_total`.
//!
//! Zenoh 1.10 keeps these counts in its runtime (the `stats` feature) and exposes the runtime
//! only through its `internal` API, so the session is opened on a runtime built here. The count
//! is per peer inside Zenoh (not per link) and includes closed transports, so the total only
//! grows; it is polled once a second and the metric advances by the difference.

use std::time::Duration;

use prometheus_client::metrics::counter::Counter;
use tokio::task::JoinHandle;
use zenoh::internal::runtime::Runtime;

/// How often Zenoh's totals are read.
pub const POLL: Duration = Duration::from_secs(1);

/// Messages Zenoh dropped for congestion so far, on every transport (open or closed).
pub fn congestion_dropped(runtime: &Runtime) -> u64 {
    // `merge_stats` fills `stats` of a JSON skeleton with the totals of all transports.
    let mut totals = serde_json::json!({ "sessions": [] });
    runtime.stats().merge_stats(&mut totals);
    totals["stats"]["tx_n_dropped"].as_u64().unwrap_or(0)
}

/// Mirrors Zenoh's congestion drops into `counter` every [`POLL`] until aborted.
pub fn spawn_poll(runtime: Runtime, counter: Counter) -> JoinHandle<()> {
    tokio::spawn(async move {
        let mut seen = 0u64;
        let mut every = tokio::time::interval(POLL);
        every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            every.tick().await;
            let now = congestion_dropped(&runtime);
            if now > seen {
                counter.inc_by(now - seen);
                seen = now;
            }
        }
    })
}
