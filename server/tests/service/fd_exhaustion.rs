//! Out of file descriptors (issue row 6: the accept loop spun on the error, 0.95 core): the
//! listener backs off and counts, and serves again once descriptors are free. In its own process
//! (`own_process`), because it lowers the whole process's open-file limit.

use std::time::Duration;

use rustix::process::{Resource, getrlimit, setrlimit};
use uavnav_tests::net::eventually;
use uavnav_tests::service::loopback_config;
use uavnavd::Server;
use uavnavd::conn::ListenerKind;

fn open_fds() -> u64 {
    std::fs::read_dir("/proc/self/fd").unwrap().count() as u64
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn accept_errors_back_off_instead_of_spinning() {
    if crate::own_process::ran_in_own_process(
        "fd_exhaustion::accept_errors_back_off_instead_of_spinning",
    ) {
        return;
    }
    if !std::path::Path::new("/proc/self/fd").exists() {
        eprintln!("skipping: no /proc/self/fd on this system");
        return;
    }
    let mut c = loopback_config();
    c.grpc.max_connections = 64;
    c.http.max_connections = 8;
    let server = Server::start(c).await.unwrap();
    let m = server.metrics().connections.clone();
    let saved = getrlimit(Resource::Nofile);
    // The client sockets exist first; then not one descriptor is left, and their connections
    // complete in the kernel's accept queue with nothing for the service to accept them with.
    let sockets: Vec<_> = (0..6)
        .map(|_| tokio::net::TcpSocket::new_v4().unwrap())
        .collect();
    setrlimit(
        Resource::Nofile,
        rustix::process::Rlimit {
            current: Some(open_fds()),
            maximum: saved.maximum,
        },
    )
    .unwrap();
    let mut clients = Vec::new();
    for s in sockets {
        clients.push(s.connect(server.grpc_addr).await.unwrap());
    }
    let errors = || m.refused_count(ListenerKind::Grpc, "accept_error");
    assert!(
        eventually(Duration::from_secs(5), || errors() > 0).await,
        "no accept error with {} clients",
        clients.len()
    );
    let before = errors();
    tokio::time::sleep(Duration::from_secs(1)).await;
    let per_second = errors() - before;
    // Restore before asserting, so a failure leaves the process usable.
    setrlimit(Resource::Nofile, saved).unwrap();
    // 100 ms back-off: about 10 a second (a spinning loop fails thousands of times).
    assert!(per_second <= 15, "{per_second} accept errors in 1 s");
    // Descriptors free again: the queued connections are taken and a new client is served.
    drop(clients);
    let mut client = uavnav_proto::v1::uav_nav_client::UavNavClient::connect(format!(
        "http://{}",
        server.grpc_addr
    ))
    .await
    .unwrap();
    client
        .list_vehicles(uavnav_proto::v1::ListVehiclesRequest::default())
        .await
        .unwrap();
    server.shutdown().await.unwrap();
}
