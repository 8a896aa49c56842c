//! The tonic `uavnav.v1.UavNav` service: `Ingest` (bidirectional, one ack per envelope or per
//! run of plain acceptances when the stream asks ([`ack_runs`]), flow control through a bounded
//! ack queue), `WatchPoses` / `WatchHealth` (server streams with
//! selection and decimation), `GetPose`, `ListVehicles`, `ConfigureVehicle`, `ResetVehicle`.
//!
//! Stream-level failures get precise statuses: a malformed envelope ends `Ingest` with
//! INVALID_ARGUMENT and an oversize one with RESOURCE_EXHAUSTED (tonic reports them as INTERNAL and
//! OUT_OF_RANGE; [`remap_transport_status`] fixes that for unary calls too).

use std::pin::Pin;
use std::sync::Arc;

use futures::{FutureExt, Stream, StreamExt};
use tokio::sync::{broadcast, watch};
use tonic::{Request, Response, Status, Streaming};
use uavnav_proto::v1 as pb;
use uavnav_proto::v1::uav_nav_server::UavNav;

use crate::ingest::Payload;
use crate::ingest::validate;
use crate::metrics::{Cause, Kind, Outcome, Transport};
use crate::output::hub::{HealthReport, PoseBatch};
use crate::security::{Access, AuthTransport, PeerInfo};
use crate::service::Service;
use crate::transport::ack_runs::{self, AckRuns};
use crate::transport::response_queue;

/// Outgoing message queue of one watch stream, in messages (and at most
/// [`response_queue::RESPONSE_QUEUE_BYTES`]).
const WATCH_QUEUE: usize = 1024;

/// The service implementation.
#[derive(Debug, Clone)]
pub struct UavNavService {
    service: Service,
    ack_buffer: usize,
}

impl UavNavService {
    /// The gRPC adapter of `service`.
    pub fn new(service: Service, ack_buffer: usize) -> Self {
        Self {
            service,
            ack_buffer,
        }
    }

    fn stopping(&self) -> watch::Receiver<bool> {
        self.service.hub().stopping.clone()
    }

    /// The selection of a watch request, once the caller is known and may watch all of it.
    fn watch_selector(&self, request: &Request<pb::WatchRequest>) -> Result<Selector, Status> {
        let access = self.access(request)?;
        let sel = Selector::from_request(request.get_ref())?;
        self.service
            .authorize_watch(&access, &sel.ids, &sel.prefix, sel.all)
            .map_err(|e| e.to_status())?;
        Ok(sel)
    }

    /// Who is calling: the verified client certificate of the connection (TLS) and the
    /// `authorization` metadata. Refused before the request's body is read.
    fn access<T>(&self, request: &Request<T>) -> Result<Access, Status> {
        let names = request
            .extensions()
            .get::<PeerInfo>()
            .map(|p| p.cert_names.clone())
            .unwrap_or_default();
        let token = request
            .metadata()
            .get("authorization")
            .map(|v| v.as_bytes());
        self.service
            .authenticate(AuthTransport::Grpc, &names, token)
            .map_err(|e| Status::unauthenticated(e.to_string()))
    }

    /// A watch stream over `rx` that ends with the service and counts its skips in
    /// `watch_lagged`.
    fn watch<T: Watched>(
        &self,
        rx: broadcast::Receiver<Arc<T>>,
        sel: Selector,
    ) -> BoxStream<T::Out> {
        let lagged = self.service.metrics().watch_lagged.clone();
        watch_stream(rx, sel, self.stopping(), lagged)
    }
}

type BoxStream<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send + 'static>>;

/// Maps tonic's decode failures to the statuses our contract promises: malformed protobuf and
/// bad compressed data are INVALID_ARGUMENT (tonic: INTERNAL), an oversize message
/// RESOURCE_EXHAUSTED (tonic: OUT_OF_RANGE).
pub fn remap_decode_status(s: Status) -> Status {
    match s.code() {
        tonic::Code::Internal if s.message().contains("decompressing") => {
            Status::invalid_argument(format!("bad compressed data: {}", s.message()))
        }
        tonic::Code::Internal if s.message().contains("decode") => {
            Status::invalid_argument(format!("malformed protobuf message: {}", s.message()))
        }
        tonic::Code::OutOfRange if s.message().contains("too large") => {
            Status::resource_exhausted(format!("message too large: {}", s.message()))
        }
        _ => s,
    }
}

/// Why an `Ingest` stream ended with an error, as a refusal cause (`None`: not the input's fault,
/// e.g. the client went away).
fn stream_cause(s: &Status) -> Option<Cause> {
    let msg = s.message();
    match s.code() {
        tonic::Code::InvalidArgument if msg.starts_with("bad compressed data") => {
            Some(Cause::Compression)
        }
        tonic::Code::InvalidArgument => Some(Cause::Malformed),
        // The shared budget of arriving messages (a limit of the service, not of this message).
        tonic::Code::ResourceExhausted if msg.starts_with("grpc.arrival_bytes") => {
            Some(Cause::Exhausted)
        }
        // Oversize, on the wire or once decompressed.
        tonic::Code::ResourceExhausted => Some(Cause::TooLarge),
        // Protocol errors (a compressed flag without an encoding, an unknown encoding...).
        tonic::Code::Internal | tonic::Code::Unimplemented if !msg.contains("h2 protocol") => {
            Some(Cause::Malformed)
        }
        _ => None,
    }
}

/// Rewrites a trailers-only error response from tonic's request decoding (INTERNAL for malformed
/// protobuf, OUT_OF_RANGE for oversize) into INVALID_ARGUMENT / RESOURCE_EXHAUSTED. Used as an axum
/// `map_response` layer around the whole gRPC router.
pub async fn remap_transport_status<B>(
    mut resp: tonic::codegen::http::Response<B>,
) -> tonic::codegen::http::Response<B> {
    let headers = resp.headers_mut();
    let code = headers
        .get("grpc-status")
        .and_then(|v| v.to_str().ok())
        .map(str::to_owned);
    let msg = headers
        .get("grpc-message")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_ascii_lowercase();
    let new = match code.as_deref() {
        Some("13") if msg.contains("decode") || msg.contains("decompressing") => Some("3"),
        Some("11") if msg.contains("too%20large") || msg.contains("too large") => Some("8"),
        _ => None,
    };
    if let Some(new) = new {
        headers.insert(
            "grpc-status",
            tonic::codegen::http::HeaderValue::from_static(new),
        );
    }
    resp
}

/// Queues one ack on an `Ingest` response stream; `Err` when the stream is gone.
async fn send_ack(
    tx: &response_queue::Sender<Result<pb::IngestAck, Status>>,
    ack: pb::IngestAck,
) -> Result<(), ()> {
    // Two strings are its only heap (no encoding pass on the ingest path).
    let bytes =
        std::mem::size_of::<pb::IngestAck>() + ack.vehicle_id.capacity() + ack.reason.capacity();
    tx.send(Ok(ack), bytes).await.map_err(drop)
}

async fn ack_envelope(service: &Service, access: &Access, e: pb::SensorEnvelope) -> pb::IngestAck {
    let verdict = match e.payload.as_ref().map(Payload::from) {
        Some(p) => {
            service
                .feed(access, Transport::Grpc, &e.vehicle_id, p)
                .await
        }
        None => {
            let metrics = service.metrics();
            metrics.input(Transport::Grpc, Kind::Malformed, Outcome::Invalid, 1);
            metrics.refuse(Transport::Grpc, Kind::Malformed, Cause::Missing);
            crate::ingest::Verdict::refused(
                pb::IngestStatus::InvalidArgument,
                "payload: required (imu, gnss, mag, baro, camera or config)".into(),
            )
        }
    };
    let mut vehicle_id = e.vehicle_id;
    // An id over the limit was refused: it is echoed cut at the limit, so that an acknowledgement
    // never carries back megabytes the client sent as an id.
    if vehicle_id.len() > validate::MAX_ID_LEN {
        let mut end = validate::MAX_ID_LEN;
        while !vehicle_id.is_char_boundary(end) {
            end -= 1;
        }
        vehicle_id.truncate(end);
        vehicle_id.shrink_to_fit();
    }
    pb::IngestAck {
        sequence: e.sequence,
        vehicle_id,
        status: verdict.status as i32,
        reason: verdict.reason.into(),
        needs_config: verdict.needs_config,
        // Set by `AckRuns` on a stream that asked for runs; unset (0) otherwise.
        covers: 0,
    }
}

/// Which vehicles a watch selects.
#[derive(Debug, Clone)]
struct Selector {
    ids: Vec<String>,
    prefix: String,
    all: bool,
    decimation: u32,
}

impl Selector {
    fn from_request(r: &pb::WatchRequest) -> Result<Self, Status> {
        if r.vehicle_ids.is_empty() && r.id_prefix.is_empty() && !r.all {
            return Err(Status::invalid_argument(
                "vehicle_ids, id_prefix or all: select at least one vehicle",
            ));
        }
        for id in &r.vehicle_ids {
            validate::vehicle_id(id)
                .map_err(|e| Status::invalid_argument(format!("vehicle_ids: {}", e.reason)))?;
        }
        Ok(Self {
            ids: r.vehicle_ids.clone(),
            prefix: r.id_prefix.clone(),
            all: r.all,
            decimation: r.decimation.max(1),
        })
    }

    fn matches(&self, id: &str) -> bool {
        self.all
            || (!self.prefix.is_empty() && id.starts_with(&self.prefix))
            || self.ids.iter().any(|v| v == id)
    }
}

/// What a watch stream carries: one vehicle's messages, `len()` of them per broadcast item.
trait Watched: Send + Sync + 'static {
    /// The message sent to the client.
    type Out: Send + 'static;
    /// The vehicle.
    fn vehicle_id(&self) -> &str;
    /// Messages in this item.
    fn len(&self) -> usize;
    /// The vehicle's number of the item's first message (numbered from 0 per vehicle).
    fn first_seq(&self) -> u64;
    /// Message `i` as sent.
    fn message(&self, i: usize) -> Option<Self::Out>;
    /// The bytes a queued message holds.
    fn held_bytes(out: &Self::Out) -> usize;
}

impl Watched for HealthReport {
    type Out = pb::VehicleHealth;
    fn vehicle_id(&self) -> &str {
        &self.health.vehicle_id
    }
    fn len(&self) -> usize {
        1
    }
    fn first_seq(&self) -> u64 {
        self.seq
    }
    fn message(&self, _: usize) -> Option<Self::Out> {
        Some((*self.health).clone())
    }
    fn held_bytes(out: &Self::Out) -> usize {
        response_queue::held_bytes(out)
    }
}

impl Watched for PoseBatch {
    type Out = pb::PoseEstimate;
    fn vehicle_id(&self) -> &str {
        &self.vehicle_id
    }
    fn len(&self) -> usize {
        self.poses.len()
    }
    fn first_seq(&self) -> u64 {
        self.first_seq
    }
    fn message(&self, i: usize) -> Option<Self::Out> {
        self.wire(i)
    }
    fn held_bytes(out: &Self::Out) -> usize {
        // Its nested messages are inline: the id is its only heap.
        std::mem::size_of::<Self::Out>() + out.vehicle_id.capacity()
    }
}

/// Forwards the selected, decimated messages of a broadcast channel to a watch stream until the
/// client leaves or the service stops. What it skips when behind is counted in `lagged`.
fn watch_stream<T: Watched>(
    mut rx: broadcast::Receiver<Arc<T>>,
    sel: Selector,
    mut stopping: watch::Receiver<bool>,
    lagged: prometheus_client::metrics::counter::Counter,
) -> BoxStream<T::Out> {
    let (tx, out) = response_queue::channel(WATCH_QUEUE);
    tokio::spawn(async move {
        let filter = WatchFilter { sel };
        loop {
            let first = tokio::select! {
                r = rx.recv() => r,
                _ = stopping.wait_for(|s| *s) => break,
                _ = tx.closed() => break,
            };
            // Then everything already in the ring, without going back through the select: at
            // fleet scale this task sees every pose of every vehicle (IMU rate), so the per-item
            // overhead is what bounds a watch's throughput.
            let mut next = Some(first);
            while let Some(item) = next.take() {
                match item {
                    Ok(m) => {
                        for i in filter.keep(m.vehicle_id(), m.first_seq(), m.len()) {
                            let Some(out) = m.message(i) else { continue };
                            let bytes = T::held_bytes(&out);
                            if tx.send(Ok(out), bytes).await.is_err() {
                                return;
                            }
                        }
                    }
                    // A slow watcher skips what it missed rather than slowing estimation down.
                    Err(broadcast::error::RecvError::Lagged(n)) => {
                        lagged.inc_by(n);
                    }
                    Err(broadcast::error::RecvError::Closed) => return,
                }
                next = match rx.try_recv() {
                    Ok(m) => Some(Ok(m)),
                    Err(broadcast::error::TryRecvError::Lagged(n)) => {
                        Some(Err(broadcast::error::RecvError::Lagged(n)))
                    }
                    Err(_) => None,
                };
            }
        }
    });
    Box::pin(out)
}

/// A watch's selector and decimation. It keeps nothing per vehicle: the messages carry their
/// vehicle's numbering, so a watch's memory does not grow with the ids it sees (a flood of new
/// ids), and it does no lookup per message (at fleet scale it sees every pose of every vehicle).
struct WatchFilter {
    sel: Selector,
}

impl WatchFilter {
    /// Which of the `n` messages of vehicle `id` numbered from `first_seq` on go out: none unless
    /// the vehicle is selected, then those whose number is divisible by `decimation` (so every
    /// watch with the same decimation gets the same messages, whenever it started).
    fn keep(
        &self,
        id: &str,
        first_seq: u64,
        n: usize,
    ) -> std::iter::StepBy<std::ops::Range<usize>> {
        if n == 0 || !self.sel.matches(id) {
            return (0..0).step_by(1);
        }
        let d = u64::from(self.sel.decimation.max(1));
        if d == 1 {
            return (0..n).step_by(1);
        }
        let first = ((d - first_seq % d) % d) as usize;
        (first.min(n)..n).step_by(d as usize)
    }
}

fn unknown_vehicle(id: &str) -> Status {
    Status::not_found(format!("vehicle_id: {id:?} is not known to this service"))
}

#[tonic::async_trait]
impl UavNav for UavNavService {
    type IngestStream = BoxStream<pb::IngestAck>;
    type WatchPosesStream = BoxStream<pb::PoseEstimate>;
    type WatchHealthStream = BoxStream<pb::VehicleHealth>;

    async fn ingest(
        &self,
        request: Request<Streaming<pb::SensorEnvelope>>,
    ) -> Result<Response<Self::IngestStream>, Status> {
        let access = self.access(&request)?;
        let mut runs = AckRuns::new(ack_runs::asked(request.metadata()));
        let mut inbound = request.into_inner();
        // Bounded: when the client stops reading acks we stop reading envelopes (HTTP/2 flow
        // control then pushes back on the sender).
        let (tx, rx) = response_queue::channel(self.ack_buffer);
        let service = self.service.clone();
        let mut stopping = self.stopping();
        tokio::spawn(async move {
            loop {
                // With a run of acks held, an envelope already received extends it; when none
                // is, the run goes out before the task waits, so no ack waits on the client.
                let ready = if runs.holding() {
                    inbound.next().now_or_never()
                } else {
                    None
                };
                let next = match ready {
                    Some(m) => m,
                    None => {
                        if let Some(run) = runs.flush()
                            && send_ack(&tx, run).await.is_err()
                        {
                            return;
                        }
                        tokio::select! {
                            biased;
                            _ = stopping.wait_for(|s| *s) => break,
                            m = inbound.next() => m,
                        }
                    }
                };
                match next {
                    None => break,
                    Some(Err(status)) => {
                        let status = remap_decode_status(status);
                        if let Some(cause) = stream_cause(&status) {
                            let metrics = service.metrics();
                            let outcome = match cause {
                                Cause::TooLarge => Outcome::Exhausted,
                                _ => Outcome::Invalid,
                            };
                            metrics.input(Transport::Grpc, Kind::Malformed, outcome, 1);
                            metrics.refuse(Transport::Grpc, Kind::Malformed, cause);
                        }
                        if let Some(run) = runs.flush()
                            && send_ack(&tx, run).await.is_err()
                        {
                            return;
                        }
                        let bytes = std::mem::size_of::<Status>() + status.message().len();
                        let _ = tx.send(Err(status), bytes).await;
                        return;
                    }
                    Some(Ok(envelope)) => {
                        let data = !matches!(
                            envelope.payload,
                            Some(pb::sensor_envelope::Payload::Config(_))
                        );
                        let ack = ack_envelope(&service, &access, envelope).await;
                        for a in runs.push(ack, data).into_iter().flatten() {
                            if send_ack(&tx, a).await.is_err() {
                                return;
                            }
                        }
                    }
                }
            }
            // The end of the stream, or the service stopping: what was acknowledged goes out.
            if let Some(run) = runs.flush() {
                let _ = send_ack(&tx, run).await;
            }
        });
        Ok(Response::new(Box::pin(rx)))
    }

    async fn watch_poses(
        &self,
        request: Request<pb::WatchRequest>,
    ) -> Result<Response<Self::WatchPosesStream>, Status> {
        let sel = self.watch_selector(&request)?;
        let rx = self.service.hub().poses.subscribe();
        Ok(Response::new(self.watch(rx, sel)))
    }

    async fn watch_health(
        &self,
        request: Request<pb::WatchRequest>,
    ) -> Result<Response<Self::WatchHealthStream>, Status> {
        let sel = self.watch_selector(&request)?;
        let rx = self.service.hub().health.subscribe();
        Ok(Response::new(self.watch(rx, sel)))
    }

    async fn get_pose(
        &self,
        request: Request<pb::GetPoseRequest>,
    ) -> Result<Response<pb::PoseEstimate>, Status> {
        let access = self.access(&request)?;
        let id = &request.get_ref().vehicle_id;
        let h = self
            .service
            .watched_vehicle(&access, id)
            .map_err(|e| e.to_status())?
            .ok_or_else(|| unknown_vehicle(id))?;
        let pose = h
            .shared
            .pose()
            .ok_or_else(|| Status::not_found(format!("vehicle_id: {id:?} has no pose yet")))?;
        Ok(Response::new(pose))
    }

    async fn list_vehicles(
        &self,
        request: Request<pb::ListVehiclesRequest>,
    ) -> Result<Response<pb::ListVehiclesResponse>, Status> {
        let access = self.access(&request)?;
        let vehicles = self
            .service
            .list(&access, &request.get_ref().id_prefix)
            .iter()
            .map(summary_of)
            .collect();
        Ok(Response::new(pb::ListVehiclesResponse { vehicles }))
    }

    async fn configure_vehicle(
        &self,
        request: Request<pb::ConfigureVehicleRequest>,
    ) -> Result<Response<pb::ConfigureVehicleResponse>, Status> {
        let access = self.access(&request)?;
        let r = request.get_ref();
        validate::vehicle_id(&r.vehicle_id).map_err(|e| e.to_status())?;
        let config = r
            .config
            .as_ref()
            .ok_or_else(|| Status::invalid_argument("config: required"))?;
        let created = self
            .service
            .configure(&access, &r.vehicle_id, config, true)
            .await
            .map_err(|e| e.to_status())?;
        Ok(Response::new(pb::ConfigureVehicleResponse { created }))
    }

    async fn reset_vehicle(
        &self,
        request: Request<pb::ResetVehicleRequest>,
    ) -> Result<Response<pb::ResetVehicleResponse>, Status> {
        let access = self.access(&request)?;
        let id = &request.get_ref().vehicle_id;
        match self
            .service
            .reset(&access, id)
            .await
            .map_err(|e| e.to_status())?
        {
            Some(()) => Ok(Response::new(pb::ResetVehicleResponse {})),
            None => Err(unknown_vehicle(id)),
        }
    }
}

/// The list entry of one vehicle.
pub fn summary_of(h: &crate::vehicle::actor::VehicleHandle) -> pb::VehicleSummary {
    let s = &h.shared;
    let pose = s.pose();
    let mode = s
        .health()
        .map(|x| x.mode)
        .or_else(|| pose.as_ref().map(|p| p.mode))
        .unwrap_or(pb::EstimatorMode::Initialising as i32);
    pb::VehicleSummary {
        vehicle_id: s.id.to_string(),
        mode,
        last_t_ns: pose.map(|p| p.t_ns).unwrap_or(0),
        last_input_wall_ns: s
            .last_input_wall_ns
            .load(std::sync::atomic::Ordering::Relaxed),
        configured: s.configured.load(std::sync::atomic::Ordering::Relaxed),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn filter(decimation: u32) -> WatchFilter {
        WatchFilter {
            sel: Selector {
                ids: Vec::new(),
                prefix: "a".into(),
                all: false,
                decimation,
            },
        }
    }

    /// Batches of any size keep exactly the messages a one-by-one count would: every
    /// `decimation`-th of each vehicle's messages, numbered from 0.
    #[test]
    fn decimation_across_batches_matches_a_per_message_count() {
        for d in [1u32, 3, 10] {
            let f = filter(d);
            let (mut kept, mut base) = (Vec::new(), 0usize);
            for n in [4usize, 1, 7, 0, 10, 3, 2, 25] {
                kept.extend(f.keep("a1", base as u64, n).map(|i| base + i));
                base += n;
            }
            let expected: Vec<usize> = (0..base).filter(|k| k % d as usize == 0).collect();
            assert_eq!(kept, expected, "decimation {d}");
        }
        assert_eq!(filter(2).keep("b1", 0, 8).count(), 0, "unselected vehicle");
    }

    /// Two watches with the same decimation get the same messages whenever each started, and a
    /// watch keeps nothing per vehicle however many ids it has seen.
    #[test]
    fn decimation_follows_the_vehicles_numbering() {
        let f = filter(10);
        // A watch that starts at the vehicle's 37th pose: its first is number 40.
        assert_eq!(f.keep("a1", 37, 8).collect::<Vec<_>>(), vec![3]);
        assert_eq!(f.keep("a1", 45, 4).count(), 0);
        assert_eq!(f.keep("a1", 50, 1).collect::<Vec<_>>(), vec![0]);
        assert_eq!(
            std::mem::size_of::<WatchFilter>(),
            std::mem::size_of::<Selector>()
        );
    }

    /// A watcher that does not read falls behind the broadcast ring: it skips the oldest batches,
    /// counts each skipped one, and delivers every batch it did not skip.
    #[tokio::test]
    async fn a_lagging_watch_counts_what_it_skipped() {
        use futures::StreamExt;
        let ring = 8;
        let (btx, rx) = broadcast::channel(ring);
        let (_stop_tx, stopping) = watch::channel(false);
        let lagged = prometheus_client::metrics::counter::Counter::default();
        let sel = Selector {
            ids: Vec::new(),
            prefix: String::new(),
            all: true,
            decimation: 1,
        };
        let mut out = watch_stream(rx, sel, stopping, lagged.clone());
        // The task forwards WATCH_QUEUE poses, then waits for the unread stream; the ring
        // overflows behind it.
        let total = (WATCH_QUEUE + 4 * ring) as i64;
        for t_ns in 0..total {
            let batch = PoseBatch {
                vehicle_id: "uav-1".into(),
                poses: vec![crate::output::hub::Pose {
                    t_ns,
                    ..Default::default()
                }],
                first_seq: t_ns as u64,
            };
            let _ = btx.send(Arc::new(batch));
            tokio::task::yield_now().await;
        }
        drop(btx);
        let mut got = Vec::new();
        while let Some(Ok(p)) = out.next().await {
            got.push(p.t_ns);
        }
        assert!(lagged.get() > 0, "the watcher lagged");
        assert_eq!(
            got.len() as u64 + lagged.get(),
            total as u64,
            "every batch sent or counted"
        );
        assert!(got.windows(2).all(|w| w[0] < w[1]), "in order");
        assert_eq!(
            got.last(),
            Some(&(total - 1)),
            "the newest batch is delivered"
        );
    }
}
