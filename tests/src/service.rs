//! An in-process `uavnavd` for client and CLI tests: gRPC and HTTP on port 0, Zenoh listening on
//! a free localhost port with multicast scouting off (so parallel tests never meet), health every
//! 200 ms; and that loopback configuration for tests that start the service themselves.

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

/// The defaults, on loopback only: gRPC and HTTP on port 0, Zenoh off (and multicast scouting
/// off, for a test that turns Zenoh on), so that parallel tests never collide or meet.
pub fn loopback_config() -> uavnavd::Config {
    let mut c = uavnavd::Config::default();
    c.grpc.addr = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
    c.http.addr = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
    c.zenoh.enabled = false;
    c.zenoh.multicast_scouting = false;
    c
}

/// Turns Zenoh on in `c`, listening on a free loopback port, with instance name `test-PORT` (so
/// that the liveliness tokens of services in parallel tests differ); returns the endpoint,
/// `tcp/127.0.0.1:PORT`.
pub fn listen_zenoh(c: &mut uavnavd::Config) -> String {
    let port = free_port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    c.zenoh.enabled = true;
    c.zenoh.listen = vec![endpoint.clone()];
    c.zenoh.instance = format!("test-{port}");
    endpoint
}

/// Starts the service with its real engine and the defaults, on loopback.
pub async fn start() -> Svc {
    let mut c = loopback_config();
    let endpoint = listen_zenoh(&mut c);
    c.health.period_ms = 200;
    let server = uavnavd::Server::start(c)
        .await
        .unwrap_or_else(|e| panic!("in-process uavnavd did not start: {e:#}"));
    let grpc = format!("grpc://{}", server.grpc_addr);
    Svc {
        server,
        grpc,
        zenoh: format!("zenoh/{endpoint}"),
    }
}

/// The text of the shipped smoke scenario (`scenarios/smoke.toml`).
pub fn smoke_text() -> String {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/smoke.toml");
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}
