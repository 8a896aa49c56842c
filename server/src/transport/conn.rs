//! Connections: the one accept loop of every TCP listener of the service (gRPC and HTTP,
//! plaintext or TLS), so what a connection may cost is decided in one place.
//!
//! - **A limit per listener** (`grpc.max_connections`, `http.max_connections`). Beyond it a new
//!   connection is closed at once, counted (`uavnav_connections_refused_total{reason="limit"}`)
//!   and logged at most every [`LOG_EVERY`]: never queued, never a file descriptor held for it.
//! - **Accept errors** (out of file descriptors, say) back off [`ACCEPT_BACKOFF`], counted and
//!   logged, instead of spinning on the error.
//! - **An idle timeout**: a connection whose peer sends nothing for `idle_timeout_s` is closed
//!   (`uavnav_connections_closed_total{reason="idle_timeout"}`). With HTTP/2 keepalive on (gRPC),
//!   a live peer answers the service's pings, so only dead links and silent sockets reach it.
//! - **TLS** handshakes run in a task each, bounded in number and time
//!   ([`crate::security::tls::handshake`]); a connection holds its slot from accept, so
//!   handshakes in progress count against the limit.
//! - **A file-descriptor budget** ([`fd_budget`]): at startup the process's open-file limit must
//!   cover every listener's limit, Zenoh's links and a reserve; the soft limit is raised towards
//!   the hard one when needed, and the service refuses to start when even that is short.

use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc, watch};
use tokio::time::{Instant, Sleep};
use tracing::warn;

use crate::security::PeerInfo;
use crate::security::TlsFailures;
use crate::security::tls::{self, Alpn, CertStore, MAX_HANDSHAKES};

/// Pause after a failed `accept` (the error is usually "too many open files": spinning on it
/// would burn a core and free nothing).
pub const ACCEPT_BACKOFF: Duration = Duration::from_millis(100);
/// At most one warning per listener and cause in this period (a flood must not flood the log).
pub const LOG_EVERY: Duration = Duration::from_secs(10);
/// File descriptors kept for everything that is not a listener's connection: the listeners,
/// the runtime's epoll and wakers, recording files, the Foxglove live view, the vision pool.
pub const RESERVED_FDS: u64 = 256;

/// Which listener a connection came in on (the `listener` label).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ListenerKind {
    /// The gRPC port.
    Grpc,
    /// The HTTP port (metrics and probes).
    Http,
}

impl ListenerKind {
    fn label(self) -> &'static str {
        match self {
            Self::Grpc => "grpc",
            Self::Http => "http",
        }
    }
}

/// What one listener allows.
#[derive(Debug, Clone, Copy)]
pub struct ConnLimits {
    /// Connections open at once (handshakes included).
    pub max_connections: usize,
    /// A connection whose peer sent nothing for this long is closed.
    pub idle_timeout: Duration,
}

/// Labels of the per-listener connection metrics.
#[derive(Debug, Clone, PartialEq, Eq, Hash, EncodeLabelSet)]
pub struct ListenerLabels {
    /// `grpc` or `http`.
    pub listener: &'static str,
}

/// Labels of refused and closed connections.
#[derive(Debug, Clone, PartialEq, Eq, Hash, EncodeLabelSet)]
pub struct ConnReasonLabels {
    /// `grpc` or `http`.
    pub listener: &'static str,
    /// `limit`, `accept_error` (refused); `idle_timeout` (closed).
    pub reason: &'static str,
}

/// Connection metrics.
#[derive(Debug, Clone, Default)]
pub struct ConnectionMetrics {
    /// Connections open now (TLS handshakes in progress included), by listener.
    pub open: Family<ListenerLabels, Gauge>,
    /// Connections refused at accept, by listener and reason.
    pub refused: Family<ConnReasonLabels, Counter>,
    /// Connections the service closed, by listener and reason.
    pub closed: Family<ConnReasonLabels, Counter>,
}

impl ConnectionMetrics {
    /// Creates and registers the metrics.
    pub fn register(registry: &mut Registry) -> Self {
        let m = Self::default();
        registry.register(
            "connections_open",
            "TCP connections open, TLS handshakes in progress included, by listener",
            m.open.clone(),
        );
        registry.register(
            "connections_refused",
            "TCP connections refused at accept, by listener and reason (limit, accept_error)",
            m.refused.clone(),
        );
        registry.register(
            "connections_closed",
            "TCP connections the service closed, by listener and reason (idle_timeout)",
            m.closed.clone(),
        );
        m
    }

    /// Open connections on `kind` (for tests and tools).
    pub fn open_count(&self, kind: ListenerKind) -> i64 {
        self.open
            .get_or_create(&ListenerLabels {
                listener: kind.label(),
            })
            .get()
    }

    /// Refused connections on `kind` for `reason` (for tests and tools).
    pub fn refused_count(&self, kind: ListenerKind, reason: &'static str) -> u64 {
        self.refused
            .get_or_create(&ConnReasonLabels {
                listener: kind.label(),
                reason,
            })
            .get()
    }

    /// Closed connections on `kind` for `reason` (for tests and tools).
    pub fn closed_count(&self, kind: ListenerKind, reason: &'static str) -> u64 {
        self.closed
            .get_or_create(&ConnReasonLabels {
                listener: kind.label(),
                reason,
            })
            .get()
    }
}

/// The TLS side of a listener.
#[derive(Debug, Clone)]
pub struct TlsSide {
    /// The certificates.
    pub store: Arc<CertStore>,
    /// The protocols offered.
    pub alpn: Alpn,
    /// Where failed handshakes are counted.
    pub failures: TlsFailures,
}

/// An open connection: plaintext or TLS, holding its slot of the listener's limit until dropped.
#[derive(Debug)]
pub struct Conn {
    io: Io,
    info: PeerInfo,
    idle: IdleTimer,
    slot: Slot,
}

#[derive(Debug)]
enum Io {
    Plain(TcpStream),
    Tls(Box<tokio_rustls::server::TlsStream<TcpStream>>),
}

/// A slot of the listener's limit; the open gauge follows it.
#[derive(Debug)]
struct Slot {
    _permit: OwnedSemaphorePermit,
    open: Gauge,
    idle_closed: Counter,
}

impl Drop for Slot {
    fn drop(&mut self) {
        self.open.dec();
    }
}

/// The idle deadline. Reads only store the instant of the last byte; the timer is re-armed only
/// when it fires, so an active connection costs one clock read per read, not a timer update.
#[derive(Debug)]
struct IdleTimer {
    timeout: Duration,
    last_read: Instant,
    sleep: Pin<Box<Sleep>>,
}

impl IdleTimer {
    fn new(timeout: Duration) -> Self {
        let now = Instant::now();
        Self {
            timeout,
            last_read: now,
            sleep: Box::pin(tokio::time::sleep_until(now + timeout)),
        }
    }

    /// Ready once the peer has been silent for the whole timeout.
    fn poll_expired(&mut self, cx: &mut Context<'_>) -> Poll<()> {
        loop {
            if self.sleep.as_mut().poll(cx).is_pending() {
                return Poll::Pending;
            }
            let deadline = self.last_read + self.timeout;
            if deadline <= Instant::now() {
                return Poll::Ready(());
            }
            self.sleep.as_mut().reset(deadline);
        }
    }
}

impl AsyncRead for Conn {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        let before = buf.filled().len();
        let r = match &mut this.io {
            Io::Plain(s) => Pin::new(s).poll_read(cx, buf),
            Io::Tls(s) => Pin::new(s.as_mut()).poll_read(cx, buf),
        };
        match r {
            Poll::Ready(Ok(())) if buf.filled().len() > before => {
                this.idle.last_read = Instant::now();
                Poll::Ready(Ok(()))
            }
            Poll::Pending => match this.idle.poll_expired(cx) {
                Poll::Ready(()) => {
                    this.slot.idle_closed.inc();
                    Poll::Ready(Err(io::Error::new(
                        io::ErrorKind::TimedOut,
                        "connection idle: closed",
                    )))
                }
                Poll::Pending => Poll::Pending,
            },
            other => other,
        }
    }
}

impl AsyncWrite for Conn {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        match &mut self.get_mut().io {
            Io::Plain(s) => Pin::new(s).poll_write(cx, buf),
            Io::Tls(s) => Pin::new(s.as_mut()).poll_write(cx, buf),
        }
    }
    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        match &mut self.get_mut().io {
            Io::Plain(s) => Pin::new(s).poll_flush(cx),
            Io::Tls(s) => Pin::new(s.as_mut()).poll_flush(cx),
        }
    }
    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        match &mut self.get_mut().io {
            Io::Plain(s) => Pin::new(s).poll_shutdown(cx),
            Io::Tls(s) => Pin::new(s.as_mut()).poll_shutdown(cx),
        }
    }
    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        match &mut self.get_mut().io {
            Io::Plain(s) => Pin::new(s).poll_write_vectored(cx, bufs),
            Io::Tls(s) => Pin::new(s.as_mut()).poll_write_vectored(cx, bufs),
        }
    }
    fn is_write_vectored(&self) -> bool {
        match &self.io {
            Io::Plain(s) => s.is_write_vectored(),
            Io::Tls(s) => s.is_write_vectored(),
        }
    }
}

impl tonic::transport::server::Connected for Conn {
    type ConnectInfo = PeerInfo;
    fn connect_info(&self) -> PeerInfo {
        self.info.clone()
    }
}

/// A warning that says itself at most every [`LOG_EVERY`], with the count of what it held back.
#[derive(Debug)]
struct Throttle {
    last: Option<Instant>,
    held: u64,
}

impl Throttle {
    fn new() -> Self {
        Self {
            last: None,
            held: 0,
        }
    }

    /// `Some(held back since the last warning)` when it is time to warn again.
    fn due(&mut self) -> Option<u64> {
        let now = Instant::now();
        match self.last {
            Some(t) if now.duration_since(t) < LOG_EVERY => {
                self.held += 1;
                None
            }
            _ => {
                self.last = Some(now);
                Some(std::mem::take(&mut self.held))
            }
        }
    }
}

/// Accepts connections on `listener` within `limits` and yields them (TLS ones once their
/// handshake finished). Ends when `stop` fires or the receiver is dropped.
pub fn accept(
    listener: TcpListener,
    kind: ListenerKind,
    limits: ConnLimits,
    tls: Option<TlsSide>,
    metrics: ConnectionMetrics,
    mut stop: watch::Receiver<bool>,
) -> mpsc::Receiver<Conn> {
    let (tx, rx) = mpsc::channel(64);
    let slots = Arc::new(Semaphore::new(limits.max_connections));
    let handshakes = Arc::new(Semaphore::new(MAX_HANDSHAKES));
    let label = ListenerLabels {
        listener: kind.label(),
    };
    let open = metrics.open.get_or_create(&label).clone();
    let idle_closed = metrics
        .closed
        .get_or_create(&ConnReasonLabels {
            listener: kind.label(),
            reason: "idle_timeout",
        })
        .clone();
    let refused = |reason| {
        metrics
            .refused
            .get_or_create(&ConnReasonLabels {
                listener: kind.label(),
                reason,
            })
            .clone()
    };
    let (refused_limit, refused_error) = (refused("limit"), refused("accept_error"));
    tokio::spawn(async move {
        let (mut limit_log, mut error_log) = (Throttle::new(), Throttle::new());
        loop {
            // Handshakes beyond the bound wait in the kernel's accept queue.
            let handshake = match &tls {
                Some(_) => match Arc::clone(&handshakes).acquire_owned().await {
                    Ok(p) => Some(p),
                    Err(_) => break,
                },
                None => None,
            };
            let accepted = tokio::select! {
                r = listener.accept() => r,
                _ = stop.wait_for(|s| *s) => break,
                _ = tx.closed() => break,
            };
            let (tcp, remote) = match accepted {
                Ok(c) => c,
                Err(e) => {
                    refused_error.inc();
                    if let Some(held) = error_log.due() {
                        warn!(listener = kind.label(), error = %e, more = held,
                            "cannot accept connections (file descriptors exhausted?); backing off");
                    }
                    tokio::time::sleep(ACCEPT_BACKOFF).await;
                    continue;
                }
            };
            let Ok(permit) = Arc::clone(&slots).try_acquire_owned() else {
                refused_limit.inc();
                if let Some(held) = limit_log.due() {
                    warn!(listener = kind.label(), limit = limits.max_connections, %remote,
                        more = held,
                        "connection limit reached: closing new connections ({}.max_connections)",
                        kind.label());
                }
                drop(tcp);
                continue;
            };
            let _ = tcp.set_nodelay(true);
            open.inc();
            let slot = Slot {
                _permit: permit,
                open: open.clone(),
                idle_closed: idle_closed.clone(),
            };
            let conn = move |io, cert_names| Conn {
                io,
                info: PeerInfo {
                    remote: Some(remote),
                    cert_names,
                },
                idle: IdleTimer::new(limits.idle_timeout),
                slot,
            };
            match &tls {
                None => {
                    if tx.send(conn(Io::Plain(tcp), Arc::from([]))).await.is_err() {
                        break;
                    }
                }
                Some(side) => {
                    let (tx, side) = (tx.clone(), side.clone());
                    tokio::spawn(async move {
                        let _handshake = handshake;
                        match tls::handshake(&side.store, side.alpn, tcp, remote).await {
                            Ok((stream, names)) => {
                                let _ = tx.send(conn(Io::Tls(Box::new(stream)), names)).await;
                            }
                            Err(reason) => side.failures.inc(reason),
                        }
                    });
                }
            }
        }
    });
    rx
}

/// The file descriptors the configuration may need at once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FdBudget {
    /// What the listeners' limits, Zenoh and the reserve add up to.
    pub needed: u64,
    /// The soft limit after any raise.
    pub limit: u64,
    /// Whether the soft limit was raised.
    pub raised: bool,
}

/// Checks that the process may open `needed` files, raising the soft limit towards the hard one
/// when it is lower. `Err` names the figures and the knobs.
pub fn fd_budget(needed: u64) -> Result<FdBudget, String> {
    use rustix::process::{Resource, getrlimit, setrlimit};
    let lim = getrlimit(Resource::Nofile);
    // `None` is "unlimited".
    let soft = lim.current.unwrap_or(u64::MAX);
    let hard = lim.maximum.unwrap_or(u64::MAX);
    if soft >= needed {
        return Ok(FdBudget {
            needed,
            limit: soft,
            raised: false,
        });
    }
    if hard < needed {
        return Err(format!(
            "file-descriptor budget: the configuration may need {needed} open files \
             (grpc.max_connections + http.max_connections + zenoh.max_sessions when Zenoh is \
             enabled + {RESERVED_FDS} reserved) but the hard limit is {hard} (soft {soft}); raise it \
             (`ulimit -Hn`, LimitNOFILE=, docker --ulimit nofile=) or lower the connection limits"
        ));
    }
    let raised = rustix::process::Rlimit {
        current: Some(needed),
        maximum: lim.maximum,
    };
    setrlimit(Resource::Nofile, raised).map_err(|e| {
        format!("file-descriptor budget: raising the soft limit from {soft} to {needed}: {e}")
    })?;
    Ok(FdBudget {
        needed,
        limit: needed,
        raised: true,
    })
}

/// The descriptors a configuration may need: every listener's limit, Zenoh's links, the reserve.
pub fn fds_needed(config: &crate::Config) -> u64 {
    // Zenoh's links: one descriptor per session, at most `zenoh.max_sessions`.
    let zenoh = if config.zenoh.enabled {
        config.zenoh.max_sessions as u64
    } else {
        0
    };
    config.grpc.max_connections as u64 + config.http.max_connections as u64 + zenoh + RESERVED_FDS
}
