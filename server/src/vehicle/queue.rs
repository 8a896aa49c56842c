//! The ordered input queue of one vehicle actor: many senders (the transports' ingest tasks),
//! one receiver (the actor), bounded in messages; senders wait for room (back-pressure).
//!
//! Why not `tokio::sync::mpsc`: at fleet scale every input message crosses one of these queues,
//! and tokio's bounded channel gives its permit back through a semaphore that takes a mutex on
//! every receive, besides its block list and ready bits. Here a message costs one uncontended
//! lock on each side and a waker; with tokio's channel, its list, semaphore and waker were about
//! 6.5 % of the service's CPU at 1,000 vehicles.
//!
//! The lifecycle is tokio's: `recv` gives `None` once the queue is empty and either every sender
//! has gone or the receiver closed it; a closed queue refuses new messages (they are handed back).

use std::collections::VecDeque;
use std::future::poll_fn;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::task::{Context, Poll};

use futures::task::AtomicWaker;
use tokio::sync::Notify;

/// Slots an emptied queue keeps; a burst's larger buffer is given back once it is drained.
const KEPT_SLOTS: usize = 16;

/// Why [`Sender::try_send`] handed the message back.
#[derive(Debug, PartialEq, Eq)]
pub enum TrySendError<T> {
    /// The queue holds its capacity.
    Full(T),
    /// The receiver is gone or closed the queue.
    Closed(T),
}

struct Shared<T> {
    state: Mutex<State<T>>,
    capacity: usize,
    /// The receiver closed the queue or is gone (mirrors `State::closed` for lock-free reads).
    closed: AtomicBool,
    senders: AtomicUsize,
    /// The receiver's task, woken by a message or by the last sender leaving.
    receiver: AtomicWaker,
    /// Senders waiting for room, woken one per message taken (all when the queue closes).
    room: Notify,
}

struct State<T> {
    items: VecDeque<T>,
    closed: bool,
    /// Senders that found the queue full and wait for room.
    waiting: usize,
}

impl<T> Shared<T> {
    fn lock(&self) -> MutexGuard<'_, State<T>> {
        // A panic while holding the lock leaves a consistent queue: every critical section is a
        // single push, pop or flag change.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// A bounded queue of `capacity` (at least 1) messages.
pub fn channel<T>(capacity: usize) -> (Sender<T>, Receiver<T>) {
    let shared = Arc::new(Shared {
        state: Mutex::new(State {
            items: VecDeque::new(),
            closed: false,
            waiting: 0,
        }),
        capacity: capacity.max(1),
        closed: AtomicBool::new(false),
        senders: AtomicUsize::new(1),
        receiver: AtomicWaker::new(),
        room: Notify::new(),
    });
    (
        Sender {
            shared: Arc::clone(&shared),
        },
        Receiver { shared },
    )
}

/// The sending side; cloneable.
pub struct Sender<T> {
    shared: Arc<Shared<T>>,
}

impl<T> std::fmt::Debug for Sender<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Sender")
            .field("closed", &self.is_closed())
            .finish_non_exhaustive()
    }
}

impl<T> Clone for Sender<T> {
    fn clone(&self) -> Self {
        self.shared.senders.fetch_add(1, Ordering::Relaxed);
        Self {
            shared: Arc::clone(&self.shared),
        }
    }
}

impl<T> Drop for Sender<T> {
    fn drop(&mut self) {
        if self.shared.senders.fetch_sub(1, Ordering::AcqRel) == 1 {
            self.shared.receiver.wake();
        }
    }
}

/// Counts a sender out of `State::waiting` if its wait is abandoned (its future dropped).
struct Waiting<'a, T> {
    shared: &'a Shared<T>,
    armed: bool,
}

impl<T> Drop for Waiting<'_, T> {
    fn drop(&mut self) {
        if self.armed {
            self.shared.lock().waiting -= 1;
        }
    }
}

impl<T> Sender<T> {
    /// Queues `value`, waiting while the queue is full; hands it back if the queue is closed.
    pub async fn send(&self, value: T) -> Result<(), T> {
        let shared = &*self.shared;
        let mut waited = false;
        loop {
            let notified = {
                let mut st = shared.lock();
                if waited {
                    st.waiting -= 1;
                }
                if st.closed {
                    return Err(value);
                }
                if st.items.len() < shared.capacity {
                    st.items.push_back(value);
                    drop(st);
                    shared.receiver.wake();
                    return Ok(());
                }
                st.waiting += 1;
                // Made under the lock: a `close` from now on reaches it (`notify_waiters` wakes
                // every `Notified` made before it, polled or not), and a message taken from now
                // on notifies one waiter (a permit `Notify` keeps for a waiter not yet polled).
                shared.room.notified()
            };
            let mut guard = Waiting {
                shared,
                armed: true,
            };
            notified.await;
            guard.armed = false;
            waited = true;
        }
    }

    /// Queues `value` unless the queue is full or closed.
    pub fn try_send(&self, value: T) -> Result<(), TrySendError<T>> {
        let shared = &*self.shared;
        let mut st = shared.lock();
        if st.closed {
            return Err(TrySendError::Closed(value));
        }
        if st.items.len() >= shared.capacity {
            return Err(TrySendError::Full(value));
        }
        st.items.push_back(value);
        drop(st);
        shared.receiver.wake();
        Ok(())
    }

    /// Whether the receiver closed the queue or is gone.
    pub fn is_closed(&self) -> bool {
        self.shared.closed.load(Ordering::Acquire)
    }
}

/// The receiving side (one per queue).
pub struct Receiver<T> {
    shared: Arc<Shared<T>>,
}

impl<T> std::fmt::Debug for Receiver<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Receiver").finish_non_exhaustive()
    }
}

/// Why [`Receiver::try_recv`] returned nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TryRecvError {
    /// Nothing queued now.
    Empty,
    /// Nothing queued, and nothing will be: every sender has gone or the queue is closed.
    Disconnected,
}

impl<T> Receiver<T> {
    /// Takes the oldest message, if any, under the lock already held.
    fn pop(&self, st: &mut State<T>) -> Option<T> {
        let v = st.items.pop_front()?;
        if st.waiting > 0 {
            self.shared.room.notify_one();
        }
        if st.items.is_empty() && st.items.capacity() > KEPT_SLOTS {
            st.items.shrink_to(KEPT_SLOTS);
        }
        Some(v)
    }

    /// Takes the oldest message without waiting.
    pub fn try_recv(&mut self) -> Result<T, TryRecvError> {
        let mut st = self.shared.lock();
        if let Some(v) = self.pop(&mut st) {
            return Ok(v);
        }
        if st.closed || self.shared.senders.load(Ordering::Acquire) == 0 {
            Err(TryRecvError::Disconnected)
        } else {
            Err(TryRecvError::Empty)
        }
    }

    /// Polls for the oldest message: `None` once the queue is empty and will stay so.
    pub fn poll_recv(&mut self, cx: &mut Context<'_>) -> Poll<Option<T>> {
        match self.try_recv() {
            Ok(v) => return Poll::Ready(Some(v)),
            Err(TryRecvError::Disconnected) => return Poll::Ready(None),
            Err(TryRecvError::Empty) => {}
        }
        // Registered before looking again: a message queued in between wakes this task.
        self.shared.receiver.register(cx.waker());
        match self.try_recv() {
            Ok(v) => Poll::Ready(Some(v)),
            Err(TryRecvError::Disconnected) => Poll::Ready(None),
            Err(TryRecvError::Empty) => Poll::Pending,
        }
    }

    /// Waits for the oldest message: `None` once the queue is empty and will stay so.
    pub async fn recv(&mut self) -> Option<T> {
        poll_fn(|cx| self.poll_recv(cx)).await
    }

    /// Refuses new messages (senders get theirs back); those queued can still be taken.
    pub fn close(&mut self) {
        let mut st = self.shared.lock();
        st.closed = true;
        self.shared.closed.store(true, Ordering::Release);
        drop(st);
        self.shared.room.notify_waiters();
    }
}

impl<T> Drop for Receiver<T> {
    fn drop(&mut self) {
        self.close();
        // What is still queued goes now, not with the last sender.
        let items = std::mem::take(&mut self.shared.lock().items);
        drop(items);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[tokio::test]
    async fn messages_arrive_in_order_and_the_last_sender_ends_the_queue() {
        let (tx, mut rx) = channel(4);
        let tx2 = tx.clone();
        for i in 0..3 {
            tx.send(i).await.unwrap();
        }
        tx2.send(3).await.unwrap();
        assert_eq!(tx.try_send(4), Err(TrySendError::Full(4)));
        drop(tx);
        assert_eq!(rx.try_recv(), Ok(0));
        drop(tx2);
        // Queued messages outlive their senders.
        assert_eq!(rx.recv().await, Some(1));
        assert_eq!(rx.recv().await, Some(2));
        assert_eq!(rx.recv().await, Some(3));
        assert_eq!(rx.recv().await, None);
        assert_eq!(rx.try_recv(), Err(TryRecvError::Disconnected));
    }

    #[tokio::test]
    async fn a_full_queue_makes_senders_wait_until_there_is_room() {
        let (tx, mut rx) = channel(2);
        tx.send(0).await.unwrap();
        tx.send(1).await.unwrap();
        let mut waiting = Vec::new();
        for i in 2..6 {
            let tx = tx.clone();
            waiting.push(tokio::spawn(async move { tx.send(i).await }));
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
        assert!(waiting.iter().all(|t| !t.is_finished()), "nobody got in");
        let mut got = Vec::new();
        while got.len() < 6 {
            got.push(rx.recv().await.unwrap());
        }
        for t in waiting {
            t.await.unwrap().unwrap();
        }
        assert_eq!(&got[..2], &[0, 1]);
        got.sort_unstable();
        assert_eq!(got, vec![0, 1, 2, 3, 4, 5]);
    }

    #[tokio::test]
    async fn an_abandoned_wait_does_not_block_the_next_sender() {
        let (tx, mut rx) = channel(1);
        tx.send(0).await.unwrap();
        // A sender gives up waiting (its future is dropped)...
        assert!(
            tokio::time::timeout(Duration::from_millis(10), tx.send(1))
                .await
                .is_err()
        );
        // ...and the room made next goes to the one still waiting.
        let tx2 = tx.clone();
        let next = tokio::spawn(async move { tx2.send(2).await });
        tokio::time::sleep(Duration::from_millis(10)).await;
        assert_eq!(rx.recv().await, Some(0));
        next.await.unwrap().unwrap();
        assert_eq!(rx.recv().await, Some(2));
    }

    #[tokio::test]
    async fn closing_hands_messages_back_and_keeps_what_was_queued() {
        let (tx, mut rx) = channel(1);
        tx.send(7).await.unwrap();
        let tx2 = tx.clone();
        let blocked = tokio::spawn(async move { tx2.send(8).await });
        tokio::time::sleep(Duration::from_millis(10)).await;
        rx.close();
        assert_eq!(
            blocked.await.unwrap(),
            Err(8),
            "a waiting sender gets its message back"
        );
        assert!(tx.is_closed());
        assert_eq!(tx.send(9).await, Err(9));
        assert_eq!(tx.try_send(10), Err(TrySendError::Closed(10)));
        assert_eq!(rx.try_recv(), Ok(7));
        assert_eq!(rx.recv().await, None);
    }

    #[tokio::test]
    async fn a_dropped_receiver_closes_the_queue() {
        let (tx, rx) = channel::<u32>(1);
        drop(rx);
        assert!(tx.is_closed());
        assert_eq!(tx.send(1).await, Err(1));
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn many_senders_on_two_threads_lose_nothing_and_keep_each_ones_order() {
        let (tx, mut rx) = channel(8);
        let mut tasks = Vec::new();
        for s in 0..4u64 {
            let tx = tx.clone();
            tasks.push(tokio::spawn(async move {
                for i in 0..2_000u64 {
                    tx.send((s, i)).await.unwrap();
                }
            }));
        }
        drop(tx);
        let mut next = [0u64; 4];
        while let Some((s, i)) = rx.recv().await {
            assert_eq!(i, next[s as usize], "sender {s} out of order");
            next[s as usize] += 1;
        }
        assert_eq!(next, [2_000; 4]);
        for t in tasks {
            t.await.unwrap();
        }
    }
}
