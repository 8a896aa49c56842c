//! Shutdown: waiting for SIGTERM / SIGINT, and the drain order used by
//! [`RunningServer::shutdown`](crate::server::RunningServer::shutdown):
//!
//! 1. mark not ready (`/readyz` 503, grpc.health NOT_SERVING) and raise the stop flag, which ends
//!    `Ingest` reading and every watch stream and refuses new vehicles;
//! 2. stop the Zenoh subscriptions and the gRPC listener;
//! 3. tell every actor to stop: each fuses what is queued, waits for its vision job and publishes
//!    a final health report;
//! 4. publish the remaining outputs on Zenoh, close the session, stop HTTP, finish the recording
//!    (after the drain, so it ends with the vehicles' last poses) and stop the vision pool.

/// Resolves on the first SIGTERM or SIGINT (Ctrl-C).
pub async fn signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = term.recv() => tracing::info!("SIGTERM received"),
                    _ = tokio::signal::ctrl_c() => tracing::info!("SIGINT received"),
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}
