//! Pose and health subscriptions that survive transport failures.
//!
//! A [`Watch`] is fed by a task that opens the subscription, forwards its items, and when the
//! subscription fails or ends, reopens it after the [`Backoff`] delays (the attempt count restarts
//! after every item received). Items published while disconnected are missed; the watch resumes
//! with the next ones. When the backoff gives up, the watch yields one [`ClientError::GaveUp`] and
//! ends. A refusal by the service (`Unauthenticated`, `PermissionDenied`) is yielded and ends the
//! watch at once: the same credentials would be refused again.

use std::future::Future;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use futures::{Stream, StreamExt};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::backoff::Backoff;
use crate::error::ClientError;
use crate::pb;

/// Which vehicles a watch selects (OR of the selectors), and the decimation.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Selector {
    /// Exact vehicle ids.
    pub ids: Vec<String>,
    /// Every id starting with this prefix (empty = no prefix selector).
    pub prefix: String,
    /// Every vehicle, including future ones.
    pub all: bool,
    /// One message in `decimation` per vehicle (0 and 1 = every message).
    pub decimation: u32,
}

impl Selector {
    /// Every vehicle.
    pub fn all() -> Self {
        Self {
            all: true,
            ..Self::default()
        }
    }

    /// These vehicles.
    pub fn ids<I: IntoIterator<Item = S>, S: Into<String>>(ids: I) -> Self {
        Self {
            ids: ids.into_iter().map(Into::into).collect(),
            ..Self::default()
        }
    }

    /// Vehicles whose id starts with `prefix`.
    pub fn prefix(prefix: impl Into<String>) -> Self {
        Self {
            prefix: prefix.into(),
            ..Self::default()
        }
    }

    /// Keeps one message in `n` per vehicle.
    pub fn with_decimation(mut self, n: u32) -> Self {
        self.decimation = n;
        self
    }

    /// Whether it selects anything at all.
    pub fn is_empty(&self) -> bool {
        !self.all && self.ids.is_empty() && self.prefix.is_empty()
    }

    /// Whether vehicle `id` is selected.
    pub fn matches(&self, id: &str) -> bool {
        self.all
            || (!self.prefix.is_empty() && id.starts_with(&self.prefix))
            || self.ids.iter().any(|i| i == id)
    }

    /// The gRPC request.
    pub fn to_request(&self) -> pb::WatchRequest {
        pb::WatchRequest {
            vehicle_ids: self.ids.clone(),
            id_prefix: self.prefix.clone(),
            all: self.all,
            decimation: self.decimation,
        }
    }
}

/// A resuming subscription (see the module doc).
#[derive(Debug)]
pub struct Watch<T> {
    rx: mpsc::Receiver<Result<T, ClientError>>,
    task: JoinHandle<()>,
    reconnects: Arc<AtomicU64>,
}

impl<T> Drop for Watch<T> {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// Items buffered between the subscription task and the reader.
const WATCH_BUFFER: usize = 8192;

impl<T: Send + 'static> Watch<T> {
    /// Runs `open` until it yields a stream, forwards the stream, reopens on failure.
    pub(crate) fn spawn<F, Fut, S>(op: &'static str, backoff: Backoff, open: F) -> Self
    where
        F: Fn() -> Fut + Send + 'static,
        Fut: Future<Output = Result<S, ClientError>> + Send,
        S: Stream<Item = Result<T, ClientError>> + Send + Unpin,
    {
        let (tx, rx) = mpsc::channel(WATCH_BUFFER);
        let reconnects = Arc::new(AtomicU64::new(0));
        let counter = Arc::clone(&reconnects);
        let task = tokio::spawn(async move {
            let mut attempt = 0u32;
            loop {
                let last = match open().await {
                    Ok(mut stream) => loop {
                        match stream.next().await {
                            Some(Ok(item)) => {
                                attempt = 0;
                                if tx.send(Ok(item)).await.is_err() {
                                    return;
                                }
                            }
                            // A refusal (credentials revoked, grant narrowed) stays a refusal.
                            Some(Err(e)) if e.is_refusal() => {
                                let _ = tx.send(Err(e)).await;
                                return;
                            }
                            Some(Err(e)) => break e.to_string(),
                            None => break "the service ended the stream".to_string(),
                        }
                    },
                    Err(e) if !e.is_transient() => {
                        let _ = tx.send(Err(e)).await;
                        return;
                    }
                    Err(e) => e.to_string(),
                };
                attempt += 1;
                let Some(delay) = backoff.delay(attempt) else {
                    let _ = tx
                        .send(Err(ClientError::GaveUp {
                            op,
                            attempts: attempt - 1,
                            last,
                        }))
                        .await;
                    return;
                };
                tracing::warn!(op, attempt, error = %last, "subscription lost; resubscribing in {delay:?}");
                counter.fetch_add(1, Ordering::Relaxed);
                tokio::time::sleep(delay).await;
            }
        });
        Self {
            rx,
            task,
            reconnects,
        }
    }

    /// The next item; `None` once the watch has ended, `Some(Err)` for a permanent failure.
    pub async fn next(&mut self) -> Option<Result<T, ClientError>> {
        self.rx.recv().await
    }

    /// How many times the subscription was reopened.
    pub fn reconnects(&self) -> u64 {
        self.reconnects.load(Ordering::Relaxed)
    }
}
