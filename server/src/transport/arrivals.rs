//! One byte budget for the gRPC messages arriving on all streams together (`grpc.arrival_bytes`).
//!
//! tonic reserves a stream's receive buffer for a whole message as soon as it reads the message's
//! 5-byte header (compressed flag, big-endian length), decompresses a compressed message into a
//! second buffer of up to `grpc.max_message_bytes`, and keeps both buffers' capacity until the
//! stream ends. Each stream is bounded by the message limit, but nothing bounded the streams
//! together: `max_connections × max_streams_per_connection` streams could each hold their
//! largest message (1 TiB at the defaults).
//!
//! [`ArrivalLayer`] wraps every request body in a [`BudgetedBody`] that reads the same headers
//! ([`MessageScanner`]) *before* tonic sees them. A stream holds, from a shared
//! [`ArrivalBudget`], the cost of the largest message it has announced ([`message_cost`]); it
//! gives it back when tonic drops the body, which is when tonic frees the buffers. A message
//! whose cost does not fit ends its stream with RESOURCE_EXHAUSTED naming `grpc.arrival_bytes`
//! before tonic reserves anything, counted in `uavnav_grpc_arrival_refused_total`; the bytes held
//! are the gauge `uavnav_grpc_arrival_bytes`.

use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll};

use bytes::Bytes;
use http_body::{Body as HttpBody, Frame, SizeHint};
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;
use tonic::Status;
use tonic::body::Body;
use tonic::codegen::http::Request;

/// The budget's metrics.
#[derive(Debug, Clone, Default)]
pub struct ArrivalMetrics {
    /// Bytes held by arriving messages now.
    pub held: Gauge,
    /// Streams ended because their next message did not fit.
    pub refused: Counter,
}

impl ArrivalMetrics {
    /// Creates and registers the metrics.
    pub fn register(registry: &mut Registry) -> Self {
        let m = Self::default();
        registry.register(
            "grpc_arrival_bytes",
            "Bytes held by gRPC messages arriving on all streams (bounded by grpc.arrival_bytes)",
            m.held.clone(),
        );
        registry.register(
            "grpc_arrival_refused",
            "gRPC streams ended with RESOURCE_EXHAUSTED because a message did not fit grpc.arrival_bytes",
            m.refused.clone(),
        );
        m
    }
}

/// What one stream holds while its largest message so far arrives and is decoded, bytes.
///
/// Uncompressed: tonic's receive buffer and the decoded message beside it (`2 × len`).
/// Compressed: the compressed bytes, plus a decompression buffer and a decoded message of up to
/// `max_message_bytes` each (the decompressed size is not known before decompressing, and a
/// header's claim of it could be forged). A message above `max_message_bytes` costs nothing:
/// tonic refuses it before reserving.
pub fn message_cost(compressed: bool, len: u32, max_message_bytes: u64) -> u64 {
    let len = u64::from(len);
    if len > max_message_bytes {
        0
    } else if compressed {
        len + 2 * max_message_bytes
    } else {
        2 * len
    }
}

/// The shared budget.
#[derive(Debug)]
pub struct ArrivalBudget {
    limit: u64,
    max_message_bytes: u64,
    used: AtomicU64,
    metrics: ArrivalMetrics,
}

impl ArrivalBudget {
    /// A budget of `limit` bytes for messages of up to `max_message_bytes`.
    pub fn new(limit: u64, max_message_bytes: u64, metrics: ArrivalMetrics) -> Self {
        Self {
            limit,
            max_message_bytes,
            used: AtomicU64::new(0),
            metrics,
        }
    }

    /// Bytes held now.
    pub fn used(&self) -> u64 {
        self.used.load(Ordering::Acquire)
    }

    /// Moves a stream's hold from `from` to `to` (`to > from`); `Err(used)` when it does not fit.
    fn grow(&self, from: u64, to: u64) -> Result<(), u64> {
        let extra = to - from;
        let mut cur = self.used.load(Ordering::Acquire);
        loop {
            if cur + extra > self.limit {
                return Err(cur);
            }
            match self.used.compare_exchange_weak(
                cur,
                cur + extra,
                Ordering::AcqRel,
                Ordering::Acquire,
            ) {
                Ok(_) => {
                    self.metrics.held.inc_by(extra as i64);
                    return Ok(());
                }
                Err(now) => cur = now,
            }
        }
    }

    fn release(&self, n: u64) {
        if n > 0 {
            self.used.fetch_sub(n, Ordering::AcqRel);
            self.metrics.held.dec_by(n as i64);
        }
    }
}

/// Reads gRPC message headers out of a request body's bytes, wherever the body's chunks split
/// them: a message is a 1-byte compressed flag, a 4-byte big-endian length, then that many bytes.
#[derive(Debug, Default, Clone)]
pub struct MessageScanner {
    header: [u8; 5],
    have: usize,
    body_left: u64,
}

impl MessageScanner {
    /// Feeds the next bytes of the body; `on_header(compressed, len)` is called for each header
    /// completed by them, in order. Its first error stops the scan and is returned.
    pub fn feed<E>(
        &mut self,
        mut data: &[u8],
        mut on_header: impl FnMut(bool, u32) -> Result<(), E>,
    ) -> Result<(), E> {
        while !data.is_empty() {
            if self.body_left > 0 {
                let n = self.body_left.min(data.len() as u64);
                data = &data[n as usize..];
                self.body_left -= n;
                continue;
            }
            let n = (5 - self.have).min(data.len());
            self.header[self.have..self.have + n].copy_from_slice(&data[..n]);
            self.have += n;
            data = &data[n..];
            if self.have == 5 {
                self.have = 0;
                let [flag, l0, l1, l2, l3] = self.header;
                let len = u32::from_be_bytes([l0, l1, l2, l3]);
                self.body_left = u64::from(len);
                on_header(flag != 0, len)?;
            }
        }
        Ok(())
    }
}

/// A request body that holds its stream's share of the [`ArrivalBudget`].
pub struct BudgetedBody {
    inner: Body,
    budget: Arc<ArrivalBudget>,
    scanner: MessageScanner,
    held: u64,
    failed: bool,
}

impl std::fmt::Debug for BudgetedBody {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BudgetedBody")
            .field("held", &self.held)
            .field("failed", &self.failed)
            .finish_non_exhaustive()
    }
}

impl BudgetedBody {
    /// Wraps `inner`.
    pub fn new(inner: Body, budget: Arc<ArrivalBudget>) -> Self {
        Self {
            inner,
            budget,
            scanner: MessageScanner::default(),
            held: 0,
            failed: false,
        }
    }

    /// Charges the headers in `data`; the refusal when a message does not fit.
    fn charge(&mut self, data: &[u8]) -> Result<(), Status> {
        let Self {
            budget,
            scanner,
            held,
            ..
        } = self;
        scanner.feed(data, |compressed, len| {
            let cost = message_cost(compressed, len, budget.max_message_bytes);
            if cost <= *held {
                return Ok(());
            }
            match budget.grow(*held, cost) {
                Ok(()) => {
                    *held = cost;
                    Ok(())
                }
                Err(used) => {
                    budget.metrics.refused.inc();
                    let kind = if compressed {
                        " compressed (which may decompress to grpc.max_message_bytes)"
                    } else {
                        ""
                    };
                    Err(Status::resource_exhausted(format!(
                        "grpc.arrival_bytes exhausted: messages arriving on all streams hold {used} of \
                         {} bytes, and this stream's {len}-byte{kind} message needs {cost}",
                        budget.limit
                    )))
                }
            }
        })
    }
}

impl Drop for BudgetedBody {
    fn drop(&mut self) {
        self.budget.release(self.held);
    }
}

impl HttpBody for BudgetedBody {
    type Data = Bytes;
    type Error = Status;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, Status>>> {
        if self.failed {
            return Poll::Ready(None);
        }
        let frame = match Pin::new(&mut self.inner).poll_frame(cx) {
            Poll::Ready(Some(Ok(frame))) => frame,
            other => return other,
        };
        if let Some(data) = frame.data_ref()
            && let Err(refusal) = self.charge(data)
        {
            self.failed = true;
            return Poll::Ready(Some(Err(refusal)));
        }
        Poll::Ready(Some(Ok(frame)))
    }

    fn is_end_stream(&self) -> bool {
        self.failed || self.inner.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.inner.size_hint()
    }
}

/// The tower layer that budgets every gRPC request body.
#[derive(Debug, Clone)]
pub struct ArrivalLayer {
    budget: Arc<ArrivalBudget>,
}

impl ArrivalLayer {
    /// A layer charging `budget`.
    pub fn new(budget: Arc<ArrivalBudget>) -> Self {
        Self { budget }
    }
}

impl<S> tower::Layer<S> for ArrivalLayer {
    type Service = ArrivalService<S>;

    fn layer(&self, inner: S) -> Self::Service {
        ArrivalService {
            inner,
            budget: self.budget.clone(),
        }
    }
}

/// [`ArrivalLayer`]'s service.
#[derive(Debug, Clone)]
pub struct ArrivalService<S> {
    inner: S,
    budget: Arc<ArrivalBudget>,
}

impl<S> tower::Service<Request<Body>> for ArrivalService<S>
where
    S: tower::Service<Request<Body>>,
{
    type Response = S::Response;
    type Error = S::Error;
    type Future = S::Future;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, req: Request<Body>) -> Self::Future {
        let budget = self.budget.clone();
        self.inner
            .call(req.map(|body| Body::new(BudgetedBody::new(body, budget))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message(compressed: bool, body: &[u8]) -> Vec<u8> {
        let mut m = vec![u8::from(compressed)];
        m.extend_from_slice(&(body.len() as u32).to_be_bytes());
        m.extend_from_slice(body);
        m
    }

    #[test]
    fn the_scanner_finds_every_header_however_the_chunks_split_them() {
        let mut wire = message(false, &[7; 300]);
        wire.extend(message(true, &[1; 5]));
        wire.extend(message(false, &[]));
        wire.extend(message(false, &[2; 70_000]));
        let want = vec![(false, 300), (true, 5), (false, 0), (false, 70_000)];
        for chunk in [1, 2, 3, 4, 5, 6, 7, 299, 305, 4096, wire.len()] {
            let mut s = MessageScanner::default();
            let mut got = Vec::new();
            for c in wire.chunks(chunk) {
                s.feed(c, |f, l| {
                    got.push((f, l));
                    Ok::<_, ()>(())
                })
                .unwrap();
            }
            assert_eq!(got, want, "chunks of {chunk} bytes");
        }
    }

    #[test]
    fn costs_follow_what_tonic_allocates() {
        let m = 16 << 20;
        assert_eq!(message_cost(false, 1000, m), 2000);
        assert_eq!(message_cost(true, 1000, m), 1000 + 2 * m);
        // Oversize: tonic refuses it before reserving anything.
        assert_eq!(message_cost(false, (m + 1) as u32, m), 0);
    }

    fn budget(limit: u64) -> Arc<ArrivalBudget> {
        Arc::new(ArrivalBudget::new(
            limit,
            1 << 20,
            ArrivalMetrics::default(),
        ))
    }

    async fn drain(body: &mut BudgetedBody) -> Result<usize, Status> {
        use http_body_util::BodyExt;
        let mut n = 0;
        while let Some(f) = body.frame().await {
            n += f?.into_data().map(|d| d.len()).unwrap_or(0);
        }
        Ok(n)
    }

    #[tokio::test]
    async fn streams_share_the_budget_and_give_it_back_when_dropped() {
        let b = budget(1_000_000);
        let big = message(false, &[0; 400_000]);
        let mut first = BudgetedBody::new(
            Body::new(http_body_util::Full::new(Bytes::from(big.clone()))),
            b.clone(),
        );
        assert_eq!(drain(&mut first).await.unwrap(), big.len());
        assert_eq!(b.used(), 800_000, "held until the stream ends");
        // A second stream's large message no longer fits: refused, naming the setting.
        let mut second = BudgetedBody::new(
            Body::new(http_body_util::Full::new(Bytes::from(big.clone()))),
            b.clone(),
        );
        let err = drain(&mut second).await.unwrap_err();
        assert_eq!(err.code(), tonic::Code::ResourceExhausted);
        assert!(
            err.message().contains("grpc.arrival_bytes"),
            "{}",
            err.message()
        );
        assert_eq!(b.metrics.refused.get(), 1);
        drop(second);
        assert_eq!(b.used(), 800_000);
        // Small messages still fit beside it; the first stream's hold comes back on drop.
        let mut small = BudgetedBody::new(
            Body::new(http_body_util::Full::new(Bytes::from(message(
                false, &[0; 1000],
            )))),
            b.clone(),
        );
        drain(&mut small).await.unwrap();
        assert_eq!(b.used(), 802_000);
        drop(first);
        drop(small);
        assert_eq!(b.used(), 0);
        assert_eq!(b.metrics.held.get(), 0);
        let mut again = BudgetedBody::new(
            Body::new(http_body_util::Full::new(Bytes::from(big))),
            b.clone(),
        );
        drain(&mut again).await.unwrap();
    }

    #[tokio::test]
    async fn a_compressed_message_holds_room_for_its_decompressed_copies() {
        let b = budget(3 << 20);
        let mut z = BudgetedBody::new(
            Body::new(http_body_util::Full::new(Bytes::from(message(
                true, &[0; 100],
            )))),
            b.clone(),
        );
        drain(&mut z).await.unwrap();
        assert_eq!(b.used(), 100 + 2 * (1 << 20));
        let mut z2 = BudgetedBody::new(
            Body::new(http_body_util::Full::new(Bytes::from(message(
                true, &[0; 100],
            )))),
            b.clone(),
        );
        assert!(drain(&mut z2).await.is_err());
    }
}
