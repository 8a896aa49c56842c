//! Serves the gRPC routes connection by connection over the service's own accept loop
//! ([`crate::transport::conn`]: limits, idle timeout, TLS), with hyper's HTTP/2 set up here.
//!
//! tonic's server builder sets most HTTP/2 settings but not the per-stream send buffer, which
//! hyper then leaves at its 400 KB default: each open response stream (acknowledgements, watched
//! poses) could hold that much for a peer that stops reading, and the worst-case memory budget
//! had to count 448 KiB per stream (15 GiB at the defaults' 1,024 connections × 32 streams).
//! Served here, [`STREAM_SEND_BUFFER`] bounds it. Each request carries the connection's
//! [`PeerInfo`] (its verified certificate names), as tonic's own server inserts it. tonic's server
//! also cancelled a call at the client's `grpc-timeout`; here the client's own deadline does it
//! (it resets the stream, and hyper drops the call).

use std::convert::Infallible;
use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll};
use std::time::Duration;

use hyper_util::rt::{TokioExecutor, TokioTimer};
use hyper_util::server::conn::auto;
use hyper_util::service::TowerToHyperService;
use tokio::sync::mpsc;
use tonic::body::Body;
use tonic::codegen::http::{Request, Response};
use tonic::transport::server::Connected;

use crate::security::PeerInfo;
use crate::transport::conn::Conn;

/// Most bytes hyper buffers for one response stream beyond what the peer has read. Above the
/// 32 KiB that tonic's encoder yields at a time, so a stream that is read keeps flowing: on
/// loopback the watch stream of 2,000 vehicles' poses is written out long before it fills.
pub const STREAM_SEND_BUFFER: usize = 64 << 10;

/// The HTTP/2 settings of the gRPC port.
#[derive(Debug, Clone, Copy)]
pub struct Http2Settings {
    /// Most concurrent streams per connection (`grpc.max_streams_per_connection`).
    pub max_streams: u32,
    /// The connection and per-stream receive windows, bytes.
    pub receive_window: u32,
    /// Keepalive ping interval and timeout (`grpc.keepalive_*`), or none.
    pub keepalive: Option<(Duration, Duration)>,
}

/// Serves `routes` on the connections of `conns` until `shutdown`, then closes idle
/// connections and lets calls in progress finish (the caller bounds that wait).
pub async fn serve<S, B>(
    conns: mpsc::Receiver<Conn>,
    routes: S,
    settings: Http2Settings,
    shutdown: impl Future<Output = ()>,
) where
    S: tower::Service<Request<Body>, Response = Response<B>, Error = Infallible>
        + Clone
        + Send
        + 'static,
    S::Future: Send + 'static,
    B: http_body::Body<Data = bytes::Bytes> + Send + 'static,
    B::Error: Into<Box<dyn std::error::Error + Send + Sync>>,
{
    let mut builder = auto::Builder::new(TokioExecutor::new()).http2_only();
    builder
        .http2()
        .timer(TokioTimer::new())
        .initial_connection_window_size(settings.receive_window)
        .initial_stream_window_size(settings.receive_window)
        .max_concurrent_streams(settings.max_streams)
        .max_send_buf_size(STREAM_SEND_BUFFER);
    if let Some((interval, timeout)) = settings.keepalive {
        builder
            .http2()
            .keep_alive_interval(interval)
            .keep_alive_timeout(timeout);
    }
    let service = |c: &Conn| {
        TowerToHyperService::new(WithPeer {
            inner: routes.clone(),
            peer: c.connect_info(),
        })
    };
    crate::transport::http::serve_each(conns, &builder, "gRPC", service, shutdown).await;
}

/// Gives each request of one connection its [`PeerInfo`] and tonic's body type.
#[derive(Debug, Clone)]
struct WithPeer<S> {
    inner: S,
    peer: PeerInfo,
}

impl<S, B> tower::Service<Request<hyper::body::Incoming>> for WithPeer<S>
where
    S: tower::Service<Request<Body>, Response = Response<B>, Error = Infallible>
        + Clone
        + Send
        + 'static,
    S::Future: Send + 'static,
{
    type Response = Response<B>;
    type Error = Infallible;
    type Future = Pin<Box<dyn Future<Output = Result<Response<B>, Infallible>> + Send>>;

    fn poll_ready(&mut self, _cx: &mut Context<'_>) -> Poll<Result<(), Infallible>> {
        // Readiness is awaited per call on a fresh clone (below): hyper calls without waiting.
        Poll::Ready(Ok(()))
    }

    fn call(&mut self, req: Request<hyper::body::Incoming>) -> Self::Future {
        let mut req = req.map(Body::new);
        req.extensions_mut().insert(self.peer.clone());
        let mut inner = self.inner.clone();
        Box::pin(async move {
            std::future::poll_fn(|cx| inner.poll_ready(cx)).await?;
            inner.call(req).await
        })
    }
}
