//! Connections (issue row 6: 1,100 idle connections locked new clients out and the accept loop
//! spun; slowloris connections were held forever): the per-listener limit closes the excess at
//! once and counts it while existing clients keep working, silent connections are closed after
//! the idle timeout, a link that dies without a reset is noticed by HTTP/2 keepalive, an HTTP
//! client that dribbles its headers is cut off, and the file-descriptor budget is checked at
//! startup. All in-process on port 0.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use uavnav_proto::v1 as pb;
use uavnav_proto::v1::uav_nav_client::UavNavClient;
use uavnav_tests::net::eventually;
use uavnav_tests::service::loopback_config;
use uavnavd::Server;
use uavnavd::conn::ListenerKind;

/// Whether the peer closes `s` within `within` (EOF or reset), reading whatever it sends.
async fn closed_within(s: &mut TcpStream, within: Duration) -> bool {
    let mut buf = [0u8; 4096];
    let end = tokio::time::Instant::now() + within;
    loop {
        match tokio::time::timeout_at(end, s.read(&mut buf)).await {
            Err(_) => return false,
            Ok(Ok(0)) | Ok(Err(_)) => return true,
            Ok(Ok(_)) => continue,
        }
    }
}

async fn list(addr: SocketAddr) -> Result<pb::ListVehiclesResponse, String> {
    let mut client = UavNavClient::connect(format!("http://{addr}"))
        .await
        .map_err(|e| e.to_string())?;
    client
        .list_vehicles(pb::ListVehiclesRequest::default())
        .await
        .map(|r| r.into_inner())
        .map_err(|e| e.to_string())
}

#[tokio::test]
async fn the_connection_limit_closes_the_excess_at_once_and_counts_it() {
    let mut c = loopback_config();
    c.grpc.max_connections = 4;
    let server = Server::start(c).await.unwrap();
    let m = server.metrics().connections.clone();
    let mut held = Vec::new();
    for _ in 0..4 {
        held.push(TcpStream::connect(server.grpc_addr).await.unwrap());
    }
    assert!(
        eventually(Duration::from_secs(5), || m.open_count(ListenerKind::Grpc)
            == 4)
        .await,
        "open connections: {}",
        m.open_count(ListenerKind::Grpc)
    );
    // The fifth is closed at once, not queued.
    let mut extra = TcpStream::connect(server.grpc_addr).await.unwrap();
    assert!(closed_within(&mut extra, Duration::from_secs(2)).await);
    assert_eq!(m.refused_count(ListenerKind::Grpc, "limit"), 1);
    // A real client is refused too while the limit is held ...
    assert!(list(server.grpc_addr).await.is_err());
    // ... and served once connections are released.
    held.truncate(2);
    assert!(
        eventually(Duration::from_secs(5), || m.open_count(ListenerKind::Grpc)
            == 2)
        .await
    );
    list(server.grpc_addr).await.unwrap();
    // The refusals are in /metrics.
    let text = server.metrics().encode();
    assert!(
        text.contains("uavnav_connections_refused_total{listener=\"grpc\",reason=\"limit\"}"),
        "{text}"
    );
    server.shutdown().await.unwrap();
}

#[tokio::test]
async fn a_silent_connection_is_closed_after_the_idle_timeout() {
    let mut c = loopback_config();
    c.grpc.keepalive_interval_s = 0.0;
    c.grpc.idle_timeout_s = 1.0;
    c.http.idle_timeout_s = 1.0;
    let server = Server::start(c).await.unwrap();
    let m = server.metrics().connections.clone();
    let t0 = Instant::now();
    let mut grpc = TcpStream::connect(server.grpc_addr).await.unwrap();
    let mut http = TcpStream::connect(server.http_addr).await.unwrap();
    assert!(closed_within(&mut grpc, Duration::from_secs(5)).await);
    assert!(closed_within(&mut http, Duration::from_secs(5)).await);
    let waited = t0.elapsed();
    assert!(
        waited >= Duration::from_millis(900),
        "closed after {waited:?}"
    );
    assert_eq!(m.closed_count(ListenerKind::Grpc, "idle_timeout"), 1);
    assert_eq!(m.closed_count(ListenerKind::Http, "idle_timeout"), 1);
    assert!(
        eventually(Duration::from_secs(2), || m.open_count(ListenerKind::Grpc)
            == 0)
        .await
    );
    server.shutdown().await.unwrap();
}

#[tokio::test]
async fn an_idle_client_that_answers_keepalive_pings_stays_connected() {
    let mut c = loopback_config();
    c.grpc.keepalive_interval_s = 0.2;
    c.grpc.keepalive_timeout_s = 0.5;
    c.grpc.idle_timeout_s = 1.0;
    let server = Server::start(c).await.unwrap();
    let m = server.metrics().connections.clone();
    let mut client = UavNavClient::connect(format!("http://{}", server.grpc_addr))
        .await
        .unwrap();
    client
        .list_vehicles(pb::ListVehiclesRequest::default())
        .await
        .unwrap();
    // Three idle timeouts without a call: the pings' answers keep it alive.
    tokio::time::sleep(Duration::from_secs(3)).await;
    assert_eq!(m.closed_count(ListenerKind::Grpc, "idle_timeout"), 0);
    assert_eq!(m.open_count(ListenerKind::Grpc), 1);
    client
        .list_vehicles(pb::ListVehiclesRequest::default())
        .await
        .unwrap();
    server.shutdown().await.unwrap();
}

/// A TCP relay that can go silent in both directions without closing anything: a radio link
/// that died without a reset.
async fn relay(to: SocketAddr, dead: Arc<AtomicBool>) -> SocketAddr {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(async move {
        while let Ok((a, _)) = listener.accept().await {
            let b = TcpStream::connect(to).await.unwrap();
            let (ar, aw) = a.into_split();
            let (br, bw) = b.into_split();
            for (mut r, mut w) in [(ar, bw), (br, aw)] {
                let dead = Arc::clone(&dead);
                tokio::spawn(async move {
                    let mut buf = vec![0u8; 16384];
                    loop {
                        match r.read(&mut buf).await {
                            Ok(0) | Err(_) => break,
                            Ok(n) if !dead.load(Ordering::Relaxed) => {
                                if w.write_all(&buf[..n]).await.is_err() {
                                    break;
                                }
                            }
                            // Swallowed: the bytes never arrive, nothing is closed.
                            Ok(_) => {}
                        }
                    }
                    // Keep the write half (and so the connection) open after a dead link.
                    std::future::pending::<()>().await;
                    drop(w);
                });
            }
        }
    });
    addr
}

#[tokio::test]
async fn keepalive_notices_a_link_that_died_without_a_reset() {
    let mut c = loopback_config();
    c.grpc.keepalive_interval_s = 0.3;
    c.grpc.keepalive_timeout_s = 0.5;
    c.grpc.idle_timeout_s = 30.0;
    let server = Server::start(c).await.unwrap();
    let m = server.metrics().connections.clone();
    let dead = Arc::new(AtomicBool::new(false));
    let via = relay(server.grpc_addr, Arc::clone(&dead)).await;
    let mut client = UavNavClient::connect(format!("http://{via}"))
        .await
        .unwrap();
    client
        .list_vehicles(pb::ListVehiclesRequest::default())
        .await
        .unwrap();
    assert_eq!(m.open_count(ListenerKind::Grpc), 1);
    dead.store(true, Ordering::Relaxed);
    let t0 = Instant::now();
    // Closed by the unanswered ping, long before the 30 s idle timeout.
    assert!(
        eventually(Duration::from_secs(10), || m.open_count(ListenerKind::Grpc)
            == 0)
        .await,
        "the dead link is still open"
    );
    assert!(t0.elapsed() < Duration::from_secs(10));
    assert_eq!(m.closed_count(ListenerKind::Grpc, "idle_timeout"), 0);
    server.shutdown().await.unwrap();
}

#[tokio::test]
async fn an_http_client_dribbling_its_headers_is_cut_off() {
    let mut c = loopback_config();
    c.http.header_timeout_s = 1.0;
    c.http.idle_timeout_s = 30.0;
    let server = Server::start(c).await.unwrap();
    // Positive control: a whole request is answered.
    let mut ok = TcpStream::connect(server.http_addr).await.unwrap();
    ok.write_all(b"GET /livez HTTP/1.1\r\nhost: x\r\n\r\n")
        .await
        .unwrap();
    let mut buf = [0u8; 256];
    let n = ok.read(&mut buf).await.unwrap();
    assert!(buf[..n].starts_with(b"HTTP/1.1 200"), "{:?}", &buf[..n]);
    // Slowloris: one header byte every 100 ms, for ever; each byte defeats the idle timeout.
    let mut slow = TcpStream::connect(server.http_addr).await.unwrap();
    slow.write_all(b"GET /livez HTTP/1.1\r\n").await.unwrap();
    let t0 = Instant::now();
    let mut cut = false;
    while t0.elapsed() < Duration::from_secs(8) {
        if slow.write_all(b"x").await.is_err() {
            cut = true;
            break;
        }
        let mut b = [0u8; 512];
        match tokio::time::timeout(Duration::from_millis(100), slow.read(&mut b)).await {
            Ok(Ok(0)) | Ok(Err(_)) => {
                cut = true;
                break;
            }
            // A 408 before the close is fine.
            Ok(Ok(_)) | Err(_) => {}
        }
    }
    assert!(cut, "a dribbling client was never cut off");
    assert!(t0.elapsed() < Duration::from_secs(5), "{:?}", t0.elapsed());
    server.shutdown().await.unwrap();
}

#[tokio::test]
async fn the_file_descriptor_budget_is_checked_at_startup() {
    let mut c = loopback_config();
    // Beyond any hard limit the kernel allows (fs.nr_open is at most 2^30).
    c.grpc.max_connections = 1 << 31;
    let err = Server::start(c).await.unwrap_err().to_string();
    assert!(err.contains("file-descriptor budget"), "{err}");
    // The defaults fit this machine (raising the soft limit if needed).
    let server = Server::start(loopback_config()).await.unwrap();
    server.shutdown().await.unwrap();
}
