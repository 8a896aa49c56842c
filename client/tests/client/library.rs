//! The client library against an in-process `uavnavd`: the same API over gRPC and Zenoh.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::Duration;

use crate::common::*;
use uavnav_client::{Client, ClientError, ConnectOptions, Endpoint, Selector, pb};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn library_same_api_over_grpc_and_zenoh() {
    let svc = start().await;
    let opts = ConnectOptions::default();
    let g = Client::connect(&svc.grpc.parse().unwrap(), opts.clone())
        .await
        .unwrap();
    let z = Client::connect(&svc.zenoh.parse().unwrap(), opts.clone())
        .await
        .unwrap();
    let (config, msgs) = flight(6.0);

    // Watch over both transports, feed over gRPC (vehicle a) and Zenoh (vehicle b).
    let mut wg = g
        .watch_poses(Selector::ids(["lib-a", "lib-b"]))
        .await
        .unwrap();
    let mut wz = z
        .watch_poses(Selector::prefix("lib-").with_decimation(10))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(g.configure("lib-a", &config).await.unwrap(), Some(true));
    assert_eq!(g.configure("lib-a", &config).await.unwrap(), Some(false));
    assert_eq!(z.configure("lib-b", &config).await.unwrap(), None);
    feed(&g, "lib-a", &msgs).await;
    feed(&z, "lib-b", &msgs).await;

    // lib-a was fed first (as fast as accepted): read until lib-b's poses show up too.
    let mut pg = collect(&mut wg, 200, Duration::from_secs(15)).await;
    let _ = tokio::time::timeout(Duration::from_secs(15), async {
        while !pg.iter().any(|p| p.vehicle_id == "lib-b") {
            match wg.next().await {
                Some(Ok(p)) => pg.push(p),
                _ => break,
            }
        }
    })
    .await;
    let pz = collect(&mut wz, 20, Duration::from_secs(15)).await;
    assert!(pg.len() >= 200, "gRPC watch got {} poses", pg.len());
    assert!(pz.len() >= 20, "Zenoh watch got {} poses", pz.len());
    for id in ["lib-a", "lib-b"] {
        let list = g.list_vehicles("").await.unwrap();
        assert!(
            pg.iter().any(|p| p.vehicle_id == id),
            "no gRPC pose of {id} ({} poses; vehicles {list:?})",
            pg.len()
        );
    }
    // Decimation 10 over Zenoh: consecutive poses of one vehicle are 10 IMU samples (50 ms) apart.
    let za: Vec<i64> = pz
        .iter()
        .filter(|p| p.vehicle_id == pz[0].vehicle_id)
        .map(|p| p.t_ns)
        .collect();
    assert!(za.windows(2).all(|w| w[1] - w[0] == 50_000_000), "{za:?}");

    // List and latest pose agree across transports.
    tokio::time::sleep(Duration::from_millis(500)).await;
    let lg = g.list_vehicles("lib-").await.unwrap();
    let lz = z.list_vehicles("lib-").await.unwrap();
    let ids = |l: &[pb::VehicleSummary]| l.iter().map(|v| v.vehicle_id.clone()).collect::<Vec<_>>();
    assert_eq!(ids(&lg), vec!["lib-a", "lib-b"]);
    assert_eq!(ids(&lg), ids(&lz));
    let a_g = g.get_pose("lib-a").await.unwrap();
    let a_z = z.get_pose("lib-a").await.unwrap();
    assert_eq!(a_g.t_ns, a_z.t_ns);
    assert!(matches!(
        g.get_pose("nobody").await,
        Err(ClientError::NotFound(_))
    ));
    assert!(matches!(
        z.get_pose("nobody").await,
        Err(ClientError::NotFound(_))
    ));
    assert!(matches!(
        g.get_pose("bad id!").await,
        Err(ClientError::InvalidId { .. })
    ));

    // Reset: gRPC only.
    g.reset("lib-a").await.unwrap();
    assert!(matches!(
        z.reset("lib-a").await,
        Err(ClientError::Unsupported { .. })
    ));
    assert!(matches!(
        g.reset("nobody").await,
        Err(ClientError::NotFound(_))
    ));

    // Health over both.
    let mut hg = g.watch_health(Selector::all()).await.unwrap();
    let mut hz = z.watch_health(Selector::ids(["lib-b"])).await.unwrap();
    let h1 = tokio::time::timeout(Duration::from_secs(5), hg.next())
        .await
        .unwrap()
        .unwrap()
        .unwrap();
    let h2 = tokio::time::timeout(Duration::from_secs(5), hz.next())
        .await
        .unwrap()
        .unwrap()
        .unwrap();
    assert!(h1.vehicle_id.starts_with("lib-"));
    assert_eq!(h2.vehicle_id, "lib-b");

    // Errors name what failed.
    let e = Client::connect(
        &"grpc://127.0.0.1:1".parse().unwrap(),
        ConnectOptions {
            connect_timeout: Duration::from_millis(500),
            ..opts
        },
    )
    .await
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("cannot connect to grpc://127.0.0.1:1"),
        "{e}"
    );
    let e = "grpc://nohost".parse::<Endpoint>().unwrap_err();
    assert!(e.to_string().contains("missing :PORT"), "{e}");
    g.close().await;
    z.close().await;
    svc.server.shutdown().await.unwrap();
}
