//! Sensor streams into the service: [`Ingest`] (one logical stream) and its cloneable
//! [`IngestSender`]s, with counters of what was sent, acknowledged, refused and lost.
//!
//! Over gRPC an `Ingest` is one `Ingest` bidirectional stream; a task reads the acks (so flow
//! control never stalls the sender) and reopens the stream with backoff when it breaks. The
//! stream asks for ack runs (`uavnav_proto::ACK_RUNS_HEADER`): one ack answers a run of plain
//! acceptances, and its `covers` is what the counters add. Envelopes
//! in flight at a break are lost and counted (`sent - acked`). A reopened stream first re-sends
//! every vehicle configuration this client gave (in the stream or by `Client::configure`), so a
//! service that restarted has them before the data (the service ignores a configuration a
//! vehicle already runs with, so a stream that broke without a restart loses nothing by it);
//! counted in [`IngestStats::configs_resent`]. An ack saying `needs_config` (the service forgot
//! a vehicle this client configured: an idle eviction, a restart the stream did not see) makes
//! the driver re-send that vehicle's configuration in the same stream (while it is open), once
//! until it is acknowledged, also counted there. Over Zenoh each message is a `put` on the
//! vehicle's key (congestion control `Block`: never dropped locally); there are no acks, and the
//! stream's [`crate::zenoh_keeper`] re-puts a configuration when the vehicle's health reports say
//! the service runs it without one (also counted in `configs_resent`).
//!
//! Refusals are not retried: an ack `PERMISSION_DENIED` (a vehicle outside the caller's grants)
//! is counted with its reason ([`IngestStats::permission_denied`]); a stream refused as a whole
//! (`Unauthenticated`, `PermissionDenied`) is not reopened, and later sends return that refusal.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use prost::Message;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::error::{ClientError, check_vehicle_id};
use crate::keys::Leaf;
use crate::pb;
use crate::pb::sensor_envelope::Payload;
use uavnav_proto::ACK_RUNS_HEADER;

/// Counters of one ingest stream (shared by its senders).
#[derive(Debug, Default)]
pub struct IngestStats {
    /// Messages handed to the transport.
    pub sent: AtomicU64,
    /// Encoded bytes handed to the transport.
    pub bytes: AtomicU64,
    /// Acks received (gRPC).
    pub acked: AtomicU64,
    /// Acks with status ACCEPTED (gRPC; for Zenoh and discard: every message put).
    pub accepted: AtomicU64,
    /// Stream reopenings.
    pub reconnects: AtomicU64,
    /// Vehicle configurations re-sent: at the start of a reopened stream, and when an ack says
    /// the service lost one (`needs_config`).
    pub configs_resent: AtomicU64,
    /// Messages handed to the transport per input kind, indexed like [`Leaf::INPUTS`].
    sent_by_leaf: [AtomicU64; Leaf::INPUTS.len()],
    /// Acks with status OK (kept apart from `statuses`: the hot path takes no lock).
    ok: AtomicU64,
    statuses: Mutex<BTreeMap<String, u64>>,
    errors: Mutex<BTreeMap<String, u64>>,
    /// PERMISSION_DENIED acks by the service's reason.
    denied: Mutex<BTreeMap<String, u64>>,
    /// The status that refused the whole stream (it is not reopened), and a flag the hot path
    /// reads without a lock.
    refused: Mutex<Option<(tonic::Code, String)>>,
    is_refused: std::sync::atomic::AtomicBool,
}

impl IngestStats {
    fn status(&self, name: &str) {
        if let Ok(mut m) = self.statuses.lock() {
            *m.entry(name.to_string()).or_default() += 1;
        }
    }

    pub(crate) fn error(&self, msg: String) {
        if let Ok(mut m) = self.errors.lock() {
            *m.entry(msg).or_default() += 1;
        }
    }

    /// Counts of acks by status name (`OK` for accepted, else the `IngestStatus` name).
    pub fn statuses(&self) -> BTreeMap<String, u64> {
        let mut m = self.statuses.lock().map(|m| m.clone()).unwrap_or_default();
        let ok = self.ok.load(Ordering::Relaxed);
        if ok > 0 {
            m.insert("OK".to_string(), ok);
        }
        m
    }

    /// Messages handed to the transport for one input kind (IMU counts batches, not samples).
    pub fn sent_of(&self, leaf: Leaf) -> u64 {
        Leaf::INPUTS
            .iter()
            .position(|l| *l == leaf)
            .map_or(0, |i| self.sent_by_leaf[i].load(Ordering::Relaxed))
    }

    /// Messages sent per input kind, by key chunk (`imu`, `gnss`, `mag`, ...), kinds never sent
    /// left out.
    pub fn sent_by_kind(&self) -> BTreeMap<&'static str, u64> {
        Leaf::INPUTS
            .iter()
            .map(|l| (l.as_str(), self.sent_of(*l)))
            .filter(|(_, n)| *n > 0)
            .collect()
    }

    fn count_sent(&self, leaf: Leaf) {
        if let Some(i) = Leaf::INPUTS.iter().position(|l| *l == leaf) {
            self.sent_by_leaf[i].fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Acks `PERMISSION_DENIED` (vehicles outside the caller's grants) by the service's reason.
    pub fn permission_denied(&self) -> BTreeMap<String, u64> {
        self.denied.lock().map(|m| m.clone()).unwrap_or_default()
    }

    /// Acks that were not ACCEPTED (refused for any reason, PERMISSION_DENIED included).
    pub fn refused(&self) -> u64 {
        self.statuses
            .lock()
            .map(|m| m.values().sum())
            .unwrap_or_default()
    }

    /// The refusal that ended the stream (`Unauthenticated`, `PermissionDenied`), if any.
    pub fn stream_refusal(&self, op: &'static str) -> Option<ClientError> {
        let r = self.refused.lock().ok()?.clone()?;
        Some(ClientError::rpc(op, tonic::Status::new(r.0, r.1)))
    }

    /// Transport errors by message.
    pub fn errors(&self) -> BTreeMap<String, u64> {
        self.errors.lock().map(|m| m.clone()).unwrap_or_default()
    }

    fn ack(&self, ack: &pb::IngestAck) {
        // A run of acceptances answers `covers` envelopes (0 from a service that sends none).
        let n = u64::from(ack.covers.max(1));
        self.acked.fetch_add(n, Ordering::Relaxed);
        let status =
            pb::IngestStatus::try_from(ack.status).unwrap_or(pb::IngestStatus::Unspecified);
        if status == pb::IngestStatus::Accepted {
            self.accepted.fetch_add(n, Ordering::Relaxed);
            self.ok.fetch_add(n, Ordering::Relaxed);
        } else {
            self.status(status.as_str_name().trim_start_matches("INGEST_STATUS_"));
            if status == pb::IngestStatus::PermissionDenied
                && let Ok(mut m) = self.denied.lock()
            {
                let reason = if ack.reason.is_empty() {
                    format!("vehicle '{}' outside the caller's grants", ack.vehicle_id)
                } else {
                    ack.reason.clone()
                };
                *m.entry(reason).or_default() += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn counts_per_kind() {
        let ingest = Ingest::new(Sink::Discard, Arc::default(), None);
        let mag = Payload::Mag(pb::MagSample {
            t_ns: 1,
            field_x_t: 2e-5,
            ..Default::default()
        });
        let baro = Payload::Baro(pb::BaroSample {
            t_ns: 1,
            pressure_pa: 1e5,
            temperature_degc: None,
        });
        ingest.send("a", mag.clone()).await.unwrap();
        ingest.send("a", mag).await.unwrap();
        ingest.send("a", baro).await.unwrap();
        let st = ingest.stats();
        assert_eq!((st.sent_of(Leaf::Mag), st.sent_of(Leaf::Baro)), (2, 1));
        assert_eq!(st.sent_of(Leaf::Imu), 0);
        assert_eq!(
            st.sent_by_kind().into_iter().collect::<Vec<_>>(),
            [("baro", 1), ("mag", 2)]
        );
        assert_eq!(
            (leaf_of(&Payload::Mag(Default::default())).message_name()),
            "uavnav.v1.MagSample"
        );
    }
}

/// Where the messages go.
#[derive(Debug, Clone)]
pub(crate) enum Sink {
    Grpc(mpsc::Sender<pb::SensorEnvelope>),
    #[cfg(feature = "zenoh")]
    Zenoh(zenoh::Session, Arc<crate::zenoh_keeper::ConfigKeeper>),
    Discard,
}

/// A cloneable handle that sends sensor messages for any vehicle.
#[derive(Debug, Clone)]
pub struct IngestSender {
    sink: Sink,
    /// Vehicles whose Zenoh key already had (or was waited for) a matching subscriber.
    #[cfg(feature = "zenoh")]
    matched: Arc<Mutex<std::collections::BTreeSet<String>>>,
    seq: Arc<AtomicU64>,
    stats: Arc<IngestStats>,
}

/// The leaf of a payload.
pub fn leaf_of(p: &Payload) -> Leaf {
    match p {
        Payload::Imu(_) => Leaf::Imu,
        Payload::Gnss(_) => Leaf::Gnss,
        Payload::Mag(_) => Leaf::Mag,
        Payload::Baro(_) => Leaf::Baro,
        Payload::Camera(_) => Leaf::Camera,
        Payload::Config(_) => Leaf::Config,
    }
}

/// The protobuf encoding of a payload's message (the Zenoh body / MCAP record).
pub fn encode_payload(p: &Payload) -> Vec<u8> {
    match p {
        Payload::Imu(m) => m.encode_to_vec(),
        Payload::Gnss(m) => m.encode_to_vec(),
        Payload::Mag(m) => m.encode_to_vec(),
        Payload::Baro(m) => m.encode_to_vec(),
        Payload::Camera(m) => m.encode_to_vec(),
        Payload::Config(m) => m.encode_to_vec(),
    }
}

impl IngestSender {
    /// Sends one message for `vehicle_id`. Waits while the transport applies back-pressure.
    pub async fn send(&self, vehicle_id: &str, payload: Payload) -> Result<(), ClientError> {
        check_vehicle_id(vehicle_id)?;
        let leaf = leaf_of(&payload);
        match &self.sink {
            Sink::Grpc(tx) => {
                // Fail fast: the request side of a refused stream may still be held by the
                // transport for a moment, and sends would fill its buffer for nothing.
                if self.stats.is_refused.load(Ordering::Relaxed)
                    && let Some(e) = self.stats.stream_refusal("Ingest")
                {
                    return Err(e);
                }
                let sequence = self.seq.fetch_add(1, Ordering::Relaxed);
                let len = payload_len(&payload);
                let env = pb::SensorEnvelope {
                    vehicle_id: vehicle_id.to_string(),
                    sequence,
                    payload: Some(payload),
                };
                if tx.send(env).await.is_err() {
                    return Err(self
                        .stats
                        .stream_refusal("Ingest")
                        .unwrap_or(ClientError::Closed("ingest stream")));
                }
                self.stats.bytes.fetch_add(len as u64, Ordering::Relaxed);
            }
            #[cfg(feature = "zenoh")]
            Sink::Zenoh(session, keeper) => {
                let key = crate::keys::vehicle_key(vehicle_id, leaf);
                self.await_subscriber(session, keeper, vehicle_id, &key)
                    .await;
                let body = encode_payload(&payload);
                let len = body.len();
                let put = session
                    .put(&key, body)
                    .encoding(crate::zenoh_backend::encoding(leaf.message_name()))
                    .congestion_control(zenoh::qos::CongestionControl::Block)
                    .await;
                if let Err(e) = put {
                    self.stats.error(format!("zenoh put: {e}"));
                    return Err(ClientError::Zenoh {
                        op: "put",
                        key,
                        reason: e.to_string(),
                    });
                }
                if let Payload::Config(c) = &payload {
                    keeper.remember(vehicle_id, c);
                }
                self.stats.bytes.fetch_add(len as u64, Ordering::Relaxed);
                self.stats.accepted.fetch_add(1, Ordering::Relaxed);
            }
            Sink::Discard => {
                // Encode like a transport would, then drop: the cost of producing the load.
                let env = pb::SensorEnvelope {
                    vehicle_id: vehicle_id.to_string(),
                    sequence: 0,
                    payload: Some(payload),
                };
                let body = env.encode_to_vec();
                self.stats
                    .bytes
                    .fetch_add(body.len() as u64, Ordering::Relaxed);
                self.stats.accepted.fetch_add(1, Ordering::Relaxed);
                self.stats.acked.fetch_add(1, Ordering::Relaxed);
                self.stats.ok.fetch_add(1, Ordering::Relaxed);
            }
        }
        self.stats.sent.fetch_add(1, Ordering::Relaxed);
        self.stats.count_sent(leaf);
        Ok(())
    }

    /// The stream's counters.
    pub fn stats(&self) -> &Arc<IngestStats> {
        &self.stats
    }

    #[cfg(feature = "zenoh")]
    /// On a vehicle's first Zenoh message: waits until the service's subscription is known, so
    /// the start of the stream is not routed nowhere (counted as an error when none shows up),
    /// and has the keeper watch the vehicle's health.
    async fn await_subscriber(
        &self,
        session: &zenoh::Session,
        keeper: &crate::zenoh_keeper::ConfigKeeper,
        vehicle_id: &str,
        key: &str,
    ) {
        let known = self
            .matched
            .lock()
            .map(|m| m.contains(vehicle_id))
            .unwrap_or(true);
        if known {
            return;
        }
        let wait = crate::zenoh_backend::SUBSCRIBER_WAIT;
        if !crate::zenoh_backend::wait_for_subscriber(session, key, wait).await {
            tracing::warn!(
                key,
                "no subscriber for this key after {wait:?}; publishing anyway"
            );
            self.stats
                .error(format!("no subscriber matched {key} within {wait:?}"));
        }
        if let Ok(mut m) = self.matched.lock() {
            m.insert(vehicle_id.to_string());
        }
        keeper.watch(vehicle_id);
    }
}

fn payload_len(p: &Payload) -> usize {
    match p {
        Payload::Imu(m) => m.encoded_len(),
        Payload::Gnss(m) => m.encoded_len(),
        Payload::Mag(m) => m.encoded_len(),
        Payload::Baro(m) => m.encoded_len(),
        Payload::Camera(m) => m.encoded_len(),
        Payload::Config(m) => m.encoded_len(),
    }
}

/// One logical ingest stream.
#[derive(Debug)]
pub struct Ingest {
    sender: IngestSender,
    task: Option<JoinHandle<()>>,
}

impl Ingest {
    pub(crate) fn new(sink: Sink, stats: Arc<IngestStats>, task: Option<JoinHandle<()>>) -> Self {
        Self {
            sender: IngestSender {
                sink,
                #[cfg(feature = "zenoh")]
                matched: Arc::default(),
                seq: Arc::new(AtomicU64::new(0)),
                stats,
            },
            task,
        }
    }

    /// A sender (cloneable; the stream closes when the `Ingest` and every sender are dropped).
    pub fn sender(&self) -> IngestSender {
        self.sender.clone()
    }

    /// Sends one message (see [`IngestSender::send`]).
    pub async fn send(&self, vehicle_id: &str, payload: Payload) -> Result<(), ClientError> {
        self.sender.send(vehicle_id, payload).await
    }

    /// The counters.
    pub fn stats(&self) -> &Arc<IngestStats> {
        &self.sender.stats
    }

    /// Closes the stream and waits (up to `timeout`) for the outstanding acks; returns the counters.
    /// Every other [`IngestSender`] must have been dropped for the gRPC stream to close.
    pub async fn finish(mut self, timeout: Duration) -> Arc<IngestStats> {
        let stats = Arc::clone(&self.sender.stats);
        let task = self.task.take();
        drop(self);
        if let Some(task) = task {
            let abort = task.abort_handle();
            if tokio::time::timeout(timeout, task).await.is_err() {
                abort.abort();
            }
        }
        stats
    }
}

/// The sequence number of a re-sent configuration (the senders number from 0 up, so it is
/// never theirs); its ack is not counted as one of the user's.
const RESENT_SEQUENCE: u64 = u64::MAX;

/// The latest configuration given for each vehicle (shared by a client's clones and its ingest
/// streams; a few hundred bytes per vehicle).
#[derive(Debug, Clone, Default)]
pub(crate) struct Configs(Arc<Mutex<BTreeMap<String, pb::VehicleConfig>>>);

impl Configs {
    pub(crate) fn remember(&self, id: &str, config: &pb::VehicleConfig) {
        if let Ok(mut m) = self.0.lock() {
            m.insert(id.to_string(), *config);
        }
    }

    /// The remembered configuration of vehicle `id`.
    #[cfg(feature = "zenoh")]
    pub(crate) fn get(&self, id: &str) -> Option<pb::VehicleConfig> {
        self.0.lock().ok()?.get(id).copied()
    }

    /// The remembered configuration of vehicle `id` as an envelope to re-send, if any.
    fn envelope(&self, id: &str) -> Option<pb::SensorEnvelope> {
        let m = self.0.lock().ok()?;
        m.get(id).map(|c| resent(id, c))
    }

    /// Every remembered configuration as an envelope to re-send.
    fn envelopes(&self) -> Vec<pb::SensorEnvelope> {
        let Ok(m) = self.0.lock() else {
            return Vec::new();
        };
        m.iter().map(|(id, c)| resent(id, c)).collect()
    }
}

/// A re-sent configuration of vehicle `id`.
fn resent(id: &str, config: &pb::VehicleConfig) -> pb::SensorEnvelope {
    pb::SensorEnvelope {
        vehicle_id: id.to_string(),
        sequence: RESENT_SEQUENCE,
        payload: Some(Payload::Config(*config)),
    }
}

/// The gRPC ingest driver: opens the stream, reads acks, reopens on failure (re-sending the
/// vehicles' configurations first).
pub(crate) fn spawn_grpc_driver(
    client: crate::grpc::RawClient,
    user_rx: mpsc::Receiver<pb::SensorEnvelope>,
    stats: Arc<IngestStats>,
    backoff: crate::Backoff,
    configs: Configs,
) -> JoinHandle<()> {
    let shared = Arc::new(tokio::sync::Mutex::new(user_rx));
    tokio::spawn(async move {
        let mut attempt = 0u32;
        let mut reopened = false;
        loop {
            let closed = Arc::new(std::sync::atomic::AtomicBool::new(false));
            let resend = if reopened {
                configs.envelopes()
            } else {
                Vec::new()
            };
            stats
                .configs_resent
                .fetch_add(resend.len() as u64, Ordering::Relaxed);
            let (again_tx, again_rx) = mpsc::channel(RESEND_QUEUE);
            let requests = request_stream(
                Arc::clone(&shared),
                Arc::clone(&closed),
                resend,
                again_rx,
                configs.clone(),
            );
            reopened = true;
            // Vehicles whose configuration was re-sent on this stream and not yet acknowledged:
            // acks of data in flight keep saying `needs_config` until it arrives.
            let mut pending = std::collections::BTreeSet::new();
            // Acks for runs of plain acceptances (`IngestAck.covers`): one per read of the
            // stream instead of one per envelope, at both ends.
            let mut request = tonic::Request::new(requests);
            request.metadata_mut().insert(
                ACK_RUNS_HEADER,
                tonic::metadata::MetadataValue::from_static("1"),
            );
            let last = match client.clone().ingest(request).await {
                Ok(resp) => {
                    let mut acks = resp.into_inner();
                    loop {
                        match acks.message().await {
                            Ok(Some(ack)) if ack.sequence == RESENT_SEQUENCE => {
                                pending.remove(&ack.vehicle_id);
                                if ack.status != pb::IngestStatus::Accepted as i32 {
                                    tracing::warn!(
                                        vehicle = ack.vehicle_id,
                                        reason = ack.reason,
                                        "a re-sent vehicle configuration was refused"
                                    );
                                    stats.error(format!(
                                        "re-sent configuration of {:?} refused: {}",
                                        ack.vehicle_id, ack.reason
                                    ));
                                }
                            }
                            Ok(Some(ack)) => {
                                attempt = 0;
                                stats.ack(&ack);
                                if ack.needs_config
                                    && !pending.contains(&ack.vehicle_id)
                                    && let Some(env) = configs.envelope(&ack.vehicle_id)
                                    && again_tx.try_send(env).is_ok()
                                {
                                    // The service forgot a vehicle this client configured (an
                                    // idle eviction, a restart behind a proxy): configure it again.
                                    tracing::info!(
                                        vehicle = ?ack.vehicle_id,
                                        "the service lost this vehicle's configuration; re-sending it"
                                    );
                                    stats.configs_resent.fetch_add(1, Ordering::Relaxed);
                                    pending.insert(ack.vehicle_id);
                                }
                            }
                            Ok(None) if closed.load(Ordering::Acquire) => return,
                            Ok(None) => break "the service ended the ingest stream".to_string(),
                            Err(status) if is_refusal(&status) => {
                                return refuse(&stats, status);
                            }
                            Err(status) => {
                                break format!("{:?}: {}", status.code(), status.message());
                            }
                        }
                    }
                }
                Err(status) if is_refusal(&status) => return refuse(&stats, status),
                Err(status) => format!("{:?}: {}", status.code(), status.message()),
            };
            stats.error(last.clone());
            if closed.load(Ordering::Acquire) {
                return;
            }
            attempt += 1;
            let Some(delay) = backoff.delay(attempt) else {
                tracing::error!(error = %last, "ingest stream lost; giving up");
                return;
            };
            tracing::warn!(attempt, error = %last, "ingest stream lost; reopening in {delay:?}");
            stats.reconnects.fetch_add(1, Ordering::Relaxed);
            tokio::time::sleep(delay).await;
        }
    })
}

fn is_refusal(status: &tonic::Status) -> bool {
    matches!(
        status.code(),
        tonic::Code::Unauthenticated | tonic::Code::PermissionDenied
    )
}

/// Ends the stream on a refusal: counted as an error, kept for `send` to return.
fn refuse(stats: &IngestStats, status: tonic::Status) {
    tracing::error!(code = ?status.code(), reason = status.message(), "ingest stream refused; not reopening");
    stats.error(format!("{:?}: {}", status.code(), status.message()));
    if let Ok(mut r) = stats.refused.lock() {
        *r = Some((status.code(), status.message().to_string()));
    }
    stats.is_refused.store(true, Ordering::Release);
}

/// Configurations re-sent during a stream (on `needs_config` acks) waiting to go out; beyond,
/// the next ack asks again.
const RESEND_QUEUE: usize = 64;

/// The request side: the re-sent configurations, then the user's channel (remembering the
/// configurations it carries) merged with configurations re-sent on the service's request
/// (`again`, first); marks `closed` when the user is done, which ends the stream.
fn request_stream(
    shared: Arc<tokio::sync::Mutex<mpsc::Receiver<pb::SensorEnvelope>>>,
    closed: Arc<std::sync::atomic::AtomicBool>,
    resend: Vec<pb::SensorEnvelope>,
    again: mpsc::Receiver<pb::SensorEnvelope>,
    configs: Configs,
) -> impl futures::Stream<Item = pb::SensorEnvelope> + Send + 'static {
    let user = futures::stream::unfold(
        (shared, closed, again, configs),
        |(shared, closed, mut again, configs)| async move {
            let next = tokio::select! {
                biased;
                Some(env) = again.recv() => Some(env),
                // `recv` is cancel-safe: a message is never lost when the other branch wins.
                next = async { shared.lock().await.recv().await } => next,
            };
            match next {
                Some(env) => {
                    if let Some(Payload::Config(c)) = &env.payload
                        && env.sequence != RESENT_SEQUENCE
                    {
                        configs.remember(&env.vehicle_id, c);
                    }
                    Some((env, (shared, closed, again, configs)))
                }
                None => {
                    closed.store(true, Ordering::Release);
                    None
                }
            }
        },
    );
    futures::StreamExt::chain(futures::stream::iter(resend), user)
}
