//! A pool of OS threads for the CPU-heavy vision work, so JPEG decoding and feature tracking never
//! run on the async runtime's threads.
//!
//! Bounded by admission, not by the queue: an actor asks [`VisionPool::is_saturated`] before it
//! hands a camera frame to its estimator and sheds the frame when the pool is full. A job the
//! estimator already created is always accepted (dropping it would stall that vehicle), and each
//! vehicle has at most one job out, so the queue never exceeds the number of camera vehicles.
//!
//! A worker that stays idle for [`IDLE_HANDOVER`] hands its place to a fresh thread and exits.
//! Why: the allocator (mimalloc) gives each thread its own heap, and memory a vision thread
//! allocated (a tracker's image pyramid, megabytes for a large camera) but another thread freed
//! (the vehicle's actor, at eviction) goes back to the allocating thread's heap only when that
//! thread allocates again; an idle vision thread never does, so after camera vehicles left the
//! service kept their memory. A thread that exits abandons its heap, whose free pages the
//! allocator then returns (`MIMALLOC_ABANDONED_PAGE_PURGE`, `uavnavd::allocator`), and whose
//! remaining blocks are reclaimed by the thread that frees them
//! (`MIMALLOC_ABANDONED_RECLAIM_ON_FREE`).

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// Idle time after which a worker hands its place to a fresh thread (see the module doc).
pub const IDLE_HANDOVER: Duration = Duration::from_secs(2);

/// A unit of vision work: runs on a pool thread and delivers its own result (through a channel
/// it captured).
pub type Job = Box<dyn FnOnce() + Send + 'static>;

#[derive(Debug, Default)]
struct PoolState {
    in_flight: AtomicUsize,
    completed: AtomicU64,
    panicked: AtomicU64,
    /// Workers replaced after an idle spell.
    handovers: AtomicU64,
}

/// The worker pool.
#[derive(Debug)]
pub struct VisionPool {
    tx: Mutex<Option<Sender<Job>>>,
    state: Arc<PoolState>,
    capacity: usize,
    workers: Arc<Mutex<Vec<JoinHandle<()>>>>,
    worker_count: usize,
}

/// Counters of the pool.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PoolStats {
    /// Worker threads.
    pub workers: usize,
    /// Queued + running jobs.
    pub in_flight: usize,
    /// Completed jobs (including panicked ones).
    pub completed: u64,
    /// Jobs that panicked (the vehicle's actor sees the result channel closed and resets).
    pub panicked: u64,
    /// Workers replaced by a fresh thread after an idle spell ([`IDLE_HANDOVER`]).
    pub handovers: u64,
}

impl VisionPool {
    /// Starts `workers` threads; the pool counts as saturated at `workers + queue` jobs.
    pub fn new(workers: usize, queue: usize) -> std::io::Result<Arc<Self>> {
        let n = workers.max(1);
        let (tx, rx) = channel::<Job>();
        let shared = Shared {
            rx: Arc::new(Mutex::new(rx)),
            state: Arc::new(PoolState::default()),
            handles: Arc::new(Mutex::new(Vec::with_capacity(n))),
        };
        for i in 0..n {
            spawn_worker(i, shared.clone())?;
        }
        Ok(Arc::new(Self {
            tx: Mutex::new(Some(tx)),
            state: shared.state,
            capacity: n + queue,
            workers: shared.handles,
            worker_count: n,
        }))
    }

    /// Whether new frames should be shed.
    pub fn is_saturated(&self) -> bool {
        self.state.in_flight.load(Ordering::Acquire) >= self.capacity
    }

    /// Queues a job. Returns `false` (dropping the job) only after [`VisionPool::shutdown`].
    pub fn submit(&self, job: Job) -> bool {
        let tx = self.tx.lock().ok().and_then(|t| t.clone());
        let Some(tx) = tx else { return false };
        self.state.in_flight.fetch_add(1, Ordering::AcqRel);
        if tx.send(job).is_err() {
            self.state.in_flight.fetch_sub(1, Ordering::AcqRel);
            return false;
        }
        true
    }

    /// Current counters.
    pub fn stats(&self) -> PoolStats {
        let s = &self.state;
        PoolStats {
            workers: self.worker_count,
            in_flight: s.in_flight.load(Ordering::Relaxed),
            completed: s.completed.load(Ordering::Relaxed),
            panicked: s.panicked.load(Ordering::Relaxed),
            handovers: s.handovers.load(Ordering::Relaxed),
        }
    }

    /// Stops accepting jobs and joins the threads once the queued jobs are done. Blocking.
    pub fn shutdown(&self) {
        if let Ok(mut tx) = self.tx.lock() {
            tx.take();
        }
        // A worker handing over at this moment may add a handle after a take: take until none.
        loop {
            let handles = self
                .workers
                .lock()
                .map(|mut w| std::mem::take(&mut *w))
                .unwrap_or_default();
            if handles.is_empty() {
                break;
            }
            for h in handles {
                let _ = h.join();
            }
        }
    }
}

/// What every worker thread holds.
#[derive(Clone)]
struct Shared {
    rx: Arc<Mutex<Receiver<Job>>>,
    state: Arc<PoolState>,
    /// Join handles of the live workers (and of exited ones not yet joined).
    handles: Arc<Mutex<Vec<JoinHandle<()>>>>,
}

fn spawn_worker(i: usize, shared: Shared) -> std::io::Result<()> {
    let handles = Arc::clone(&shared.handles);
    let h = std::thread::Builder::new()
        .name(format!("uavnav-vision-{i}"))
        .spawn(move || worker(i, shared))?;
    if let Ok(mut v) = handles.lock() {
        // Exited workers leave their handles behind: drop those (detaching a finished thread).
        v.retain(|h| !h.is_finished());
        v.push(h);
    }
    Ok(())
}

fn worker(i: usize, shared: Shared) {
    loop {
        // Hold the lock only while taking one job.
        let job = match shared.rx.lock() {
            Ok(r) => r.recv_timeout(IDLE_HANDOVER),
            Err(_) => return,
        };
        let job = match job {
            Ok(job) => job,
            Err(RecvTimeoutError::Timeout) => {
                // Idle: a fresh thread takes this place, this one exits (see the module doc).
                // If no thread can be started, this one stays.
                if spawn_worker(i, shared.clone()).is_ok() {
                    shared.state.handovers.fetch_add(1, Ordering::Relaxed);
                    return;
                }
                continue;
            }
            Err(RecvTimeoutError::Disconnected) => return,
        };
        // A panicking job must not take the pool down.
        if std::panic::catch_unwind(std::panic::AssertUnwindSafe(job)).is_err() {
            shared.state.panicked.fetch_add(1, Ordering::Relaxed);
        }
        shared.state.completed.fetch_add(1, Ordering::Relaxed);
        shared.state.in_flight.fetch_sub(1, Ordering::AcqRel);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saturates_at_capacity_and_runs_jobs() {
        let pool = VisionPool::new(1, 1).unwrap();
        let (go_tx, go_rx) = std::sync::mpsc::channel::<()>();
        let go_rx = Arc::new(Mutex::new(go_rx));
        for _ in 0..2 {
            let go = Arc::clone(&go_rx);
            assert!(pool.submit(Box::new(move || {
                let _ = go.lock().unwrap().recv();
            })));
        }
        assert!(pool.is_saturated());
        go_tx.send(()).unwrap();
        go_tx.send(()).unwrap();
        pool.shutdown();
        assert!(!pool.is_saturated());
        assert_eq!(pool.stats().completed, 2);
        assert!(!pool.submit(Box::new(|| {})), "closed after shutdown");
    }

    #[test]
    fn an_idle_worker_hands_over_to_a_fresh_thread_and_the_pool_keeps_working() {
        let pool = VisionPool::new(1, 0).unwrap();
        let first = std::thread::current().id();
        let (tx, rx) = std::sync::mpsc::channel();
        let t = tx.clone();
        assert!(pool.submit(Box::new(move || {
            t.send(std::thread::current().id()).unwrap()
        })));
        let a = rx.recv().unwrap();
        std::thread::sleep(IDLE_HANDOVER * 2 + Duration::from_millis(500));
        assert!(pool.stats().handovers >= 1, "{:?}", pool.stats());
        assert!(pool.submit(Box::new(move || {
            tx.send(std::thread::current().id()).unwrap()
        })));
        let b = rx.recv().unwrap();
        assert!(a != b && a != first, "a fresh thread ran the second job");
        pool.shutdown();
        assert_eq!(pool.stats().completed, 2);
        assert_eq!(pool.stats().in_flight, 0);
    }

    #[test]
    fn panicking_job_is_counted() {
        let pool = VisionPool::new(1, 0).unwrap();
        assert!(pool.submit(Box::new(|| panic!("boom"))));
        pool.shutdown();
        assert_eq!(pool.stats().panicked, 1);
        assert_eq!(pool.stats().in_flight, 0);
    }
}
