//! An in-process `uavnavd` for client and CLI tests: gRPC and HTTP on port 0, Zenoh listening on
//! a free localhost port with multicast scouting off (so parallel tests never meet), health every
//! 200 ms.

use crate::net::free_port;

/// A running service and the client URLs that reach it.
#[derive(Debug)]
pub struct Svc {
    /// The service (dropping it stops nothing: call its shutdown to drain).
    pub server: uavnavd::RunningServer,
    /// `grpc://127.0.0.1:PORT`.
    pub grpc: String,
    /// `zenoh/tcp/127.0.0.1:PORT`.
    pub zenoh: String,
}

/// Starts the service with its real engine and the defaults, on loopback.
pub async fn start() -> Svc {
    let mut c = uavnavd::Config::default();
    c.grpc.addr = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
    c.http.addr = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
    let port = free_port();
    c.zenoh.listen = vec![format!("tcp/127.0.0.1:{port}")];
    c.zenoh.multicast_scouting = false;
    c.health.period_ms = 200;
    let server = uavnavd::Server::start(c)
        .await
        .unwrap_or_else(|e| panic!("in-process uavnavd did not start: {e:#}"));
    let grpc = format!("grpc://{}", server.grpc_addr);
    Svc {
        server,
        grpc,
        zenoh: format!("zenoh/tcp/127.0.0.1:{port}"),
    }
}

/// The text of the shipped smoke scenario (`scenarios/smoke.toml`).
pub fn smoke_text() -> String {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/smoke.toml");
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}
