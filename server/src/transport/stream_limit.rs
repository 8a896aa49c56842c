//! One limit on the gRPC streams open on all connections together (`grpc.max_streams`).
//!
//! Each open stream holds memory whatever it carries: HTTP/2 state, codec buffers, hyper's send
//! buffer and the response queue (`budget::GRPC_STREAM_BYTES`, 288 KiB). HTTP/2 bounds the streams
//! of one connection (`grpc.max_streams_per_connection`) and the accept loop the connections
//! (`grpc.max_connections`), but their product at the defaults, 32,768 streams, would be 9 GiB:
//! more than the memory of the machines this service is meant for, taken by any peer that opens
//! streams it never reads. [`StreamLimitService`] holds a slot of a shared [`StreamLimit`] from
//! the moment a call arrives until its response body is dropped (when the stream ends, however
//! it ends). A call that finds every slot taken is answered at once with RESOURCE_EXHAUSTED
//! naming `grpc.max_streams`, before any handler runs, and counted in
//! `uavnav_grpc_streams_refused_total`; the open streams are the gauge `uavnav_grpc_streams_open`.
//! The streams already open are not touched: a flood of new streams cannot take them down.
//!
//! One peer address may hold at most `grpc.max_streams_per_peer` of the slots (by default three
//! quarters), so that a single host opening streams it never reads cannot lock every other
//! client out: a call beyond its address's share is refused the same way, naming that key, and
//! counted in `uavnav_grpc_streams_peer_refused_total`. The share is per IP address, not per
//! principal: a peer without valid credentials is answered UNAUTHENTICATED before it reads a
//! body, so it holds its slot only for that answer, while one host can present many
//! connections.

use std::collections::HashMap;
use std::future::Future;
use std::net::IpAddr;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};

use bytes::Bytes;
use http_body::{Body as HttpBody, Frame, SizeHint};
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;
use tonic::Status;
use tonic::body::Body;
use tonic::codegen::http::{Request, Response};

use crate::security::tls::PeerInfo;

/// The limit's metrics.
#[derive(Debug, Clone, Default)]
pub struct StreamMetrics {
    /// Streams open now.
    pub open: Gauge,
    /// Calls answered with RESOURCE_EXHAUSTED because every slot was taken.
    pub refused: Counter,
    /// Calls answered with RESOURCE_EXHAUSTED because their peer address held its share.
    pub peer_refused: Counter,
}

impl StreamMetrics {
    /// Creates and registers the metrics.
    pub fn register(registry: &mut Registry) -> Self {
        let m = Self::default();
        registry.register(
            "grpc_streams_open",
            "gRPC streams open on all connections (bounded by grpc.max_streams)",
            m.open.clone(),
        );
        registry.register(
            "grpc_streams_refused",
            "gRPC calls answered with RESOURCE_EXHAUSTED because grpc.max_streams streams were open",
            m.refused.clone(),
        );
        registry.register(
            "grpc_streams_peer_refused",
            "gRPC calls answered with RESOURCE_EXHAUSTED because their peer address held grpc.max_streams_per_peer streams",
            m.peer_refused.clone(),
        );
        m
    }
}

/// The shared count of open streams.
#[derive(Debug)]
pub struct StreamLimit {
    limit: usize,
    per_peer: usize,
    /// Taken once per call (not per message), so one lock over both counts is cheap and keeps
    /// them consistent without a give-back path.
    counts: Mutex<Counts>,
    metrics: StreamMetrics,
}

/// Open streams, in all and per peer address.
#[derive(Debug, Default)]
struct Counts {
    open: usize,
    /// Entries are removed at zero, so the map holds at most one entry per open stream.
    peers: HashMap<IpAddr, usize>,
}

/// Why a call found no slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    /// Every slot of `grpc.max_streams` was taken.
    Full,
    /// The call's peer address held its share, `grpc.max_streams_per_peer`.
    PeerShare,
}

impl StreamLimit {
    /// A limit of `limit` streams (at least one), at most `per_peer` of them (at least one) from
    /// one peer address.
    pub fn new(limit: usize, per_peer: usize, metrics: StreamMetrics) -> Self {
        Self {
            limit: limit.max(1),
            per_peer: per_peer.clamp(1, limit.max(1)),
            counts: Mutex::new(Counts::default()),
            metrics,
        }
    }

    fn counts(&self) -> std::sync::MutexGuard<'_, Counts> {
        self.counts.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Takes a slot for a call from `peer` (`None`: address unknown, only the total applies),
    /// if one is free and the peer holds less than its share. A full service is reported as
    /// such even to a peer at its share (the total is checked first).
    pub fn try_open(self: &Arc<Self>, peer: Option<IpAddr>) -> Result<StreamSlot, Refused> {
        let mut c = self.counts();
        if c.open >= self.limit {
            self.metrics.refused.inc();
            return Err(Refused::Full);
        }
        if let Some(ip) = peer {
            let held = c.peers.entry(ip).or_insert(0);
            if *held >= self.per_peer {
                self.metrics.peer_refused.inc();
                return Err(Refused::PeerShare);
            }
            *held += 1;
        }
        c.open += 1;
        self.metrics.open.inc();
        Ok(StreamSlot {
            limit: Arc::clone(self),
            peer,
        })
    }

    /// Streams `ip` holds now.
    pub fn open_from(&self, ip: IpAddr) -> usize {
        self.counts().peers.get(&ip).copied().unwrap_or(0)
    }

    /// Streams open now.
    pub fn open(&self) -> usize {
        self.counts().open
    }

    /// The refusal a call gets when no slot is free for it.
    fn refusal(&self, why: Refused) -> Status {
        match why {
            Refused::Full => Status::resource_exhausted(format!(
                "{} gRPC streams are open, the service's limit (grpc.max_streams); retry later",
                self.limit
            )),
            Refused::PeerShare => Status::resource_exhausted(format!(
                "this peer address has {} gRPC streams open, its share of the service's \
                 (grpc.max_streams_per_peer); close some or retry later",
                self.per_peer
            )),
        }
    }
}

/// One open stream's slot, given back when dropped.
#[derive(Debug)]
pub struct StreamSlot {
    limit: Arc<StreamLimit>,
    peer: Option<IpAddr>,
}

impl Drop for StreamSlot {
    fn drop(&mut self) {
        let Self { limit, peer } = self;
        let mut c = limit.counts();
        c.open = c.open.saturating_sub(1);
        if let Some(ip) = peer
            && let Some(held) = c.peers.get_mut(ip)
        {
            *held = held.saturating_sub(1);
            if *held == 0 {
                c.peers.remove(ip);
            }
        }
        limit.metrics.open.dec();
    }
}

/// A response body that holds its stream's slot until it is dropped.
struct SlotBody {
    inner: Body,
    _slot: StreamSlot,
}

impl HttpBody for SlotBody {
    type Data = Bytes;
    type Error = Status;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, Status>>> {
        Pin::new(&mut self.inner).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        // Never reported ended up front: `Body::new` would then drop this wrapper, and the slot
        // with it, while hyper still sends the trailers.
        false
    }

    fn size_hint(&self) -> SizeHint {
        self.inner.size_hint()
    }
}

/// The gRPC routes wrapped so that every call holds a [`StreamLimit`] slot.
#[derive(Debug, Clone)]
pub struct StreamLimitService<S> {
    inner: S,
    limit: Arc<StreamLimit>,
}

impl<S> StreamLimitService<S> {
    /// `inner`, drawing on `limit`.
    pub fn new(inner: S, limit: Arc<StreamLimit>) -> Self {
        Self { inner, limit }
    }
}

impl<S> tower::Service<Request<Body>> for StreamLimitService<S>
where
    S: tower::Service<Request<Body>, Response = Response<Body>>,
    S::Future: Send + 'static,
    S::Error: Send + 'static,
{
    type Response = Response<Body>;
    type Error = S::Error;
    type Future = Pin<Box<dyn Future<Output = Result<Response<Body>, S::Error>> + Send>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, req: Request<Body>) -> Self::Future {
        let peer = req
            .extensions()
            .get::<PeerInfo>()
            .and_then(|p| p.remote)
            .map(|a| a.ip().to_canonical());
        let slot = match self.limit.try_open(peer) {
            Ok(slot) => slot,
            Err(why) => {
                let refusal = self.limit.refusal(why).into_http::<Body>();
                return Box::pin(std::future::ready(Ok(refusal)));
            }
        };
        let fut = self.inner.call(req);
        Box::pin(async move {
            let resp = fut.await?;
            Ok(resp.map(|inner| Body::new(SlotBody { inner, _slot: slot })))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::convert::Infallible;
    use tower::{Service, ServiceExt};

    fn limit(n: usize) -> Arc<StreamLimit> {
        Arc::new(StreamLimit::new(n, n, StreamMetrics::default()))
    }

    #[test]
    fn slots_are_counted_refused_beyond_the_limit_and_given_back() {
        let l = limit(2);
        let a = l.try_open(None).expect("first");
        let b = l.try_open(None).expect("second");
        assert_eq!(l.try_open(None).err(), Some(Refused::Full));
        assert_eq!(l.metrics.refused.get(), 1);
        assert_eq!(l.metrics.open.get(), 2);
        drop(a);
        assert_eq!(l.open(), 1);
        let _c = l.try_open(None).expect("a slot was given back");
        drop(b);
        assert_eq!(l.open(), 1);
        assert_eq!(l.metrics.open.get(), 1);
    }

    #[test]
    fn one_peer_address_holds_at_most_its_share_and_the_others_get_the_rest() {
        let l = Arc::new(StreamLimit::new(4, 3, StreamMetrics::default()));
        let (greedy, other): (IpAddr, IpAddr) = ([10, 0, 0, 1].into(), [10, 0, 0, 2].into());
        let held: Vec<_> = (0..3)
            .map(|_| l.try_open(Some(greedy)).expect("within the share"))
            .collect();
        assert_eq!(l.try_open(Some(greedy)).err(), Some(Refused::PeerShare));
        assert_eq!(l.metrics.peer_refused.get(), 1);
        assert_eq!(l.open_from(greedy), 3);
        // The slot left is another peer's to take; after it every slot is taken.
        let o = l.try_open(Some(other)).expect("the slot the share leaves");
        assert_eq!(l.try_open(Some(other)).err(), Some(Refused::Full));
        assert_eq!(l.metrics.refused.get(), 1);
        // A refusal for a full service takes nothing from the peer's count.
        assert_eq!(l.open_from(other), 1);
        drop(held);
        assert_eq!((l.open(), l.open_from(greedy)), (1, 0));
        drop(o);
        assert_eq!(l.open(), 0);
        assert!(l.counts().peers.is_empty());
    }

    #[tokio::test]
    async fn a_call_holds_its_slot_until_its_response_body_is_dropped() {
        let l = limit(1);
        let routes = tower::service_fn(|_req: Request<Body>| async {
            Ok::<_, Infallible>(Response::new(Body::new(http_body_util::Full::new(
                Bytes::from_static(b"pose"),
            ))))
        });
        let mut svc = StreamLimitService::new(routes, l.clone());
        let first = svc
            .ready()
            .await
            .unwrap_or_else(|e| match e {})
            .call(Request::new(Body::empty()))
            .await
            .unwrap_or_else(|e| match e {});
        assert_eq!(l.open(), 1);
        // The second call finds no slot: RESOURCE_EXHAUSTED naming the setting, nothing run.
        let second = svc
            .call(Request::new(Body::empty()))
            .await
            .unwrap_or_else(|e| match e {});
        let status = Status::from_header_map(second.headers()).expect("a gRPC status");
        assert_eq!(status.code(), tonic::Code::ResourceExhausted);
        assert!(status.message().contains("grpc.max_streams"), "{status:?}");
        assert_eq!(l.metrics.refused.get(), 1);
        // The first stream ends: its slot is free again.
        drop(first);
        assert_eq!(l.open(), 0);
        let third = svc
            .call(Request::new(Body::empty()))
            .await
            .unwrap_or_else(|e| match e {});
        assert_eq!(third.status(), 200);
        assert!(Status::from_header_map(third.headers()).is_none());
    }
}
