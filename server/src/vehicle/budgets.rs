//! The service-wide budgets the actors share: the bytes of queued sensor data (per vehicle and
//! for all, as [`ByteBudget`]s: semaphores with a permit per byte), the bytes of queued camera frames, and the
//! pixels of all configured cameras. Each is one term of the memory formula (`crate::budget`).

use std::sync::Arc;

use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use crate::ingest::validate::CameraSpec;

/// The pixels of a camera (0 without one).
pub fn camera_pixels(camera: Option<CameraSpec>) -> u64 {
    camera.map_or(0, |c| u64::from(c.width) * u64::from(c.height))
}

/// The global budget of configured camera pixels.
#[derive(Debug, Default)]
pub struct CameraPixels {
    used: std::sync::atomic::AtomicU64,
    /// Most pixels configured at once.
    pub limit: u64,
}

impl CameraPixels {
    /// A budget of `limit` pixels.
    pub fn new(limit: u64) -> Self {
        Self {
            used: Default::default(),
            limit,
        }
    }

    /// Replaces a vehicle's `old` camera pixels by `new`; false (nothing changed) when that
    /// would exceed the limit.
    pub fn swap(&self, old: u64, new: u64) -> bool {
        use std::sync::atomic::Ordering::AcqRel;
        if new <= old {
            self.used.fetch_sub(old - new, AcqRel);
            return true;
        }
        let more = new - old;
        let before = self.used.fetch_add(more, AcqRel);
        if before + more > self.limit {
            self.used.fetch_sub(more, AcqRel);
            return false;
        }
        true
    }

    /// Pixels configured now.
    pub fn used(&self) -> u64 {
        self.used.load(std::sync::atomic::Ordering::Acquire)
    }
}

/// A byte budget of a queue: a semaphore with one permit per byte. A message holds its permits
/// until it is taken off the queue. The actors' sensor queues (per vehicle and for all) and each
/// gRPC response stream's queue (`transport::response_queue`) are bounded with it.
#[derive(Debug, Clone)]
pub struct ByteBudget {
    permits: Arc<Semaphore>,
    limit: usize,
}

impl ByteBudget {
    /// A budget of `limit` bytes.
    pub fn new(limit: usize) -> Self {
        let limit = limit.min(Semaphore::MAX_PERMITS);
        Self {
            permits: Arc::new(Semaphore::new(limit)),
            limit,
        }
    }

    /// Waits for `bytes` (at most the whole budget, so that one large message always fits an
    /// empty queue).
    pub async fn reserve(&self, bytes: usize) -> Option<OwnedSemaphorePermit> {
        let n = u32::try_from(bytes.min(self.limit)).unwrap_or(u32::MAX);
        Arc::clone(&self.permits).acquire_many_owned(n).await.ok()
    }

    /// Bytes reserved now.
    pub fn used(&self) -> usize {
        self.limit - self.permits.available_permits().min(self.limit)
    }
}

/// The bytes a queued data message holds of its vehicle's and of the global budget, given back
/// when the actor takes it.
#[derive(Debug, Default)]
pub struct Reserved {
    pub(crate) _vehicle: Option<OwnedSemaphorePermit>,
    pub(crate) _global: Option<OwnedSemaphorePermit>,
}

/// The global byte budget of the camera queues.
#[derive(Debug, Default)]
pub struct CameraBytes {
    /// Compressed bytes of the frames queued at every actor.
    pub queued: std::sync::atomic::AtomicUsize,
    /// Most bytes queued at once (`vision.queue_bytes`).
    pub limit: usize,
}

#[cfg(test)]
mod tests {
    use super::{ByteBudget, CameraPixels};

    #[tokio::test]
    async fn queued_bytes_wait_for_room_and_come_back_when_taken() {
        let budget = ByteBudget::new(1000);
        let a = budget.reserve(600).await;
        assert_eq!(budget.used(), 600);
        // 600 more do not fit: the sender waits until the first message is taken.
        let mut second = Box::pin(budget.reserve(600));
        assert!(
            futures::poll!(second.as_mut()).is_pending(),
            "reserved beyond the budget"
        );
        drop(a);
        let b = second.await;
        assert_eq!(budget.used(), 600);
        drop(b);
        // A message larger than the whole budget still passes an empty queue.
        let big = budget.reserve(5000).await;
        assert_eq!(budget.used(), 1000);
        drop(big);
        assert_eq!(budget.used(), 0);
    }

    #[test]
    fn camera_pixels_are_budgeted_across_vehicles() {
        let px = CameraPixels::new(1000);
        assert!(px.swap(0, 600));
        assert!(!px.swap(0, 600), "over the budget");
        assert_eq!(px.used(), 600);
        assert!(
            px.swap(600, 1000),
            "a vehicle's own pixels are replaced, not added"
        );
        assert!(px.swap(1000, 0));
        assert_eq!(px.used(), 0);
    }
}
