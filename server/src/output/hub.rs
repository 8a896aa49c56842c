//! Output fan-out: every pose and health report of every vehicle goes through one broadcast channel
//! each; the gRPC watchers and the Zenoh publisher subscribe and filter.
//!
//! Poses travel as compact [`Pose`]s (`uavnav_proto::compact`: plain data, the wire message is made
//! only for a pose that is sent) in [`PoseBatch`]es, the poses one actor published at once (a few IMU samples' worth): at fleet
//! scale poses come at IMU rate, and one ring slot, one wake-up of each subscriber and one
//! reference count per batch instead of per pose is what keeps the fan-out cheap.
//!
//! A subscriber that falls behind loses the oldest messages (it is told how many), so a slow
//! watcher never slows down estimation.

use std::sync::Arc;

use tokio::sync::{broadcast, watch};

pub use crate::output::health::HealthReport;
pub use uavnav_proto::compact::{Pose, PoseBatch};

/// Pose ring size, in batches (typically 4–10 poses each): a second of the whole fleet's poses at
/// 2000 vehicles × 200 Hz would be 400k poses; a smaller ring keeps memory flat (every slot holds
/// its batch until overwritten) and lagging watchers skip.
pub const POSE_CAPACITY: usize = 1 << 14;
/// Health reports ring size.
pub const HEALTH_CAPACITY: usize = 1 << 14;
/// Most poses in one batch (an actor that publishes more sends several batches): a ring slot
/// then holds at most `MAX_BATCH_POSES × size_of::<Pose>()` bytes of poses.
pub const MAX_BATCH_POSES: usize = 16;

/// The output channels plus the service-wide shutdown signal.
#[derive(Debug, Clone)]
pub struct Hub {
    /// Every pose.
    pub poses: broadcast::Sender<Arc<PoseBatch>>,
    /// Every health report.
    pub health: broadcast::Sender<Arc<HealthReport>>,
    /// Vehicle lifecycle for the liveliness tokens: (id, true) when a vehicle is announced (once
    /// configured or once it has a pose), (id, false) when it is gone.
    pub lifecycle: broadcast::Sender<(Arc<str>, bool)>,
    /// Becomes `true` when the service starts shutting down.
    pub stopping: watch::Receiver<bool>,
}

impl Hub {
    /// A hub and the sender that triggers shutdown.
    pub fn new() -> (Self, watch::Sender<bool>) {
        let (stop_tx, stopping) = watch::channel(false);
        let hub = Self {
            poses: broadcast::channel(POSE_CAPACITY).0,
            health: broadcast::channel(HEALTH_CAPACITY).0,
            lifecycle: broadcast::channel(4096).0,
            stopping,
        };
        (hub, stop_tx)
    }

    /// Whether shutdown has begun.
    pub fn is_stopping(&self) -> bool {
        *self.stopping.borrow()
    }
}
