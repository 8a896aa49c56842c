//! The embedded Zenoh session: the same actors as gRPC, fed and watched through key expressions.
//!
//! The key expressions are those of [`uavnav_proto::keys`] (the table is there): the service
//! subscribes to every vehicle's input leaves, publishes `pose`, `health` and `unconfigured` (the
//! health reports of a vehicle without its configuration, for senders' keepers), answers the
//! `pose/latest` and `vehicles` queryables and declares the liveliness tokens.
//!
//! Payloads are the protobuf encoding of the message, with Zenoh encoding `application/protobuf`
//! and the message's full name as schema. Bad input is never answered on Zenoh (there is no reply
//! path for a put): it is counted in the vehicle's health and in `uavnav_inputs_total`.

use std::collections::HashMap;
use std::hash::{Hash, Hasher};
use std::sync::Arc;

use anyhow::{Context, anyhow};
use prost::Message;
use tokio::sync::{broadcast, mpsc, oneshot};
use tokio::task::JoinHandle;
use tracing::{debug, warn};
use uavnav_proto::keys::{self, Leaf};
use uavnav_proto::{names, v1 as pb};
use zenoh::Session;
use zenoh::bytes::Encoding;
use zenoh::internal::runtime::{Runtime, RuntimeBuilder};
use zenoh::key_expr::KeyExpr;
use zenoh::liveliness::LivelinessToken;

use crate::config::ZenohConfig;
use crate::ingest::{Ingestor, Payload};
use crate::metrics::{Cause, Kind, Outcome, Transport};
use crate::output::hub::Hub;
use crate::security::{Access, SecurityConfig};
use crate::service::Service;
use crate::vehicle::VehicleStats;

/// The metric kind of an input leaf (`None` for the outputs, which the input subscription also
/// matches).
fn input_kind(leaf: Leaf) -> Option<Kind> {
    Some(match leaf {
        Leaf::Imu => Kind::Imu,
        Leaf::Gnss => Kind::Gnss,
        Leaf::Mag => Kind::Mag,
        Leaf::Baro => Kind::Baro,
        Leaf::Camera => Kind::Camera,
        Leaf::Config => Kind::Config,
        Leaf::Pose | Leaf::Health | Leaf::Unconfigured => return None,
    })
}

/// Decoder shards: inputs are spread over this many tasks by vehicle id (per-vehicle order kept).
const SHARDS: usize = 4;

/// The Zenoh encoding of a uavnav.v1 message ([`keys::encoding_for`], the clients' too).
pub fn encoding(full_name: &str) -> Encoding {
    Encoding::from(keys::encoding_for(full_name))
}

/// Builds the session configuration from ours (the JSON5 file first, then our keys on top,
/// `max_sessions` included: the memory budget and the descriptor check count on it).
pub fn session_config(cfg: &ZenohConfig, sec: &SecurityConfig) -> anyhow::Result<zenoh::Config> {
    let mut z = match &cfg.config_file {
        Some(path) => zenoh::Config::from_file(path)
            .map_err(|e| anyhow!("zenoh config {}: {e}", path.display()))?,
        None => zenoh::Config::default(),
    };
    let json = |v: &[String]| serde_json_list(v);
    let set = |z: &mut zenoh::Config, key: &str, value: String| {
        z.insert_json5(key, &value)
            .map_err(|e| anyhow!("zenoh config {key}={value}: {e}"))
    };
    set(&mut z, "mode", format!("\"{}\"", cfg.mode.as_str()))?;
    set(&mut z, "listen/endpoints", json(&cfg.listen))?;
    set(&mut z, "connect/endpoints", json(&cfg.connect))?;
    set(
        &mut z,
        "scouting/multicast/enabled",
        cfg.multicast_scouting.to_string(),
    )?;
    set(
        &mut z,
        "transport/link/tx/queue/congestion_control/drop/wait_before_drop",
        format!("{}", (cfg.stalled_link_ms * 1e3).round() as i64),
    )?;
    set(
        &mut z,
        "transport/unicast/max_sessions",
        cfg.max_sessions.to_string(),
    )?;
    crate::security::zenoh::apply(&mut z, sec)?;
    Ok(z)
}

fn serde_json_list(v: &[String]) -> String {
    let items: Vec<String> = v.iter().map(|s| keys::json_string(s)).collect();
    format!("[{}]", items.join(","))
}

/// The running Zenoh side of the service.
#[derive(Debug)]
pub struct ZenohIo {
    session: Session,
    /// The session's runtime: closed after the session (a session made on a given runtime
    /// does not close it).
    runtime: Runtime,
    /// Mirrors the runtime's congestion drops into `/metrics`.
    stats: JoinHandle<()>,
    tasks: Vec<JoinHandle<()>>,
    output: Option<(JoinHandle<()>, oneshot::Sender<()>)>,
    /// The locators the session listens on.
    pub locators: Vec<String>,
}

impl ZenohIo {
    /// Opens the session and starts the input, output and query tasks.
    pub async fn start(
        cfg: &ZenohConfig,
        sec: &SecurityConfig,
        service: Service,
        hub: Hub,
    ) -> anyhow::Result<Self> {
        let ingestor = service.ingestor().clone();
        // The session runs on a runtime built here, so that its transport statistics (what
        // Zenoh drops on congested links) can be read (`zenoh_stats`).
        let mut runtime = RuntimeBuilder::new(session_config(cfg, sec)?)
            .build()
            .await
            .map_err(|e| anyhow!("opening the zenoh session: {e}"))?;
        let session = zenoh::session::init(runtime.clone().into())
            .await
            .map_err(|e| anyhow!("opening the zenoh session: {e}"))?;
        runtime
            .start()
            .await
            .map_err(|e| anyhow!("starting the zenoh session: {e}"))?;
        // Zenoh 1.x does not expose the bound locators on the session: report the configured ones.
        let locators = cfg.listen.clone();
        let instance = if cfg.instance.is_empty() {
            default_instance()
        } else {
            cfg.instance.clone()
        };
        let service_token = session
            .liveliness()
            .declare_token(keys::service_key(&instance))
            .await
            .map_err(|e| anyhow!("declaring the service liveliness token: {e}"))
            .context("zenoh.instance must be a valid key chunk")?;
        let stats = crate::transport::zenoh_stats::spawn_poll(
            runtime.clone(),
            service.metrics().zenoh_dropped.clone(),
        );
        let mut tasks = Vec::new();
        tasks.push(spawn_inputs(&session, service).await?);
        tasks.push(spawn_queries(&session, ingestor.clone()).await?);
        tasks.push(spawn_liveliness(
            &session,
            hub.lifecycle.subscribe(),
            service_token,
            Arc::clone(ingestor.registry()),
        ));
        let (done_tx, done_rx) = oneshot::channel();
        let out = crate::transport::zenoh_out::publish_outputs(
            session.clone(),
            crate::transport::zenoh_out::OutputFeeds {
                poses: hub.poses.subscribe(),
                health: hub.health.subscribe(),
            },
            cfg.repeat_health_per_s,
            ingestor,
            done_rx,
        );
        let output = Some((tokio::spawn(out), done_tx));
        Ok(Self {
            session,
            runtime,
            stats,
            tasks,
            output,
            locators,
        })
    }

    /// Stops taking input (first step of shutdown).
    pub fn stop_inputs(&mut self) {
        for t in self.tasks.drain(..) {
            t.abort();
        }
    }

    /// Publishes what is left and closes the session (after the actors have drained).
    pub async fn close(mut self) {
        if let Some((task, done)) = self.output.take() {
            let _ = done.send(());
            let _ = tokio::time::timeout(std::time::Duration::from_secs(5), task).await;
        }
        if let Err(e) = self.session.close().await {
            warn!(error = %e, "closing the zenoh session");
        }
        self.stats.abort();
        if let Err(e) = self.runtime.close().await {
            warn!(error = %e, "closing the zenoh runtime");
        }
    }
}

fn default_instance() -> String {
    let host = std::fs::read_to_string("/etc/hostname")
        .map(|s| s.trim().to_string())
        .unwrap_or_default();
    let host: String = host
        .chars()
        .filter(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
        .collect();
    format!(
        "{}-{}",
        if host.is_empty() { "uavnavd" } else { &host },
        std::process::id()
    )
}

/// Input samples buffered between Zenoh's receive thread and the decoding shards.
const ZENOH_INPUT_BUFFER: usize = 16_384;

async fn spawn_inputs(session: &Session, service: Service) -> anyhow::Result<JoinHandle<()>> {
    let ingestor = service.ingestor().clone();
    let sub = session
        .declare_subscriber(keys::EVERY_VEHICLE_LEAF)
        // Zenoh's receive thread blocks when this is full, and a link blocked for longer than
        // Zenoh's `wait_before_close` is closed (what was queued on it is lost): keep a deep
        // buffer between the network and the actors' back-pressure.
        .with(zenoh::handlers::FifoChannel::new(ZENOH_INPUT_BUFFER))
        .await
        .map_err(|e| anyhow!("subscribing to {}: {e}", keys::EVERY_VEHICLE_LEAF))?;
    let max_bytes = ingestor.max_message_bytes();
    let mut shards = Vec::with_capacity(SHARDS);
    let mut shard_tasks = Vec::with_capacity(SHARDS);
    for _ in 0..SHARDS {
        let (tx, rx) = mpsc::channel::<zenoh::sample::Sample>(1024);
        shards.push(tx);
        shard_tasks.push(tokio::spawn(decode_loop(rx, service.clone(), max_bytes)));
    }
    Ok(tokio::spawn(async move {
        let _guard = AbortOnDrop(shard_tasks);
        while let Ok(sample) = sub.recv_async().await {
            let shard =
                keys::split_vehicle(sample.key_expr().as_str()).map_or(0, |(id, _)| shard_of(id));
            if shards[shard].send(sample).await.is_err() {
                break;
            }
        }
    }))
}

struct AbortOnDrop(Vec<JoinHandle<()>>);

impl Drop for AbortOnDrop {
    fn drop(&mut self) {
        for t in &self.0 {
            t.abort();
        }
    }
}

fn shard_of(id: &str) -> usize {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    id.hash(&mut h);
    (h.finish() % SHARDS as u64) as usize
}

async fn decode_loop(
    mut rx: mpsc::Receiver<zenoh::sample::Sample>,
    service: Service,
    max_bytes: usize,
) {
    let ingestor = service.ingestor();
    // Zenoh samples carry no caller identity: the grants are enforced per link by the session's
    // access control (`security::zenoh`), so what arrives here was allowed there.
    let access = Access::Open;
    while let Some(sample) = rx.recv().await {
        let Some((id, leaf)) = keys::split(sample.key_expr().as_str()) else {
            // A leaf that names nothing (`uavnav/v1/vehicle/x/foo`): refused, counted.
            let metrics = &ingestor.registry().ctx().metrics;
            metrics.input(Transport::Zenoh, Kind::Malformed, Outcome::Invalid, 1);
            metrics.refuse(Transport::Zenoh, Kind::Malformed, Cause::UnknownKey);
            debug!(key = ?sample.key_expr().as_str(), "zenoh put on an unknown key");
            continue;
        };
        // Our own outputs match `*/*` too (pose, health, unconfigured): not inputs.
        let Some(kind) = input_kind(leaf) else {
            continue;
        };
        ingestor.registry().ctx().metrics.zenoh_samples.inc();
        let bytes = sample.payload().to_bytes();
        if bytes.len() > max_bytes {
            reject(
                ingestor,
                id,
                kind,
                Outcome::Exhausted,
                &format!("{} bytes, limit {max_bytes}", bytes.len()),
            );
            continue;
        }
        // A batch's samples are counted on the wire, before anything is allocated: an empty
        // sample is 2 bytes encoded, 56 decoded.
        if kind == Kind::Imu {
            let limit = crate::ingest::validate::MAX_IMU_BATCH;
            match uavnav_proto::wire::count_field(&bytes, 1) {
                Ok(n) if n > limit => {
                    reject(
                        ingestor,
                        id,
                        kind,
                        Outcome::Exhausted,
                        &format!("imu.samples: {n} samples in one batch, limit {limit}"),
                    );
                    continue;
                }
                Ok(_) => {}
                Err(e) => {
                    reject(
                        ingestor,
                        id,
                        kind,
                        Outcome::Invalid,
                        &format!("malformed protobuf: {e}"),
                    );
                    continue;
                }
            }
        }
        // Outputs were skipped above: every leaf here is an input.
        let Some(decoded) = leaf.decode_input(&bytes) else {
            continue;
        };
        match decoded {
            Ok(msg) => {
                let v = service
                    .feed(&access, Transport::Zenoh, id, Payload::from(&msg))
                    .await;
                if v.status != pb::IngestStatus::Accepted {
                    debug!(vehicle = ?id, status = ?v.status, reason = %v.reason, "zenoh input refused");
                }
            }
            Err(e) => reject(
                ingestor,
                id,
                kind,
                Outcome::Invalid,
                &format!("malformed protobuf: {e}"),
            ),
        }
    }
}

/// Counts a refusal that never reached [`Ingestor::submit`] (undecodable or oversize).
fn reject(ingestor: &Ingestor, id: &str, kind: Kind, outcome: Outcome, reason: &str) {
    let metrics = &ingestor.registry().ctx().metrics;
    metrics.input(Transport::Zenoh, kind, outcome, 1);
    let cause = match outcome {
        // The only limits checked before decoding are sizes (message bytes, batch samples).
        Outcome::Exhausted => crate::metrics::Cause::TooLarge,
        _ => crate::metrics::Cause::Malformed,
    };
    metrics.refuse(Transport::Zenoh, kind, cause);
    if let Some(h) = ingestor.registry().get(id) {
        VehicleStats::add(&h.shared.stats.rejected, 1);
    }
    debug!(vehicle = ?id, ?kind, reason, "zenoh input refused");
}

async fn spawn_queries(session: &Session, ingestor: Ingestor) -> anyhow::Result<JoinHandle<()>> {
    let poses = session
        .declare_queryable(keys::EVERY_POSE_LATEST)
        .await
        .map_err(|e| anyhow!("queryable {}: {e}", keys::EVERY_POSE_LATEST))?;
    let list = session
        .declare_queryable(keys::VEHICLES)
        .await
        .map_err(|e| anyhow!("queryable {}: {e}", keys::VEHICLES))?;
    Ok(tokio::spawn(async move {
        loop {
            tokio::select! {
                q = poses.recv_async() => match q {
                    Ok(q) => answer_pose(&q, &ingestor).await,
                    Err(_) => break,
                },
                q = list.recv_async() => match q {
                    Ok(q) => {
                        let vehicles = ingestor.registry().list("").iter().map(crate::transport::grpc::summary_of).collect();
                        let body = pb::ListVehiclesResponse { vehicles }.encode_to_vec();
                        let _ = q.reply(keys::VEHICLES, body).encoding(encoding(names::LIST_VEHICLES_RESPONSE)).await;
                    }
                    Err(_) => break,
                },
            }
        }
    }))
}

/// Replies with the latest pose of every vehicle the query's key expression selects.
async fn answer_pose(q: &zenoh::query::Query, ingestor: &Ingestor) {
    let wanted = q.key_expr().clone();
    for h in ingestor.registry().list("") {
        let key = keys::pose_latest_key(&h.shared.id);
        let Ok(ke) = KeyExpr::try_from(key.as_str()) else {
            continue;
        };
        if !wanted.intersects(&ke) {
            continue;
        }
        if let Some(p) = h.shared.pose() {
            let _ = q
                .reply(ke, p.encode_to_vec())
                .encoding(encoding(Leaf::Pose.message_name()))
                .await;
        }
    }
}

fn spawn_liveliness(
    session: &Session,
    mut rx: broadcast::Receiver<(Arc<str>, bool)>,
    service: LivelinessToken,
    registry: Arc<crate::vehicle::registry::Registry>,
) -> JoinHandle<()> {
    let session = session.clone();
    tokio::spawn(async move {
        let _service = service;
        let mut tokens: HashMap<Arc<str>, LivelinessToken> = HashMap::new();
        let declare = |id: Arc<str>| {
            let session = session.clone();
            async move {
                match session
                    .liveliness()
                    .declare_token(keys::alive_key(&id))
                    .await
                {
                    Ok(t) => Some((id, t)),
                    Err(e) => {
                        warn!(vehicle = ?id, error = %e, "declaring the vehicle liveliness token");
                        None
                    }
                }
            }
        };
        loop {
            match rx.recv().await {
                Ok((id, true)) => {
                    if let Some((id, t)) = declare(id).await {
                        tokens.insert(id, t);
                    }
                }
                Ok((id, false)) => {
                    tokens.remove(&id);
                }
                Err(broadcast::error::RecvError::Lagged(_)) => {
                    // Events were lost (a flood of new ids): without them, the tokens of
                    // vehicles evicted meanwhile would stay declared for ever. Reconcile with
                    // the live vehicles instead.
                    let live: std::collections::HashSet<Arc<str>> = registry
                        .list("")
                        .into_iter()
                        .filter(|h| {
                            h.shared
                                .announced
                                .load(std::sync::atomic::Ordering::Relaxed)
                        })
                        .map(|h| Arc::clone(&h.shared.id))
                        .collect();
                    tokens.retain(|id, _| live.contains(id));
                    for id in live {
                        if !tokens.contains_key(&id)
                            && let Some((id, t)) = declare(id).await
                        {
                            tokens.insert(id, t);
                        }
                    }
                }
                Err(broadcast::error::RecvError::Closed) => break,
            }
            // A map never gives back its capacity on its own: after a flood has gone, do.
            if tokens.capacity() > 64 && tokens.len() * 4 < tokens.capacity() {
                tokens.shrink_to_fit();
            }
        }
    })
}
