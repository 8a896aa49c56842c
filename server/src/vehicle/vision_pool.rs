//! A pool of OS threads for the CPU-heavy vision work, so JPEG decoding and feature tracking never
//! run on the async runtime's threads.
//!
//! Bounded by admission, not by the queue: an actor asks [`VisionPool::is_saturated`] before it
//! hands a camera frame to its estimator and sheds the frame when the pool is full. A job the
//! estimator already created is always accepted (dropping it would stall that vehicle), and each
//! vehicle has at most one job out, so the queue never exceeds the number of camera vehicles.

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// A unit of vision work: runs on a pool thread and delivers its own result (through a channel
/// it captured).
pub type Job = Box<dyn FnOnce() + Send + 'static>;

#[derive(Debug, Default)]
struct PoolState {
    in_flight: AtomicUsize,
    completed: AtomicU64,
    panicked: AtomicU64,
}

/// The worker pool.
#[derive(Debug)]
pub struct VisionPool {
    tx: Mutex<Option<Sender<Job>>>,
    state: Arc<PoolState>,
    capacity: usize,
    workers: Mutex<Vec<JoinHandle<()>>>,
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
}

impl VisionPool {
    /// Starts `workers` threads; the pool counts as saturated at `workers + queue` jobs.
    pub fn new(workers: usize, queue: usize) -> std::io::Result<Arc<Self>> {
        let n = workers.max(1);
        let (tx, rx) = channel::<Job>();
        let rx = Arc::new(Mutex::new(rx));
        let state = Arc::new(PoolState::default());
        let mut handles = Vec::with_capacity(n);
        for i in 0..n {
            let (rx, state) = (Arc::clone(&rx), Arc::clone(&state));
            handles.push(
                std::thread::Builder::new()
                    .name(format!("uavnav-vision-{i}"))
                    .spawn(move || worker(rx, state))?,
            );
        }
        Ok(Arc::new(Self {
            tx: Mutex::new(Some(tx)),
            state,
            capacity: n + queue,
            workers: Mutex::new(handles),
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
        }
    }

    /// Stops accepting jobs and joins the threads once the queued jobs are done. Blocking.
    pub fn shutdown(&self) {
        if let Ok(mut tx) = self.tx.lock() {
            tx.take();
        }
        let handles = self
            .workers
            .lock()
            .map(|mut w| std::mem::take(&mut *w))
            .unwrap_or_default();
        for h in handles {
            let _ = h.join();
        }
    }
}

fn worker(rx: Arc<Mutex<Receiver<Job>>>, state: Arc<PoolState>) {
    loop {
        // Hold the lock only while taking one job.
        let job = match rx.lock() {
            Ok(r) => r.recv(),
            Err(_) => return,
        };
        let Ok(job) = job else { return };
        // A panicking job must not take the pool down.
        if std::panic::catch_unwind(std::panic::AssertUnwindSafe(job)).is_err() {
            state.panicked.fetch_add(1, Ordering::Relaxed);
        }
        state.completed.fetch_add(1, Ordering::Relaxed);
        state.in_flight.fetch_sub(1, Ordering::AcqRel);
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
    fn panicking_job_is_counted() {
        let pool = VisionPool::new(1, 0).unwrap();
        assert!(pool.submit(Box::new(|| panic!("boom"))));
        pool.shutdown();
        assert_eq!(pool.stats().panicked, 1);
        assert_eq!(pool.stats().in_flight, 0);
    }
}
