//! A small `uavnav.v1.UavNav` service over TLS for the client's security tests, standing in for
//! a uavnavd with `[security]` (the server side lands separately): it authenticates a bearer
//! token in an interceptor (`Unauthenticated` otherwise), records every request's
//! `authorization` header and client-certificate count, and grants the fleet `alpha-` only
//! (`PermissionDenied` and `PERMISSION_DENIED` acks for other vehicles), like the service's
//! contract.
#![allow(dead_code)] // each test uses a different part

use std::path::Path;
use std::pin::Pin;
use std::sync::{Arc, Mutex};

use futures::{Stream, StreamExt};
use tonic::transport::server::TcpIncoming;
use tonic::transport::{Certificate, Identity, Server, ServerTlsConfig};
use tonic::{Request, Response, Status, Streaming};
use uavnav_client::pb;
use uavnav_client::pb::uav_nav_server::{UavNav, UavNavServer};

type BoxStream<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send>>;

/// One request as the service saw it: its `authorization` header and the number of client
/// certificates presented.
pub type SeenRequest = (Option<String>, usize);

/// What the service saw of each request.
#[derive(Debug, Clone, Default)]
pub struct Seen {
    /// Every request, in order.
    pub requests: Arc<Mutex<Vec<SeenRequest>>>,
}

impl Seen {
    pub fn requests(&self) -> Vec<SeenRequest> {
        self.requests.lock().unwrap().clone()
    }
}

/// The fleet the caller may use.
const FLEET: &str = "alpha-";

fn granted(id: &str) -> Result<(), Status> {
    if id.starts_with(FLEET) {
        Ok(())
    } else {
        Err(Status::permission_denied(format!(
            "gs-alpha has no grant on vehicle '{id}'"
        )))
    }
}

struct Fake;

fn pose(id: &str, t_ns: i64) -> pb::PoseEstimate {
    pb::PoseEstimate {
        vehicle_id: id.to_string(),
        t_ns,
        ..Default::default()
    }
}

#[tonic::async_trait]
impl UavNav for Fake {
    type IngestStream = BoxStream<pb::IngestAck>;
    type WatchPosesStream = BoxStream<pb::PoseEstimate>;
    type WatchHealthStream = BoxStream<pb::VehicleHealth>;

    async fn ingest(
        &self,
        request: Request<Streaming<pb::SensorEnvelope>>,
    ) -> Result<Response<Self::IngestStream>, Status> {
        let acks = request.into_inner().map(|env| {
            let env = env?;
            let (status, reason) = match granted(&env.vehicle_id) {
                Ok(()) => (pb::IngestStatus::Accepted, String::new()),
                Err(s) => (pb::IngestStatus::PermissionDenied, s.message().to_string()),
            };
            Ok(pb::IngestAck {
                sequence: env.sequence,
                vehicle_id: env.vehicle_id,
                status: status as i32,
                reason,
                needs_config: false,
                // One ack per envelope, as a service does for a stream that asks for no runs.
                covers: 0,
            })
        });
        Ok(Response::new(Box::pin(acks)))
    }

    async fn watch_poses(
        &self,
        request: Request<pb::WatchRequest>,
    ) -> Result<Response<Self::WatchPosesStream>, Status> {
        let req = request.into_inner();
        if req.all {
            return Err(Status::permission_denied(
                "a fleet-limited principal cannot watch all vehicles",
            ));
        }
        for id in &req.vehicle_ids {
            granted(id)?;
        }
        let id = req.vehicle_ids.first().cloned().unwrap_or_default();
        let poses = (1..=3).map(move |k| Ok(pose(&id, k * 1_000_000)));
        Ok(Response::new(Box::pin(
            futures::stream::iter(poses).chain(futures::stream::pending()),
        )))
    }

    async fn watch_health(
        &self,
        _request: Request<pb::WatchRequest>,
    ) -> Result<Response<Self::WatchHealthStream>, Status> {
        Err(Status::unimplemented("not in this fake"))
    }

    async fn get_pose(
        &self,
        request: Request<pb::GetPoseRequest>,
    ) -> Result<Response<pb::PoseEstimate>, Status> {
        let id = request.into_inner().vehicle_id;
        granted(&id)?;
        Ok(Response::new(pose(&id, 42)))
    }

    async fn list_vehicles(
        &self,
        _request: Request<pb::ListVehiclesRequest>,
    ) -> Result<Response<pb::ListVehiclesResponse>, Status> {
        Ok(Response::new(pb::ListVehiclesResponse {
            vehicles: vec![pb::VehicleSummary {
                vehicle_id: "alpha-1".into(),
                configured: true,
                ..Default::default()
            }],
        }))
    }

    async fn configure_vehicle(
        &self,
        request: Request<pb::ConfigureVehicleRequest>,
    ) -> Result<Response<pb::ConfigureVehicleResponse>, Status> {
        granted(&request.into_inner().vehicle_id)?;
        Ok(Response::new(pb::ConfigureVehicleResponse {
            created: true,
        }))
    }

    async fn reset_vehicle(
        &self,
        request: Request<pb::ResetVehicleRequest>,
    ) -> Result<Response<pb::ResetVehicleResponse>, Status> {
        granted(&request.into_inner().vehicle_id)?;
        Ok(Response::new(pb::ResetVehicleResponse {}))
    }
}

/// Serves on 127.0.0.1 (port returned) with `DIR/SERVICE.pem`/`.key`, trusting client
/// certificates from `DIR/ca.pem` (required or optional), accepting only `token`.
pub async fn serve(
    dir: &Path,
    service: &str,
    require_client_cert: bool,
    token: &str,
) -> (u16, Seen) {
    let read = |f: String| std::fs::read(dir.join(f)).unwrap();
    let tls = ServerTlsConfig::new()
        .identity(Identity::from_pem(
            read(format!("{service}.pem")),
            read(format!("{service}.key")),
        ))
        .client_ca_root(Certificate::from_pem(read("ca.pem".into())))
        .client_auth_optional(!require_client_cert);
    let incoming = TcpIncoming::bind("127.0.0.1:0".parse().unwrap()).unwrap();
    let port = incoming.local_addr().unwrap().port();
    let seen = Seen::default();
    let record = seen.clone();
    let expected = format!("Bearer {token}");
    let check = move |req: Request<()>| {
        let header = req
            .metadata()
            .get("authorization")
            .and_then(|v| v.to_str().ok())
            .map(String::from);
        let certs = req.peer_certs().map_or(0, |c| c.len());
        record
            .requests
            .lock()
            .unwrap()
            .push((header.clone(), certs));
        if header.as_deref() == Some(expected.as_str()) {
            Ok(req)
        } else {
            Err(Status::unauthenticated("unknown or missing bearer token"))
        }
    };
    let server = Server::builder()
        .tls_config(tls)
        .unwrap()
        .add_service(UavNavServer::with_interceptor(Fake, check))
        .serve_with_incoming(incoming);
    tokio::spawn(server);
    (port, seen)
}
