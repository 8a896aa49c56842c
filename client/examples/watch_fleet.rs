//! Watches a whole fleet: one line per vehicle per second with its newest pose and health.
//!
//! ```text
//! cargo run -p uavnav-client --example watch_fleet -- [URL]
//! ```

use std::collections::BTreeMap;
use std::time::Duration;

use uavnav_client::{Client, Selector, pb};

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let url = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "grpc://127.0.0.1:50051".into());
    let client = Client::connect_url(&url).await?;
    // Ten poses per second per vehicle are plenty for a fleet overview.
    let mut poses = client
        .watch_poses(Selector::all().with_decimation(20))
        .await?;
    let mut health = client.watch_health(Selector::all()).await?;
    let mut latest: BTreeMap<String, (Option<pb::PoseEstimate>, Option<pb::VehicleHealth>)> =
        BTreeMap::new();
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    loop {
        tokio::select! {
            p = poses.next() => match p {
                Some(Ok(p)) => {
                    let id = p.vehicle_id.clone();
                    latest.entry(id).or_default().0 = Some(p);
                }
                Some(Err(e)) => return Err(e.into()),
                None => return Ok(()),
            },
            h = health.next() => if let Some(Ok(h)) = h {
                let id = h.vehicle_id.clone();
                latest.entry(id).or_default().1 = Some(h);
            },
            _ = tick.tick() => {
                for (id, (p, h)) in &latest {
                    let pos = p.as_ref().and_then(|p| p.position).unwrap_or_default();
                    let late = h.as_ref().and_then(|h| h.counters).map_or(0, |c| c.late);
                    println!("{id:<16} lat {:>12.7} lon {:>12.7} alt {:>8.1} m  late {late}", pos.latitude_deg, pos.longitude_deg, pos.altitude_m);
                }
            }
        }
    }
}
