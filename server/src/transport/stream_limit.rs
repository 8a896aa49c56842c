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

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::task::{Context, Poll};

use bytes::Bytes;
use http_body::{Body as HttpBody, Frame, SizeHint};
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;
use tonic::Status;
use tonic::body::Body;
use tonic::codegen::http::{Request, Response};

/// The limit's metrics.
#[derive(Debug, Clone, Default)]
pub struct StreamMetrics {
    /// Streams open now.
    pub open: Gauge,
    /// Calls answered with RESOURCE_EXHAUSTED because every slot was taken.
    pub refused: Counter,
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
        m
    }
}

/// The shared count of open streams.
#[derive(Debug)]
pub struct StreamLimit {
    limit: usize,
    open: AtomicUsize,
    metrics: StreamMetrics,
}

impl StreamLimit {
    /// A limit of `limit` streams (at least one).
    pub fn new(limit: usize, metrics: StreamMetrics) -> Self {
        Self {
            limit: limit.max(1),
            open: AtomicUsize::new(0),
            metrics,
        }
    }

    /// Takes a slot, if one is free.
    pub fn try_open(self: &Arc<Self>) -> Option<StreamSlot> {
        let mut n = self.open.load(Ordering::Relaxed);
        loop {
            if n >= self.limit {
                self.metrics.refused.inc();
                return None;
            }
            match self
                .open
                .compare_exchange_weak(n, n + 1, Ordering::AcqRel, Ordering::Relaxed)
            {
                Ok(_) => {
                    self.metrics.open.inc();
                    return Some(StreamSlot(Arc::clone(self)));
                }
                Err(now) => n = now,
            }
        }
    }

    /// Streams open now.
    pub fn open(&self) -> usize {
        self.open.load(Ordering::Relaxed)
    }

    /// The refusal a call gets when no slot is free.
    fn refusal(&self) -> Status {
        Status::resource_exhausted(format!(
            "{} gRPC streams are open, the service's limit (grpc.max_streams); retry later",
            self.limit
        ))
    }
}

/// One open stream's slot, given back when dropped.
#[derive(Debug)]
pub struct StreamSlot(Arc<StreamLimit>);

impl Drop for StreamSlot {
    fn drop(&mut self) {
        self.0.open.fetch_sub(1, Ordering::AcqRel);
        self.0.metrics.open.dec();
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
        let Some(slot) = self.limit.try_open() else {
            let refusal = self.limit.refusal().into_http::<Body>();
            return Box::pin(std::future::ready(Ok(refusal)));
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
        Arc::new(StreamLimit::new(n, StreamMetrics::default()))
    }

    #[test]
    fn slots_are_counted_refused_beyond_the_limit_and_given_back() {
        let l = limit(2);
        let a = l.try_open().expect("first");
        let b = l.try_open().expect("second");
        assert!(l.try_open().is_none());
        assert_eq!(l.metrics.refused.get(), 1);
        assert_eq!(l.metrics.open.get(), 2);
        drop(a);
        assert_eq!(l.open(), 1);
        let _c = l.try_open().expect("a slot was given back");
        drop(b);
        assert_eq!(l.open(), 1);
        assert_eq!(l.metrics.open.get(), 1);
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
