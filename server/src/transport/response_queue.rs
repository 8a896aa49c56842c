//! The queue between a gRPC call's task and its response stream (acknowledgements, watched poses
//! and health), bounded in bytes as well as in messages.
//!
//! A client that stops reading a response stream leaves it full. Bounded in messages alone, a
//! watch stream held 1,024 messages of up to a few hundred bytes each plus their heap: about
//! 1 MiB per stream measured with 128 stalled watch streams (`cargo bench -p uavnavd --bench
//! memory -- --only 6`), which the worst-case budget did not count. Here the sender waits while
//! [`RESPONSE_QUEUE_BYTES`] are queued; the receiving stream gives the bytes back as it takes
//! each message, before encoding it.

use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

use futures::Stream;
use tokio::sync::{Semaphore, mpsc};

/// Most bytes one response stream holds queued (messages as held in memory: the struct and its
/// heap, estimated by [`held_bytes`]).
pub const RESPONSE_QUEUE_BYTES: usize = 128 << 10;

/// The bytes a queued message holds: its struct and about its encoded length of heap (strings,
/// repeated fields).
pub fn held_bytes<M: prost::Message>(m: &M) -> usize {
    std::mem::size_of::<M>() + m.encoded_len()
}

/// The sending half.
#[derive(Debug)]
pub struct Sender<T> {
    tx: mpsc::Sender<(T, u32)>,
    room: Arc<Semaphore>,
}

/// A queue of at most `messages` messages and [`RESPONSE_QUEUE_BYTES`] bytes.
pub fn channel<T>(messages: usize) -> (Sender<T>, Receiver<T>) {
    let (tx, rx) = mpsc::channel(messages);
    let room = Arc::new(Semaphore::new(RESPONSE_QUEUE_BYTES));
    (
        Sender {
            tx,
            room: Arc::clone(&room),
        },
        Receiver { rx, room },
    )
}

impl<T> Sender<T> {
    /// Queues `item` of `bytes` bytes, waiting for room; `Err` when the stream is gone. A message
    /// larger than the whole queue waits until the queue is empty.
    pub async fn send(&self, item: T, bytes: usize) -> Result<(), T> {
        let n = bytes.clamp(1, RESPONSE_QUEUE_BYTES) as u32;
        let permit = tokio::select! {
            p = self.room.acquire_many(n) => p,
            () = self.tx.closed() => return Err(item),
        };
        match permit {
            Ok(p) => p.forget(),
            Err(_) => return Err(item),
        }
        self.tx.send((item, n)).await.map_err(|e| {
            self.room.add_permits(e.0.1 as usize);
            e.0.0
        })
    }

    /// Resolves when the receiving stream is dropped.
    pub async fn closed(&self) {
        self.tx.closed().await;
    }
}

/// The receiving half: a stream of the messages, giving their bytes back as each is taken.
#[derive(Debug)]
pub struct Receiver<T> {
    rx: mpsc::Receiver<(T, u32)>,
    room: Arc<Semaphore>,
}

impl<T> Stream for Receiver<T> {
    type Item = T;

    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<T>> {
        self.rx.poll_recv(cx).map(|m| {
            m.map(|(item, n)| {
                self.room.add_permits(n as usize);
                item
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use futures::StreamExt;

    #[tokio::test]
    async fn the_sender_waits_while_the_bytes_are_queued_and_goes_on_as_they_are_taken() {
        let (tx, mut rx) = channel::<u32>(1024);
        let third = RESPONSE_QUEUE_BYTES / 3;
        for i in 0..3 {
            tx.send(i, third).await.unwrap();
        }
        // A fourth third does not fit: it waits although the queue has message slots left.
        let blocked = tokio::time::timeout(std::time::Duration::from_millis(50), tx.send(3, third));
        assert!(blocked.await.is_err(), "the fourth message should wait");
        assert_eq!(rx.next().await, Some(0));
        tx.send(3, third).await.unwrap();
        // A message larger than the queue waits for an empty queue, then goes.
        let big = tokio::spawn(async move { tx.send(4, 10 * RESPONSE_QUEUE_BYTES).await });
        let got: Vec<u32> = rx.by_ref().take(4).collect().await;
        assert_eq!(got, vec![1, 2, 3, 4]);
        assert!(big.await.unwrap().is_ok());
    }

    #[tokio::test]
    async fn a_dropped_receiver_ends_a_waiting_sender() {
        let (tx, rx) = channel::<u32>(1);
        tx.send(0, 1).await.unwrap();
        let waiting = tokio::spawn(async move { tx.send(1, 1).await });
        drop(rx);
        assert_eq!(waiting.await.unwrap(), Err(1));
    }
}
