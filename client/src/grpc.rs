//! The gRPC backend: a tonic `uavnav.v1.UavNav` client on a channel that reconnects on demand,
//! over TLS for `https://` URIs, with the bearer token on every request (see [`crate::security`]).

use std::time::Duration;

use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Channel, Endpoint as TonicEndpoint};

use crate::client::ConnectOptions;
use crate::error::ClientError;
use crate::pb;
use crate::pb::uav_nav_client::UavNavClient;
use crate::security::{self, AuthInterceptor};

/// The generated client on a tonic channel, every request through the token interceptor.
pub type RawClient = UavNavClient<InterceptedService<Channel, AuthInterceptor>>;

/// Largest message accepted or sent, bytes (1080p JPEG frames fit; matches the service default).
pub const MAX_MESSAGE_BYTES: usize = 16 << 20;

/// Connects to `uri` (`http://HOST:PORT`, or `https://HOST:PORT` with `opts.tls`), eagerly so
/// that an unreachable service (or a failed TLS handshake) is reported now. The channel
/// reconnects by itself on later calls after a failure.
pub async fn connect(uri: &str, opts: &ConnectOptions) -> Result<RawClient, ClientError> {
    let connect_timeout = opts.connect_timeout;
    let endpoint = uri
        .replacen("https://", "grpcs://", 1)
        .replacen("http://", "grpc://", 1);
    let err = |reason: String| ClientError::Connect {
        endpoint: endpoint.clone(),
        reason,
    };
    let tls = uri.starts_with("https://");
    security::check_token_transport(uri, tls, opts.token.as_deref(), opts.allow_insecure_token)?;
    let interceptor = AuthInterceptor::new(opts.token.as_deref())?;
    let mut ep = TonicEndpoint::from_shared(uri.to_string())
        .map_err(|e| err(e.to_string()))?
        .connect_timeout(connect_timeout)
        .tcp_nodelay(true)
        .http2_keep_alive_interval(Duration::from_secs(10))
        .keep_alive_while_idle(true);
    match (tls, &opts.tls) {
        (true, Some(t)) => {
            ep = ep
                .tls_config(security::grpc_tls_config(t)?)
                .map_err(|e| err(source_chain(&e)))?;
        }
        (true, None) => {
            return Err(ClientError::Tls {
                reason: format!(
                    "{endpoint} needs TLS options: at least the CA that signed the service certificate"
                ),
            });
        }
        // Refused rather than ignored: the caller expects an encrypted, authenticated link.
        (false, Some(_)) => {
            return Err(ClientError::Tls {
                reason: format!(
                    "TLS options given for the plaintext endpoint {endpoint}: use grpcs://"
                ),
            });
        }
        (false, None) => {}
    }
    let channel = match tokio::time::timeout(connect_timeout, ep.connect()).await {
        Ok(Ok(c)) => c,
        Ok(Err(e)) => return Err(err(source_chain(&e))),
        Err(_) => return Err(err(format!("no connection within {connect_timeout:?}"))),
    };
    if !tls && speaks_tls(ep.uri(), connect_timeout.min(TLS_PROBE_WAIT)).await {
        return Err(ClientError::Tls {
            reason: format!(
                "{endpoint} answers HTTP/2 in clear with a TLS alert: the service speaks TLS, \
                 use {} with the CA that signed its certificate (--tls-ca)",
                endpoint.replacen("grpc://", "grpcs://", 1)
            ),
        });
    }
    Ok(UavNavClient::with_interceptor(channel, interceptor)
        .max_decoding_message_size(MAX_MESSAGE_BYTES)
        .max_encoding_message_size(MAX_MESSAGE_BYTES))
}

/// How long the plaintext probe waits for the server's first bytes.
const TLS_PROBE_WAIT: Duration = Duration::from_secs(1);

/// The HTTP/2 client preface and an empty SETTINGS frame: how a plaintext gRPC client opens.
const H2_PREFACE: &[u8] = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n\0\0\0\x04\0\0\0\0\0";

/// Whether the server at `uri` answers a plaintext HTTP/2 opening the way a TLS server does: with
/// an alert record (content type 21, version 3.x). An HTTP/2 server answers with its SETTINGS
/// frame (first byte 0, the top of a small length).
///
/// Why a probe: tonic connects without waiting for the server's first bytes, and a request on a
/// connection the TLS server then closes fails with a bare "transport error" that looks transient,
/// so a `grpc://` client pointed at a TLS port would retry for its whole backoff. One extra
/// connection at connect time names the cause instead. `false` when unsure (no answer within
/// `wait`, a closed or reset connection): the usual errors then tell what happened.
async fn speaks_tls(uri: &tonic::codegen::http::Uri, wait: Duration) -> bool {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let (Some(host), Some(port)) = (uri.host(), uri.port_u16()) else {
        return false;
    };
    let host = host.trim_start_matches('[').trim_end_matches(']');
    let probe = async {
        let mut s = tokio::net::TcpStream::connect((host, port)).await.ok()?;
        s.write_all(H2_PREFACE).await.ok()?;
        let mut first = [0u8; 2];
        s.read_exact(&mut first).await.ok()?;
        Some(first == [0x15, 0x03])
    };
    matches!(tokio::time::timeout(wait, probe).await, Ok(Some(true)))
}

/// `e` and its causes, joined (tonic's top-level message alone is "transport error").
fn source_chain(e: &dyn std::error::Error) -> String {
    let mut parts = vec![e.to_string()];
    let mut cur = e.source();
    while let Some(s) = cur {
        parts.push(s.to_string());
        cur = s.source();
    }
    parts.join(": ")
}

/// Maps a NOT_FOUND status to [`ClientError::NotFound`], others to [`ClientError::Rpc`].
pub fn map_status(op: &'static str, id: &str, status: tonic::Status) -> ClientError {
    if status.code() == tonic::Code::NotFound {
        ClientError::NotFound(id.to_string())
    } else {
        ClientError::rpc(op, status)
    }
}

/// `ListVehicles`.
pub async fn list(c: &RawClient, prefix: &str) -> Result<Vec<pb::VehicleSummary>, ClientError> {
    let req = pb::ListVehiclesRequest {
        id_prefix: prefix.to_string(),
    };
    let resp = c
        .clone()
        .list_vehicles(req)
        .await
        .map_err(|s| ClientError::rpc("ListVehicles", s))?;
    Ok(resp.into_inner().vehicles)
}

/// `GetPose`.
pub async fn get_pose(c: &RawClient, id: &str) -> Result<pb::PoseEstimate, ClientError> {
    let req = pb::GetPoseRequest {
        vehicle_id: id.to_string(),
    };
    let resp = c
        .clone()
        .get_pose(req)
        .await
        .map_err(|s| map_status("GetPose", id, s))?;
    Ok(resp.into_inner())
}

/// `ConfigureVehicle`: whether the vehicle was created.
pub async fn configure(
    c: &RawClient,
    id: &str,
    config: &pb::VehicleConfig,
) -> Result<bool, ClientError> {
    let req = pb::ConfigureVehicleRequest {
        vehicle_id: id.to_string(),
        config: Some(*config),
    };
    let resp = c
        .clone()
        .configure_vehicle(req)
        .await
        .map_err(|s| ClientError::rpc("ConfigureVehicle", s))?;
    Ok(resp.into_inner().created)
}

/// `ResetVehicle`.
pub async fn reset(c: &RawClient, id: &str) -> Result<(), ClientError> {
    let req = pb::ResetVehicleRequest {
        vehicle_id: id.to_string(),
    };
    c.clone()
        .reset_vehicle(req)
        .await
        .map_err(|s| map_status("ResetVehicle", id, s))?;
    Ok(())
}
