//! Keeping the service's vehicles configured over Zenoh, where puts have no ack.
//!
//! Over gRPC the acks of a vehicle's data say `needs_config` when the service runs it without the
//! configuration this client gave (a restarted service, an idle eviction), and the ingest driver
//! sends it again. Over Zenoh the same fact comes in the vehicle's health reports
//! (`VehicleHealth.configured`), which the service also publishes on the vehicle's `unconfigured`
//! key while it runs without a configuration, and only then. The keeper of an ingest stream
//! subscribes to that key of every vehicle the stream feeds (from its first message on): the
//! service publishes nothing there for configured vehicles, where a subscription to `health`
//! made it publish every vehicle's health every period. It re-puts the remembered configuration
//! when a report says the vehicle runs without one: at most once per [`MIN_RESEND_INTERVAL`] per
//! vehicle (a report comes every health period until the configuration arrives), counted in
//! [`IngestStats::configs_resent`]. The keeper's task ends when the stream and every sender are
//! dropped.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use prost::Message;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::ingest::{Configs, IngestStats};
use crate::keys::{self, Leaf};
use crate::pb;

/// Shortest interval between two re-puts of one vehicle's configuration.
pub const MIN_RESEND_INTERVAL: Duration = Duration::from_secs(1);

/// Health reports saying "not configured" waiting for the task; beyond, they are dropped (the
/// next report says it again).
const PENDING_REPORTS: usize = 1024;

/// The keeper of one Zenoh ingest stream (see the module docs).
#[derive(Debug)]
pub(crate) struct ConfigKeeper {
    configs: Configs,
    watch: mpsc::UnboundedSender<String>,
    task: JoinHandle<()>,
}

impl Drop for ConfigKeeper {
    fn drop(&mut self) {
        self.task.abort();
    }
}

impl ConfigKeeper {
    /// Starts the keeper's task on `session`, re-putting from `configs` and counting in `stats`.
    pub(crate) fn spawn(
        session: zenoh::Session,
        configs: Configs,
        stats: Arc<IngestStats>,
    ) -> Self {
        let (watch, rx) = mpsc::unbounded_channel();
        let task = tokio::spawn(run(session, configs.clone(), stats, rx));
        Self {
            configs,
            watch,
            task,
        }
    }

    /// Remembers the configuration a client put for vehicle `id`.
    pub(crate) fn remember(&self, id: &str, config: &pb::VehicleConfig) {
        self.configs.remember(id, config);
    }

    /// Watches vehicle `id`'s `unconfigured` reports from now on. Called on a vehicle's first message of
    /// the stream (`IngestSender::await_subscriber`), so the channel sees each vehicle about once;
    /// the task ignores a vehicle it watches already.
    pub(crate) fn watch(&self, id: &str) {
        let _ = self.watch.send(id.to_string());
    }
}

async fn run(
    session: zenoh::Session,
    configs: Configs,
    stats: Arc<IngestStats>,
    mut watch: mpsc::UnboundedReceiver<String>,
) {
    let (unconfigured_tx, mut unconfigured) = mpsc::channel::<String>(PENDING_REPORTS);
    // Dropping a subscriber undeclares it: they live as long as the task, one per vehicle.
    let mut subscribers = BTreeMap::new();
    let mut last_put: BTreeMap<String, Instant> = BTreeMap::new();
    loop {
        tokio::select! {
            id = watch.recv() => {
                let Some(id) = id else { return };
                if subscribers.contains_key(&id) {
                    continue;
                }
                let key = keys::vehicle_key(&id, Leaf::Unconfigured);
                let tx = unconfigured_tx.clone();
                let sub = session
                    .declare_subscriber(&key)
                    .callback(move |sample| {
                        let bytes = sample.payload().to_bytes();
                        if let Ok(h) = pb::VehicleHealth::decode(bytes.as_ref())
                            && !h.configured
                        {
                            let _ = tx.try_send(h.vehicle_id);
                        }
                    })
                    .await;
                match sub {
                    Ok(s) => {
                        subscribers.insert(id, s);
                    }
                    Err(e) => stats.error(format!("zenoh subscribe {key}: {e}")),
                }
            }
            Some(id) = unconfigured.recv() => {
                let now = Instant::now();
                if last_put
                    .get(&id)
                    .is_some_and(|t| now.duration_since(*t) < MIN_RESEND_INTERVAL)
                {
                    continue;
                }
                let Some(config) = configs.get(&id) else {
                    continue;
                };
                last_put.insert(id.clone(), now);
                let key = keys::vehicle_key(&id, Leaf::Config);
                let put = session
                    .put(&key, config.encode_to_vec())
                    .encoding(crate::zenoh_backend::encoding(Leaf::Config.message_name()))
                    .congestion_control(zenoh::qos::CongestionControl::Block)
                    .await;
                match put {
                    Ok(()) => {
                        stats.configs_resent.fetch_add(1, Ordering::Relaxed);
                    }
                    Err(e) => stats.error(format!("zenoh put {key} (re-sent configuration): {e}")),
                }
            }
        }
    }
}
