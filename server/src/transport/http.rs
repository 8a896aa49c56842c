//! The HTTP side port: Prometheus `/metrics`, `/livez` (the process answers) and `/readyz`
//! (serving and not shutting down).
//!
//! With principals configured, `/metrics` needs an `authorization: Bearer` token of a principal
//! granted `metrics` (401 without a recognised token, 403 without the grant); the probes stay
//! open (an orchestrator's probe carries no credentials, and they tell nothing about vehicles).
//!
//! [`serve`] serves the router connection by connection over the service's own accept loop
//! ([`crate::transport::conn`]: limits, idle timeout, TLS) with hyper's HTTP/1 header timeout, so
//! a client that dribbles its request headers (slowloris) is cut off after
//! `http.header_timeout_s`.

use std::future::Future;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use axum::Router;
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::IntoResponse;
use axum::routing::get;

use axum::http::{Request, Response};
use hyper::body::Incoming;
use hyper_util::rt::{TokioExecutor, TokioIo, TokioTimer};
use hyper_util::server::conn::auto;
use hyper_util::server::graceful::GracefulShutdown;
use hyper_util::service::TowerToHyperService;
use tokio::sync::mpsc;
use tracing::debug;

use crate::metrics::Metrics;
use crate::security::AuthTransport;
use crate::service::Service;
use crate::transport::conn::Conn;

/// What the HTTP handlers read.
#[derive(Debug, Clone)]
pub struct HttpState {
    /// Metrics to expose.
    pub metrics: Metrics,
    /// Whether the service is ready (all transports up, not stopping).
    pub ready: Arc<AtomicBool>,
    /// The facade (who may read the metrics).
    pub service: Service,
}

/// The router.
pub fn router(state: HttpState) -> Router {
    Router::new()
        .route("/metrics", get(metrics))
        .route("/livez", get(|| async { "ok\n" }))
        .route("/readyz", get(readyz))
        .with_state(state)
}

/// Serves `app` on the connections of `conns` until `shutdown`, then closes idle connections
/// and lets requests in progress finish (the caller bounds that wait).
pub async fn serve(
    conns: mpsc::Receiver<Conn>,
    app: Router,
    header_timeout: Duration,
    shutdown: impl Future<Output = ()>,
) {
    let mut builder = auto::Builder::new(TokioExecutor::new());
    builder
        .http1()
        .timer(TokioTimer::new())
        .header_read_timeout(header_timeout);
    builder.http2().timer(TokioTimer::new());
    serve_each(
        conns,
        &builder,
        "HTTP",
        |_| TowerToHyperService::new(app.clone()),
        shutdown,
    )
    .await;
}

/// Serves each connection of `conns` with `builder` and the service `service(&conn)` makes for
/// it, until `shutdown`; then closes idle connections and lets requests in progress finish (the
/// caller bounds that wait). `what` names the port in the log. The gRPC port uses it too
/// ([`crate::transport::grpc_serve`]).
pub async fn serve_each<S, B>(
    mut conns: mpsc::Receiver<Conn>,
    builder: &auto::Builder<TokioExecutor>,
    what: &'static str,
    mut service: impl FnMut(&Conn) -> S,
    shutdown: impl Future<Output = ()>,
) where
    S: hyper::service::Service<Request<Incoming>, Response = Response<B>> + Send + 'static,
    S::Future: Send + 'static,
    S::Error: Into<Box<dyn std::error::Error + Send + Sync>>,
    B: http_body::Body + Send + 'static,
    B::Data: Send,
    B::Error: Into<Box<dyn std::error::Error + Send + Sync>>,
{
    let graceful = GracefulShutdown::new();
    tokio::pin!(shutdown);
    let mut accepting = true;
    loop {
        tokio::select! {
            c = conns.recv(), if accepting => {
                // The accept loop ends first at shutdown: keep serving until told to stop.
                let Some(c) = c else {
                    accepting = false;
                    continue;
                };
                let svc = service(&c);
                let conn = builder.serve_connection(TokioIo::new(c), svc).into_owned();
                let conn = graceful.watch(conn);
                tokio::spawn(async move {
                    if let Err(e) = conn.await {
                        debug!(error = %e, "{what} connection ended");
                    }
                });
            }
            () = &mut shutdown => break,
        }
    }
    graceful.shutdown().await;
}

async fn metrics(State(s): State<HttpState>, headers: HeaderMap) -> axum::response::Response {
    let token = headers.get(header::AUTHORIZATION).map(|v| v.as_bytes());
    let access = match s.service.authenticate(AuthTransport::Http, &[], token) {
        Ok(a) => a,
        Err(e) => {
            return (
                StatusCode::UNAUTHORIZED,
                [(header::WWW_AUTHENTICATE, "Bearer")],
                format!("{e}\n"),
            )
                .into_response();
        }
    };
    if !s.service.may_read_metrics(&access) {
        s.service.count_metrics_refusal(&access);
        return (
            StatusCode::FORBIDDEN,
            format!("{:?} has no grant of `metrics`\n", access.name()),
        )
            .into_response();
    }
    (
        [(
            header::CONTENT_TYPE,
            "application/openmetrics-text; version=1.0.0; charset=utf-8",
        )],
        s.metrics.encode(),
    )
        .into_response()
}

async fn readyz(State(s): State<HttpState>) -> impl IntoResponse {
    if s.ready.load(Ordering::Acquire) {
        (StatusCode::OK, "ready\n")
    } else {
        (StatusCode::SERVICE_UNAVAILABLE, "not ready\n")
    }
}
