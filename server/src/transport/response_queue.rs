//! The queue between a gRPC call's task and its response stream (acknowledgements, watched poses
//! and health), bounded in bytes as well as in messages.
//!
//! A client that stops reading a response stream leaves it full. Bounded in messages alone, a
//! watch stream held 1,024 messages of up to a few hundred bytes each plus their heap: about
//! 1 MiB per stream measured with 128 stalled watch streams (`cargo bench -p uavnavd --bench
//! memory -- --only 6`), which the worst-case budget did not count. Here the sender waits while
//! [`RESPONSE_QUEUE_BYTES`] are queued (a [`ByteBudget`], as the actors' sensor queues have); the
//! receiving stream gives the bytes back as it takes each message, before encoding it.

use futures::StreamExt;
use tokio::sync::{OwnedSemaphorePermit, mpsc};
use tokio_stream::wrappers::ReceiverStream;

use crate::vehicle::budgets::ByteBudget;

/// Most bytes one response stream holds queued (messages as held in memory: the struct and its
/// heap, estimated by the caller; [`held_bytes`] for a message with repeated fields).
pub const RESPONSE_QUEUE_BYTES: usize = 128 << 10;

/// The bytes a queued message holds: its struct and about its encoded length of heap (strings,
/// repeated fields).
pub fn held_bytes<M: prost::Message>(m: &M) -> usize {
    std::mem::size_of::<M>() + m.encoded_len()
}

/// The sending half.
#[derive(Debug)]
pub struct Sender<T> {
    tx: mpsc::Sender<(T, OwnedSemaphorePermit)>,
    room: ByteBudget,
}

/// The receiving half: the response stream. It gives each message's bytes back as it takes it
/// (the permit is dropped there).
pub type Receiver<T> = futures::stream::Map<
    ReceiverStream<(T, OwnedSemaphorePermit)>,
    fn((T, OwnedSemaphorePermit)) -> T,
>;

/// A queue of at most `messages` messages and [`RESPONSE_QUEUE_BYTES`] bytes.
pub fn channel<T>(messages: usize) -> (Sender<T>, Receiver<T>) {
    let (tx, rx) = mpsc::channel(messages);
    let room = ByteBudget::new(RESPONSE_QUEUE_BYTES);
    let take: fn((T, OwnedSemaphorePermit)) -> T = |(item, _bytes)| item;
    (Sender { tx, room }, ReceiverStream::new(rx).map(take))
}

impl<T> Sender<T> {
    /// Queues `item` of `bytes` bytes, waiting for room; `Err` when the stream is gone. A message
    /// larger than the whole queue waits until the queue is empty.
    pub async fn send(&self, item: T, bytes: usize) -> Result<(), T> {
        let permit = tokio::select! {
            p = self.room.reserve(bytes.max(1)) => p,
            () = self.tx.closed() => return Err(item),
        };
        let Some(permit) = permit else {
            return Err(item);
        };
        self.tx.send((item, permit)).await.map_err(|e| e.0.0)
    }

    /// Resolves when the receiving stream is dropped.
    pub async fn closed(&self) {
        self.tx.closed().await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
