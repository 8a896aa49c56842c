//! Output fan-out: every pose and health report of every vehicle goes through one broadcast channel
//! each; the gRPC watchers and the Zenoh publisher subscribe and filter.
//!
//! A subscriber that falls behind loses the oldest messages (it is told how many), so a slow
//! watcher never slows down estimation.

use std::sync::Arc;

use tokio::sync::{broadcast, watch};
use uavnav_proto::v1 as pb;

/// Broadcast capacities: about one second of the whole fleet's poses at 2000 vehicles × 200 Hz
/// would be 400k; a smaller ring keeps memory flat and lagging watchers skip.
pub const POSE_CAPACITY: usize = 1 << 16;
/// Health reports ring size.
pub const HEALTH_CAPACITY: usize = 1 << 14;

/// The output channels plus the service-wide shutdown signal.
#[derive(Debug, Clone)]
pub struct Hub {
    /// Every pose.
    pub poses: broadcast::Sender<Arc<pb::PoseEstimate>>,
    /// Every health report.
    pub health: broadcast::Sender<Arc<pb::VehicleHealth>>,
    /// Vehicle lifecycle (id, alive) for liveliness tokens.
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
