//! A Zenoh subscriber that stops reading (issue row 7: every other Zenoh subscriber then got no
//! pose for 10 of 30 s): its link congests and loses what it cannot take, while a healthy
//! subscriber beside it gets every pose. The stalled subscriber reaches the service through a
//! relay that stops reading from the service (a ground station whose process hangs, or whose
//! link is slower than the fleet's poses) with a small receive buffer, so the congestion comes
//! after kilobytes, not megabytes.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use crate::common::*;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpSocket};
use uavnav_proto::v1 as pb;

/// A relay to `to` whose service-to-client direction stops reading once `stalled` is set.
async fn relay(to: SocketAddr, stalled: Arc<AtomicBool>) -> SocketAddr {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(async move {
        while let Ok((client, _)) = listener.accept().await {
            let socket = TcpSocket::new_v4().unwrap();
            socket.set_recv_buffer_size(4096).unwrap();
            let service = socket.connect(to).await.unwrap();
            let (mut cr, mut cw) = client.into_split();
            let (mut sr, mut sw) = service.into_split();
            tokio::spawn(async move {
                let mut buf = vec![0u8; 16384];
                while let Ok(n) = cr.read(&mut buf).await {
                    if n == 0 || sw.write_all(&buf[..n]).await.is_err() {
                        break;
                    }
                }
            });
            let stalled = Arc::clone(&stalled);
            tokio::spawn(async move {
                let mut buf = vec![0u8; 4096];
                loop {
                    if stalled.load(Ordering::Relaxed) {
                        // Hold the connection, read nothing more.
                        tokio::time::sleep(Duration::from_secs(3600)).await;
                    }
                    match tokio::time::timeout(Duration::from_millis(50), sr.read(&mut buf)).await {
                        Ok(Ok(0)) | Ok(Err(_)) => break,
                        Ok(Ok(n)) => {
                            if cw.write_all(&buf[..n]).await.is_err() {
                                break;
                            }
                        }
                        Err(_) => {}
                    }
                }
            });
        }
    });
    addr
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_zenoh_subscriber_does_not_starve_the_others() {
    let mut cfg = test_config();
    let endpoint = listen_zenoh(&mut cfg);
    let server = start(cfg).await;
    let service_addr: SocketAddr = endpoint.trim_start_matches("tcp/").parse().unwrap();
    let key = "uavnav/v1/vehicle/*/pose";

    let healthy = zenoh_peer(&endpoint).await;
    let got = Arc::new(AtomicU64::new(0));
    let counter = Arc::clone(&got);
    // The longest silence between two poses at the healthy subscriber, and when it had them all.
    let gap = Arc::new(std::sync::Mutex::new((
        std::time::Instant::now(),
        Duration::ZERO,
    )));
    let gaps = Arc::clone(&gap);
    let _h = healthy
        .declare_subscriber(key)
        .callback(move |_| {
            counter.fetch_add(1, Ordering::Relaxed);
            let mut g = gaps.lock().unwrap();
            let now = std::time::Instant::now();
            g.1 = g.1.max(now - g.0);
            g.0 = now;
        })
        .await
        .unwrap();
    let stalled = Arc::new(AtomicBool::new(false));
    let via = relay(service_addr, Arc::clone(&stalled)).await;
    let slow = zenoh_peer(&format!("tcp/{via}")).await;
    let slow_got = Arc::new(AtomicU64::new(0));
    let slow_counter = Arc::clone(&slow_got);
    let _s = slow
        .declare_subscriber(key)
        .callback(move |_| {
            slow_counter.fetch_add(1, Ordering::Relaxed);
        })
        .await
        .unwrap();
    // Both subscriptions reach the service; then the slow one stops reading.
    tokio::time::sleep(Duration::from_millis(800)).await;
    stalled.store(true, Ordering::Relaxed);

    // 100 vehicles x 2000 IMU samples (10 s of flight each), as fast as the service takes them.
    // The stalled link absorbs tens of thousands of poses before Zenoh drops any (the kernel's
    // loopback buffers and Zenoh's queues: about 76,000 on a 6.18 kernel, where 20 vehicles'
    // 40,000 poses all fitted and nothing was dropped), so the burst must be well beyond it.
    let (vehicles, samples, per_batch) = (100usize, 2000i64, 50i64);
    let mut c = client(&server).await;
    let mut envs = Vec::new();
    for k in 0..samples / per_batch {
        for v in 0..vehicles {
            let t0 = 1_000_000_000 + k * per_batch * 5_000_000;
            let batch = (0..per_batch).map(|i| imu(t0 + i * 5_000_000)).collect();
            envs.push(imu_env(&format!("zs-{v}"), k as u64, batch));
        }
    }
    *gap.lock().unwrap() = (std::time::Instant::now(), Duration::ZERO);
    let t0 = std::time::Instant::now();
    let acks = ingest(&mut c, envs).await.unwrap();
    let fed = t0.elapsed();
    assert!(
        acks.iter()
            .all(|a| a.status == pb::IngestStatus::Accepted as i32)
    );
    // Every vehicle's last reorder window (20 ms, 4 samples) stays in the service.
    let want = (vehicles as u64) * (samples as u64 - 4);
    let all = eventually(Duration::from_secs(20), || {
        got.load(Ordering::Relaxed) >= want
    })
    .await;
    let (h, s) = (
        got.load(Ordering::Relaxed),
        slow_got.load(Ordering::Relaxed),
    );
    let (last, longest) = *gap.lock().unwrap();
    eprintln!(
        "healthy subscriber: {h} of {want} poses, the last {:?} after the first input \
         (fed in {fed:?}), longest silence {longest:?}; stalled one: {s}",
        last - t0
    );
    let lagged = server.metrics().zenoh_output_lagged.get();
    assert!(
        all,
        "the healthy subscriber got {h} of {want} poses ({lagged} skipped by the publisher)"
    );
    // With congestion control `Block` the publisher waited on the stalled link until Zenoh gave
    // it up (5 s), and the healthy subscriber got nothing meanwhile.
    assert!(
        longest < Duration::from_secs(1),
        "the healthy subscriber went {longest:?} without a pose"
    );
    assert!(
        s < want,
        "the stalled subscriber got everything: the test stalled nothing"
    );
    // What the stalled link lost is counted (read from Zenoh's statistics once a second).
    let dropped = server.metrics().zenoh_dropped.clone();
    assert!(
        eventually(Duration::from_secs(5), || dropped.get() > 0).await,
        "Zenoh's drops on the stalled link were not counted"
    );
    eprintln!(
        "counted as dropped by Zenoh: {} (the stalled subscriber missed {})",
        dropped.get(),
        want - s
    );
    assert!(
        server
            .metrics()
            .encode()
            .contains("uavnav_zenoh_dropped_total "),
        "not in /metrics"
    );
    server.shutdown().await.unwrap();
}
