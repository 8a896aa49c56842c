//! Issue 20 on gRPC and HTTP, in process on port 0 with certificates made at test time: TLS and
//! mutual TLS, who is calling (certificate name or bearer token), what they may do (fleet alpha
//! against fleet bravo, each with its positive control), the metrics of every refusal, reflection
//! off, and the startup rule (no plaintext off loopback unless insecure).
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::sync::Arc;
use std::time::Duration;

use crate::common::*;
use rustls_pki_types::pem::PemObject;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Endpoint, Identity};
use uavnav_proto::v1 as pb;
use uavnav_proto::v1::uav_nav_client::UavNavClient;
use uavnav_tests::pki::{Pem, Pki};
use uavnav_tests::wire;
use uavnavd::security::{Grant, PrincipalConfig, TlsConfig, Verb, auth::token_digest_hex};

const BRAVO_TOKEN: &str = "bravo-token-5f1c0a7e";
const OPS_TOKEN: &str = "ops-token-99a1";

struct Setup {
    _dir: tempfile::TempDir,
    pki: Pki,
    server: uavnavd::RunningServer,
}

fn principals() -> Vec<PrincipalConfig> {
    let all = vec![
        Verb::Feed,
        Verb::Watch,
        Verb::Configure,
        Verb::Reset,
        Verb::List,
    ];
    vec![
        PrincipalConfig {
            name: "gs-alpha".into(),
            certificate_names: vec!["gs-alpha".into()],
            token_sha256: vec![],
            grants: vec![Grant {
                vehicles: "alpha-".into(),
                verbs: all.clone(),
            }],
        },
        PrincipalConfig {
            name: "gs-bravo".into(),
            certificate_names: vec![],
            token_sha256: vec![token_digest_hex(BRAVO_TOKEN)],
            grants: vec![Grant {
                vehicles: "bravo-".into(),
                verbs: all,
            }],
        },
        PrincipalConfig {
            name: "ops".into(),
            certificate_names: vec![],
            token_sha256: vec![token_digest_hex(OPS_TOKEN)],
            grants: vec![Grant {
                vehicles: String::new(),
                verbs: vec![Verb::Metrics, Verb::List],
            }],
        },
    ]
}

async fn secure_server() -> Setup {
    let dir = tempfile::tempdir().unwrap();
    let pki = Pki::new(dir.path(), "fleet");
    let svc = pki.service("uavnavd");
    let mut c = test_config();
    c.security.tls = Some(TlsConfig {
        certificate: svc.cert,
        private_key: svc.key,
        client_ca: Some(pki.ca.clone()),
        require_client_certificate: false,
        reload_s: 0.2,
    });
    c.security.principals = principals();
    let server = start(c).await;
    Setup {
        _dir: dir,
        pki,
        server,
    }
}

/// A TLS channel trusting `ca`, with an optional client certificate.
async fn tls_channel(
    server: &uavnavd::RunningServer,
    ca: &std::path::Path,
    identity: Option<&Pem>,
) -> Result<Channel, tonic::transport::Error> {
    let mut tls = ClientTlsConfig::new()
        .ca_certificate(Certificate::from_pem(std::fs::read(ca).unwrap()))
        .domain_name("localhost");
    if let Some(p) = identity {
        tls = tls.identity(Identity::from_pem(p.cert_pem(), p.key_pem()));
    }
    Endpoint::from_shared(format!("https://localhost:{}", server.grpc_addr.port()))
        .unwrap()
        .tls_config(tls)?
        .connect_timeout(Duration::from_secs(5))
        .connect()
        .await
}

/// Adds the bearer token (if any) to every call.
type Intercept =
    Box<dyn FnMut(tonic::Request<()>) -> Result<tonic::Request<()>, tonic::Status> + Send>;

type Authed = UavNavClient<tonic::service::interceptor::InterceptedService<Channel, Intercept>>;

/// A client that sends `token` (if any) on every call.
fn with_token(channel: Channel, token: Option<&str>) -> Authed {
    let value: Option<tonic::metadata::MetadataValue<tonic::metadata::Ascii>> =
        token.map(|t| format!("Bearer {t}").parse().unwrap());
    let f: Intercept = Box::new(move |mut r: tonic::Request<()>| {
        if let Some(v) = &value {
            r.metadata_mut().insert("authorization", v.clone());
        }
        Ok(r)
    });
    UavNavClient::with_interceptor(channel, f)
}

/// Sends one envelope on an `Ingest` stream and returns its ack.
async fn feed_one(c: &mut Authed, e: pb::SensorEnvelope) -> Result<pb::IngestAck, tonic::Status> {
    let mut acks = c.ingest(futures::stream::iter(vec![e])).await?.into_inner();
    Ok(acks.message().await?.expect("one ack"))
}

fn status_of(ack: &pb::IngestAck) -> pb::IngestStatus {
    pb::IngestStatus::try_from(ack.status).unwrap()
}

fn refused(
    server: &uavnavd::RunningServer,
    principal: &str,
    reason: &'static str,
    verb: Option<Verb>,
) -> u64 {
    server
        .metrics()
        .security
        .refused_count("grpc", principal, reason, verb)
}

#[tokio::test]
async fn strangers_are_refused_before_anything_is_read() {
    let s = secure_server().await;
    // Plaintext to a TLS port: no gRPC exchange is possible.
    let plain = Endpoint::from_shared(format!("http://127.0.0.1:{}", s.server.grpc_addr.port()))
        .unwrap()
        .connect_timeout(Duration::from_secs(3));
    let plain_call = async {
        let ch = plain.connect().await?;
        UavNavClient::new(ch)
            .list_vehicles(pb::ListVehiclesRequest::default())
            .await
            .map_err(|e| anyhow_like(e.to_string()))?;
        Ok::<_, Box<dyn std::error::Error>>(())
    };
    assert!(plain_call.await.is_err(), "plaintext must not get through");

    // A client that trusts another CA does not trust the service.
    let stranger_dir = tempfile::tempdir().unwrap();
    let stranger = Pki::new(stranger_dir.path(), "stranger");
    let wrong_ca = tls_channel(&s.server, &stranger.ca, None).await;
    let wrong_ca_call = match wrong_ca {
        Err(_) => true,
        Ok(ch) => with_token(ch, None)
            .list_vehicles(pb::ListVehiclesRequest::default())
            .await
            .is_err(),
    };
    assert!(wrong_ca_call, "a client trusting a stranger CA must fail");

    // A certificate of a stranger CA, and an expired one of ours: the handshake fails, counted.
    let mallory = stranger.client("gs-alpha");
    let expired = s.pki.expired_client("gs-alpha");
    for (what, pem) in [("stranger CA", &mallory), ("expired", &expired)] {
        let call = match tls_channel(&s.server, &s.pki.ca, Some(pem)).await {
            Err(_) => true,
            Ok(ch) => with_token(ch, None)
                .list_vehicles(pb::ListVehiclesRequest::default())
                .await
                .is_err(),
        };
        assert!(call, "a client certificate from a {what} must be refused");
    }
    let failures = &s.server.metrics().security.tls_failures;
    assert!(
        failures.get("expired_certificate") >= 1,
        "the expired certificate is counted by reason"
    );
    assert!(failures.get("untrusted_certificate") >= 1);

    // TLS without credentials, or with a wrong token: UNAUTHENTICATED.
    let ch = tls_channel(&s.server, &s.pki.ca, None).await.unwrap();
    let e = with_token(ch.clone(), None)
        .list_vehicles(pb::ListVehiclesRequest::default())
        .await
        .unwrap_err();
    assert_eq!(e.code(), tonic::Code::Unauthenticated, "{e:?}");
    let e = with_token(ch.clone(), Some("guess"))
        .configure_vehicle(pb::ConfigureVehicleRequest {
            vehicle_id: "bravo-1".into(),
            config: Some(wire::vehicle_config(false)),
        })
        .await
        .unwrap_err();
    assert_eq!(e.code(), tonic::Code::Unauthenticated, "{e:?}");
    let e = feed_one(
        &mut with_token(ch, Some("guess")),
        wire::imu_env("bravo-1", 0, vec![wire::imu(1_000_000_000)]),
    )
    .await
    .unwrap_err();
    assert_eq!(e.code(), tonic::Code::Unauthenticated, "{e:?}");
    assert!(
        s.server.registry().get("bravo-1").is_none(),
        "nothing was created"
    );
    assert_eq!(refused(&s.server, "anonymous", "no_credentials", None), 1);
    assert_eq!(refused(&s.server, "anonymous", "bad_token", None), 2);
    s.server.shutdown().await.unwrap();
}

fn anyhow_like(s: String) -> Box<dyn std::error::Error> {
    s.into()
}

#[tokio::test]
async fn fleets_only_reach_their_own_vehicles() {
    let s = secure_server().await;
    let alpha_pem = s.pki.client("gs-alpha");
    // alpha by certificate, bravo by token over TLS without a certificate.
    let mut alpha = with_token(
        tls_channel(&s.server, &s.pki.ca, Some(&alpha_pem))
            .await
            .unwrap(),
        None,
    );
    let mut bravo = with_token(
        tls_channel(&s.server, &s.pki.ca, None).await.unwrap(),
        Some(BRAVO_TOKEN),
    );

    // Positive controls: each feeds and configures its own vehicle.
    let ok = feed_one(
        &mut alpha,
        wire::imu_env("alpha-1", 0, vec![wire::imu(1_000_000_000)]),
    )
    .await
    .unwrap();
    assert_eq!(status_of(&ok), pb::IngestStatus::Accepted, "{ok:?}");
    let created = bravo
        .configure_vehicle(pb::ConfigureVehicleRequest {
            vehicle_id: "bravo-1".into(),
            config: Some(wire::vehicle_config(false)),
        })
        .await
        .unwrap();
    assert!(created.get_ref().created);

    // alpha feeding bravo's vehicles: PERMISSION_DENIED acks, and a vehicle never created.
    for e in [
        wire::imu_env("bravo-2", 1, vec![wire::imu(1_000_000_000)]),
        wire::gnss_env("bravo-1", 2, wire::fix(1_000_000_000)),
        wire::config_env("bravo-3", 3, false),
    ] {
        let ack = feed_one(&mut alpha, e).await.unwrap();
        assert_eq!(
            status_of(&ack),
            pb::IngestStatus::PermissionDenied,
            "{ack:?}"
        );
        assert!(ack.reason.contains("gs-alpha"), "{}", ack.reason);
    }
    assert!(s.server.registry().get("bravo-2").is_none());
    assert!(s.server.registry().get("bravo-3").is_none());

    // Configure, reset, get, watch bravo's: PERMISSION_DENIED; watch all: PERMISSION_DENIED.
    let denied = |r: Result<(), tonic::Status>| {
        let e = r.unwrap_err();
        assert_eq!(e.code(), tonic::Code::PermissionDenied, "{e:?}");
    };
    denied(
        alpha
            .configure_vehicle(pb::ConfigureVehicleRequest {
                vehicle_id: "bravo-1".into(),
                config: Some(wire::vehicle_config(false)),
            })
            .await
            .map(|_| ()),
    );
    denied(
        alpha
            .reset_vehicle(pb::ResetVehicleRequest {
                vehicle_id: "bravo-1".into(),
            })
            .await
            .map(|_| ()),
    );
    denied(
        alpha
            .get_pose(pb::GetPoseRequest {
                vehicle_id: "bravo-1".into(),
            })
            .await
            .map(|_| ()),
    );
    for req in [
        pb::WatchRequest {
            all: true,
            ..Default::default()
        },
        pb::WatchRequest {
            id_prefix: "b".into(),
            ..Default::default()
        },
        pb::WatchRequest {
            vehicle_ids: vec!["alpha-1".into(), "bravo-1".into()],
            ..Default::default()
        },
    ] {
        denied(alpha.watch_poses(req.clone()).await.map(|_| ()));
        denied(alpha.watch_health(req).await.map(|_| ()));
    }
    // Its own: allowed.
    alpha
        .watch_poses(pb::WatchRequest {
            id_prefix: "alpha-".into(),
            ..Default::default()
        })
        .await
        .unwrap();
    alpha
        .reset_vehicle(pb::ResetVehicleRequest {
            vehicle_id: "alpha-1".into(),
        })
        .await
        .unwrap();

    // Listing shows only the caller's vehicles.
    let ids = |r: pb::ListVehiclesResponse| -> Vec<String> {
        r.vehicles.into_iter().map(|v| v.vehicle_id).collect()
    };
    let a = ids(alpha
        .list_vehicles(pb::ListVehiclesRequest::default())
        .await
        .unwrap()
        .into_inner());
    let b = ids(bravo
        .list_vehicles(pb::ListVehiclesRequest::default())
        .await
        .unwrap()
        .into_inner());
    assert_eq!(a, vec!["alpha-1".to_string()]);
    assert_eq!(b, vec!["bravo-1".to_string()]);

    // Counted by principal, reason and verb.
    let m = |verb| refused(&s.server, "gs-alpha", "permission_denied", Some(verb));
    assert_eq!(m(Verb::Feed), 2);
    assert_eq!(
        m(Verb::Configure),
        2,
        "the stream's config and ConfigureVehicle"
    );
    assert_eq!(m(Verb::Reset), 1);
    assert_eq!(m(Verb::Watch), 7, "GetPose and six watches");
    s.server.shutdown().await.unwrap();
}

/// One HTTP/1.1 GET over TLS; returns the status line and body.
async fn https_get(
    server: &uavnavd::RunningServer,
    ca: &std::path::Path,
    path: &str,
    token: Option<&str>,
) -> String {
    let mut roots = rustls::RootCertStore::empty();
    for c in rustls_pki_types::CertificateDer::pem_file_iter(ca).unwrap() {
        roots.add(c.unwrap()).unwrap();
    }
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let config = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .unwrap()
        .with_root_certificates(roots)
        .with_no_client_auth();
    let connector = tokio_rustls::TlsConnector::from(Arc::new(config));
    let tcp = tokio::net::TcpStream::connect(server.http_addr)
        .await
        .unwrap();
    let name = rustls_pki_types::ServerName::try_from("localhost").unwrap();
    let mut tls = connector.connect(name, tcp).await.unwrap();
    let auth = token
        .map(|t| format!("Authorization: Bearer {t}\r\n"))
        .unwrap_or_default();
    tls.write_all(
        format!("GET {path} HTTP/1.1\r\nHost: localhost\r\n{auth}Connection: close\r\n\r\n")
            .as_bytes(),
    )
    .await
    .unwrap();
    let mut out = String::new();
    tls.read_to_string(&mut out).await.ok();
    out
}

#[tokio::test]
async fn http_is_tls_and_metrics_need_a_grant() {
    let s = secure_server().await;
    let ca = s.pki.ca.clone();
    let live = https_get(&s.server, &ca, "/livez", None).await;
    assert!(live.starts_with("HTTP/1.1 200"), "{live}");
    let anon = https_get(&s.server, &ca, "/metrics", None).await;
    assert!(anon.starts_with("HTTP/1.1 401"), "{anon}");
    let bravo = https_get(&s.server, &ca, "/metrics", Some(BRAVO_TOKEN)).await;
    assert!(bravo.starts_with("HTTP/1.1 403"), "{bravo}");
    let ops = https_get(&s.server, &ca, "/metrics", Some(OPS_TOKEN)).await;
    assert!(ops.starts_with("HTTP/1.1 200"), "{ops}");
    assert!(
        ops.contains("uavnav_auth_refused_total{transport=\"http\",principal=\"gs-bravo\",reason=\"permission_denied\",verb=\"metrics\"} 1"),
        "{ops}"
    );
    // Plain HTTP to the TLS port gets nothing.
    let mut tcp = tokio::net::TcpStream::connect(s.server.http_addr)
        .await
        .unwrap();
    tcp.write_all(b"GET /livez HTTP/1.1\r\nHost: x\r\n\r\n")
        .await
        .unwrap();
    let mut buf = Vec::new();
    let _ = tokio::time::timeout(Duration::from_secs(3), tcp.read_to_end(&mut buf)).await;
    assert!(
        !String::from_utf8_lossy(&buf).contains("ok"),
        "no plaintext answer"
    );
    s.server.shutdown().await.unwrap();
}

#[tokio::test]
async fn certificates_are_reloaded_without_a_restart() {
    let s = secure_server().await;
    let alpha_pem = s.pki.client("gs-alpha");
    let ch = tls_channel(&s.server, &s.pki.ca, Some(&alpha_pem))
        .await
        .unwrap();
    with_token(ch, None)
        .list_vehicles(pb::ListVehiclesRequest::default())
        .await
        .unwrap();
    // A new CA and service certificate written over the files in use: once reloaded, clients
    // of the new CA get in and clients of the old one no longer do.
    let dir2 = tempfile::tempdir().unwrap();
    let pki2 = Pki::new(dir2.path(), "rotated");
    let svc2 = pki2.service("uavnavd");
    let tls = uavnavd::security::TlsConfig {
        certificate: s._dir.path().join("uavnavd.pem"),
        private_key: s._dir.path().join("uavnavd.key"),
        client_ca: Some(s.pki.ca.clone()),
        require_client_certificate: false,
        reload_s: 0.2,
    };
    // Let the modification time move on (coarse file-system clocks).
    tokio::time::sleep(Duration::from_millis(20)).await;
    std::fs::copy(&svc2.cert, &tls.certificate).unwrap();
    std::fs::copy(&svc2.key, &tls.private_key).unwrap();
    let old_trust = async || -> bool {
        match tls_channel(&s.server, &s.pki.ca, Some(&alpha_pem)).await {
            Err(_) => false,
            Ok(ch) => with_token(ch, None)
                .list_vehicles(pb::ListVehiclesRequest::default())
                .await
                .is_ok(),
        }
    };
    let mut switched = false;
    for _ in 0..50 {
        if !old_trust().await {
            switched = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(switched, "the new service certificate is in use within 5 s");
    let ch = tls_channel(&s.server, &pki2.ca, Some(&alpha_pem))
        .await
        .unwrap();
    with_token(ch, None)
        .list_vehicles(pb::ListVehiclesRequest::default())
        .await
        .unwrap();
    s.server.shutdown().await.unwrap();
}

#[tokio::test]
async fn reflection_is_off_unless_asked_for_and_health_stays_open() {
    let s = secure_server().await;
    let ch = tls_channel(&s.server, &s.pki.ca, None).await.unwrap();
    let mut health = tonic_health::pb::health_client::HealthClient::new(ch.clone());
    let r = health
        .check(tonic_health::pb::HealthCheckRequest::default())
        .await
        .unwrap();
    assert_eq!(r.get_ref().status, 1, "SERVING, without credentials");
    let mut reflection =
        tonic_reflection::pb::v1::server_reflection_client::ServerReflectionClient::new(ch);
    let req = tonic_reflection::pb::v1::ServerReflectionRequest {
        host: String::new(),
        message_request: Some(
            tonic_reflection::pb::v1::server_reflection_request::MessageRequest::ListServices(
                String::new(),
            ),
        ),
    };
    let e = reflection
        .server_reflection_info(futures::stream::iter(vec![req]))
        .await
        .unwrap_err();
    assert_eq!(e.code(), tonic::Code::Unimplemented, "{e:?}");
    s.server.shutdown().await.unwrap();
}

#[tokio::test]
async fn plaintext_off_loopback_is_refused_at_startup() {
    let mut c = test_config();
    c.grpc.addr = "0.0.0.0:0".parse().unwrap();
    let e = uavnavd::Server::start(c.clone()).await.unwrap_err();
    assert!(format!("{e:#}").contains("grpc.addr 0.0.0.0:0"), "{e:#}");
    c.security.insecure = true;
    let server = uavnavd::Server::start(c).await.unwrap();
    server.shutdown().await.unwrap();
}
