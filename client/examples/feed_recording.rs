//! Feeds a recorded flight (ASL folder or MCAP) into a service at real time, as one vehicle.
//!
//! ```text
//! cargo run -p uavnav-client --example feed_recording -- DATASET [URL] [VEHICLE_ID]
//! ```
//! URL defaults to `grpc://127.0.0.1:50051` (`zenoh/tcp/HOST:7447` works the same way).

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use uavnav_client::schedule::{Batcher, ScheduleParams};
use uavnav_client::{Client, pb};

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or_else(|| anyhow::anyhow!("usage: feed_recording DATASET [URL] [VEHICLE_ID]"))?;
    let url = args
        .next()
        .unwrap_or_else(|| "grpc://127.0.0.1:50051".into());
    let id = args.next().unwrap_or_else(|| "example-0".into());

    let dataset = uavnav_dataset::Dataset::open(std::path::Path::new(&path))?;
    let client = Client::connect_url(&url).await?;
    let ingest = client.ingest().await?;
    // The configuration first, then the sensors, each message when its last sample is due.
    ingest
        .send(
            &id,
            pb::sensor_envelope::Payload::Config(pb::VehicleConfig::from(dataset.config())),
        )
        .await?;
    let mut batcher = Batcher::new(ScheduleParams::default());
    let start = Instant::now();
    for event in dataset.events()? {
        for msg in batcher.push(&event?) {
            tokio::time::sleep_until(
                (start + Duration::from_nanos(msg.offset_ns.max(0) as u64)).into(),
            )
            .await;
            ingest.send(&id, msg.payload).await?;
        }
    }
    if let Some(msg) = batcher.finish() {
        ingest.send(&id, msg.payload).await?;
    }
    let stats = ingest.finish(Duration::from_secs(10)).await;
    println!(
        "sent {} messages, {} accepted, statuses {:?}",
        stats.sent.load(Ordering::Relaxed),
        stats.accepted.load(Ordering::Relaxed),
        stats.statuses()
    );
    Ok(())
}
