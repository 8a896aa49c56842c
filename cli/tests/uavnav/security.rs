//! Issue 20, client side: `uavnav certs` makes a deployment's CA, service and ground-station
//! certificates and tokens; the client library reaches a TLS service with them (gRPC: the token
//! on every request, mutual TLS, refusals as their own errors; Zenoh: `tls/` locators with
//! mutual TLS); the CLI's security options. Certificates are made at test time by the command
//! under test, and checked by rustls (webpki) in real handshakes.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use crate::common;
use crate::tls_fake;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use prost::Message;
use uavnav_client::pb::sensor_envelope::Payload;
use uavnav_client::{Client, ClientError, ConnectOptions, Endpoint, Selector, TlsOptions, pb};

use crate::common::{BIN, run, run_async, stdout};

/// `uavnav certs init` for service `uavnavd` and ground stations gs-alpha and gs-bravo.
fn deployment(dir: &Path, extra: &[&str]) {
    let d = dir.to_str().unwrap();
    let mut args = vec![
        "certs",
        "init",
        "--dir",
        d,
        "--service",
        "uavnavd",
        "--san",
        "uavnavd.fleet.example",
        "--san",
        "10.20.30.40",
        "--client",
        "gs-alpha",
        "--client",
        "gs-bravo",
    ];
    args.extend_from_slice(extra);
    let out = run(&args);
    assert_eq!(out.status.code(), Some(0));
}

fn tls(dir: &Path, client: Option<&str>) -> TlsOptions {
    let t = TlsOptions::with_ca(dir.join("ca.pem"));
    match client {
        Some(c) => t.with_identity(dir.join(format!("{c}.pem")), dir.join(format!("{c}.key"))),
        None => t,
    }
}

fn options(tls: Option<TlsOptions>, token: Option<&str>) -> ConnectOptions {
    ConnectOptions {
        tls,
        token: token.map(String::from),
        connect_timeout: Duration::from_secs(3),
        ..ConnectOptions::default()
    }
}

async fn connect(url: &str, opts: ConnectOptions) -> Result<Client, ClientError> {
    Client::connect(&url.parse::<Endpoint>()?, opts).await
}

fn mode(p: &Path) -> u32 {
    use std::os::unix::fs::PermissionsExt;
    std::fs::metadata(p).unwrap().permissions().mode() & 0o777
}

#[test]
fn certs_init_writes_a_deployment_keys_private_and_never_overwrites() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("pki");
    deployment(&dir, &[]);
    for name in ["ca", "uavnavd", "gs-alpha", "gs-bravo"] {
        let pem = std::fs::read_to_string(dir.join(format!("{name}.pem"))).unwrap();
        assert!(pem.starts_with("-----BEGIN CERTIFICATE-----"), "{name}");
        let key = std::fs::read_to_string(dir.join(format!("{name}.key"))).unwrap();
        assert!(key.contains("PRIVATE KEY-----"), "{name}");
        assert_eq!(mode(&dir.join(format!("{name}.key"))), 0o600, "{name}.key");
    }
    let ca_before = std::fs::read(dir.join("ca.pem")).unwrap();
    // `uavnav certs SUB --dir DIR ARGS…`: its exit code.
    let certs = |sub: &str, args: &[&str]| {
        let mut all = vec!["certs", sub, "--dir", dir.to_str().unwrap()];
        all.extend_from_slice(args);
        let out = run(&all);
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, err) = certs("init", &["--service", "uavnavd"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("refusing to overwrite"), "{err}");
    assert_eq!(std::fs::read(dir.join("ca.pem")).unwrap(), ca_before);
    let (code, _) = certs("issue", &["--client", "gs-alpha"]);
    assert_eq!(code, Some(2), "gs-alpha exists already");
    let (code, _) = certs("init", &["--service", "a/b"]);
    assert_eq!(code, Some(2));
    // --exist-ok (a deployment restarted on its volume): complete = nothing written; a missing
    // client certificate is issued from the CA already there.
    let exist_ok = [
        "--service",
        "uavnavd",
        "--client",
        "gs-alpha",
        "--client",
        "gs-bravo",
    ];
    let (code, _) = certs("init", &[&exist_ok[..], &["--exist-ok"]].concat());
    assert_eq!(code, Some(0));
    std::fs::remove_file(dir.join("gs-bravo.pem")).unwrap();
    std::fs::remove_file(dir.join("gs-bravo.key")).unwrap();
    let alpha = std::fs::read(dir.join("gs-alpha.pem")).unwrap();
    let (code, _) = certs("init", &[&exist_ok[..], &["--exist-ok"]].concat());
    assert_eq!(code, Some(0));
    assert!(dir.join("gs-bravo.pem").exists() && dir.join("gs-bravo.key").exists());
    assert_eq!(mode(&dir.join("gs-bravo.key")), 0o600);
    assert_eq!(std::fs::read(dir.join("gs-alpha.pem")).unwrap(), alpha);
    assert_eq!(std::fs::read(dir.join("ca.pem")).unwrap(), ca_before);
    let (code, _) = certs("init", &["--service", "uavnavd", "--force"]);
    assert_eq!(code, Some(0));
    assert_ne!(std::fs::read(dir.join("ca.pem")).unwrap(), ca_before);
    assert_eq!(mode(&dir.join("uavnavd.key")), 0o600);
}

#[test]
fn certs_token_and_hash_token_agree() {
    let out = run(&["certs", "token", "--name", "gs-alpha"]);
    assert_eq!(out.status.code(), Some(0));
    let token = stdout(&out).trim().to_string();
    assert_eq!(token.len(), 64);
    assert!(token.bytes().all(|b| b.is_ascii_hexdigit()));
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let line = stderr
        .lines()
        .find(|l| l.starts_with("token_sha256 = [\""))
        .expect("config line");
    let from_token = &line["token_sha256 = [\"".len()..line.len() - 2];
    let mut child = Command::new(BIN)
        .args(["certs", "hash-token"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    writeln!(child.stdin.take().unwrap(), "{token}").unwrap();
    let hashed = child.wait_with_output().unwrap();
    assert!(hashed.status.success());
    assert_eq!(stdout(&hashed).trim(), from_token);
    let second = stdout(&run(&["certs", "token", "--name", "gs-alpha"]));
    assert_ne!(second.trim(), token, "tokens are random");
}

/// One gRPC round trip of every kind over TLS with gs-alpha's certificate and token: the token
/// is on every request, the certificate is presented, the fleet's refusals are their own errors.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn grpcs_with_mutual_tls_sends_the_token_everywhere_and_maps_refusals() {
    let tmp = tempfile::tempdir().unwrap();
    deployment(tmp.path(), &[]);
    let (port, seen) = tls_fake::serve(tmp.path(), "uavnavd", true, "t0ken-alpha").await;
    let url = format!("grpcs://127.0.0.1:{port}");
    let client = connect(
        &url,
        options(Some(tls(tmp.path(), Some("gs-alpha"))), Some("t0ken-alpha")),
    )
    .await
    .unwrap();
    let list = client.list_vehicles("").await.unwrap();
    assert_eq!(list[0].vehicle_id, "alpha-1");
    assert_eq!(client.get_pose("alpha-1").await.unwrap().t_ns, 42);
    assert_eq!(
        client
            .configure("alpha-1", &pb::VehicleConfig::default())
            .await
            .unwrap(),
        Some(true)
    );
    client.reset("alpha-1").await.unwrap();
    let mut poses = client
        .watch_poses(Selector::ids(["alpha-1"]))
        .await
        .unwrap();
    for _ in 0..3 {
        assert_eq!(poses.next().await.unwrap().unwrap().vehicle_id, "alpha-1");
    }
    let ingest = client.ingest().await.unwrap();
    let baro = Payload::Baro(pb::BaroSample {
        t_ns: 1,
        pressure_pa: 1e5,
        temperature_degc: None,
    });
    for id in ["alpha-1", "alpha-2", "bravo-1"] {
        ingest.send(id, baro.clone()).await.unwrap();
    }
    let stats = ingest.finish(Duration::from_secs(5)).await;
    assert_eq!(stats.accepted.load(std::sync::atomic::Ordering::Relaxed), 2);
    assert_eq!(stats.statuses().get("PERMISSION_DENIED"), Some(&1));
    assert_eq!(stats.refused(), 1);
    let denied = stats.permission_denied();
    assert_eq!(denied.len(), 1);
    assert!(
        denied.keys().next().unwrap().contains("bravo-1"),
        "{denied:?}"
    );

    // Refusals: their own variants, and not retried (one request each).
    let before = seen.requests().len();
    let t0 = Instant::now();
    let e = client.get_pose("bravo-1").await.unwrap_err();
    assert!(
        matches!(e, ClientError::PermissionDenied { op: "GetPose", .. }),
        "{e}"
    );
    let e = client.watch_poses(Selector::all()).await.unwrap_err();
    assert!(
        matches!(
            e,
            ClientError::PermissionDenied {
                op: "WatchPoses",
                ..
            }
        ),
        "{e}"
    );
    assert!(
        t0.elapsed() < Duration::from_secs(1),
        "a refusal is not retried"
    );
    assert_eq!(seen.requests().len(), before + 2);

    let requests = seen.requests();
    // list, get, configure, reset, watch, ingest, get, watch: every one carried the token and
    // gs-alpha's certificate.
    assert_eq!(requests.len(), 8, "{requests:?}");
    for (header, certs) in &requests {
        assert_eq!(header.as_deref(), Some("Bearer t0ken-alpha"));
        assert_eq!(*certs, 1);
    }
    drop(poses);
    client.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_wrong_token_is_unauthenticated_and_not_retried() {
    let tmp = tempfile::tempdir().unwrap();
    deployment(tmp.path(), &[]);
    let (port, seen) = tls_fake::serve(tmp.path(), "uavnavd", false, "t0ken-alpha").await;
    let url = format!("grpcs://127.0.0.1:{port}");
    let client = connect(
        &url,
        options(Some(tls(tmp.path(), None)), Some("stolen-guess")),
    )
    .await
    .unwrap();
    let e = client.list_vehicles("").await.unwrap_err();
    assert!(
        matches!(
            e,
            ClientError::Unauthenticated {
                op: "ListVehicles",
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("not authenticated"), "{e}");
    // No token at all: refused the same way; no client certificate was presented (optional).
    let anonymous = connect(&url, options(Some(tls(tmp.path(), None)), None))
        .await
        .unwrap();
    let e = anonymous.list_vehicles("").await.unwrap_err();
    assert!(matches!(e, ClientError::Unauthenticated { .. }), "{e}");
    let requests = seen.requests();
    assert_eq!(requests.len(), 2, "{requests:?}");
    assert_eq!(requests[0], (Some("Bearer stolen-guess".into()), 0));
    assert_eq!(requests[1], (None, 0));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_service_from_another_ca_or_expired_is_refused_at_connect() {
    let tmp = tempfile::tempdir().unwrap();
    let (ours, theirs, stale) = (
        tmp.path().join("ours"),
        tmp.path().join("theirs"),
        tmp.path().join("stale"),
    );
    deployment(&ours, &[]);
    deployment(&theirs, &[]);
    deployment(&stale, &["--expired"]);
    for (dir, expect) in [(&theirs, "unknownissuer"), (&stale, "expired")] {
        let (port, seen) = tls_fake::serve(dir, "uavnavd", false, "t").await;
        let url = format!("grpcs://127.0.0.1:{port}");
        let e = connect(&url, options(Some(tls(&ours, Some("gs-alpha"))), Some("t")))
            .await
            .unwrap_err();
        assert!(matches!(e, ClientError::Connect { .. }), "{e}");
        let msg = e.to_string().to_lowercase();
        assert!(msg.contains("certificate") && msg.contains(expect), "{msg}");
        assert!(
            seen.requests().is_empty(),
            "no request reached the impostor"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_issued_certificate_chains_to_the_ca_on_disk() {
    let tmp = tempfile::tempdir().unwrap();
    deployment(tmp.path(), &[]);
    let d = tmp.path().to_str().unwrap().to_string();
    let out = run_async(
        ["certs", "issue", "--dir", &d, "--client", "gs-charlie"]
            .map(String::from)
            .to_vec(),
    )
    .await;
    assert_eq!(out.status.code(), Some(0));
    assert_eq!(mode(&tmp.path().join("gs-charlie.key")), 0o600);
    let out = run_async(
        [
            "certs",
            "issue",
            "--dir",
            &d,
            "--service",
            "uavnavd-2",
            "--san",
            "127.0.0.2",
        ]
        .map(String::from)
        .to_vec(),
    )
    .await;
    assert_eq!(out.status.code(), Some(0));
    // The issued service certificate serves, the issued client certificate is accepted where
    // client certificates are required.
    let (port, seen) = tls_fake::serve(tmp.path(), "uavnavd-2", true, "t").await;
    let client = connect(
        &format!("grpcs://127.0.0.1:{port}"),
        options(Some(tls(tmp.path(), Some("gs-charlie"))), Some("t")),
    )
    .await
    .unwrap();
    client.list_vehicles("").await.unwrap();
    assert_eq!(seen.requests(), vec![(Some("Bearer t".into()), 1)]);
}

#[tokio::test]
async fn misconfigurations_are_refused_before_any_traffic() {
    let tmp = tempfile::tempdir().unwrap();
    deployment(tmp.path(), &[]);
    let e = connect("grpcs://127.0.0.1:1", options(None, None))
        .await
        .unwrap_err();
    assert!(matches!(e, ClientError::Tls { .. }), "{e}");
    let e = connect(
        "grpc://127.0.0.1:1",
        options(Some(tls(tmp.path(), None)), None),
    )
    .await
    .unwrap_err();
    assert!(
        matches!(e, ClientError::Tls { .. }) && e.to_string().contains("grpcs://"),
        "{e}"
    );
    // 192.0.2.0/24 is TEST-NET-1: the refusal comes before any connection attempt.
    let e = connect("grpc://192.0.2.1:50051", options(None, Some("s3cret")))
        .await
        .unwrap_err();
    assert!(matches!(e, ClientError::InsecureToken { .. }), "{e}");
    let mut half = tls(tmp.path(), None);
    half.cert_pem = Some(tmp.path().join("gs-alpha.pem"));
    let e = connect("grpcs://127.0.0.1:1", options(Some(half), None))
        .await
        .unwrap_err();
    assert!(e.to_string().contains("without its key"), "{e}");
    let e = connect("zenoh/tls/127.0.0.1:1", options(None, None))
        .await
        .unwrap_err();
    assert!(matches!(e, ClientError::Tls { .. }), "{e}");
    let secret = format!("{:?}", options(None, Some("s3cret")));
    assert!(!secret.contains("s3cret"), "{secret}");
}

fn write_token(dir: &Path, token: &str) -> PathBuf {
    let p = dir.join("gs-alpha.token");
    std::fs::write(&p, format!("{token}\n")).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o600)).unwrap();
    p
}

/// The CLI's security options: `vehicles` and `reset` over grpcs with mutual TLS and a token file.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_cli_takes_tls_files_and_a_token_file() {
    let tmp = tempfile::tempdir().unwrap();
    deployment(tmp.path(), &[]);
    let (port, seen) = tls_fake::serve(tmp.path(), "uavnavd", true, "t0ken-alpha").await;
    let p = |f: &str| tmp.path().join(f).to_str().unwrap().to_string();
    let good = write_token(tmp.path(), "t0ken-alpha");
    let url = format!("grpcs://127.0.0.1:{port}");
    let base = |cmd: &str, token: &Path| {
        [
            cmd,
            "--from",
            &url,
            "--tls-ca",
            &p("ca.pem"),
            "--tls-cert",
            &p("gs-alpha.pem"),
            "--tls-key",
            &p("gs-alpha.key"),
            "--token-file",
            token.to_str().unwrap(),
        ]
        .map(String::from)
        .to_vec()
    };
    let out = run_async(base("vehicles", &good)).await;
    assert_eq!(out.status.code(), Some(0));
    assert!(stdout(&out).contains("alpha-1"));
    let mut reset = base("reset", &good);
    reset.extend(["--vehicle".into(), "bravo-7".into()]);
    let out = run_async(reset).await;
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("permission denied"));
    let bad = tmp.path().join("wrong.token");
    std::fs::write(&bad, "guess").unwrap();
    let out = run_async(base("vehicles", &bad)).await;
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        err.contains("not authenticated") && !err.contains("guess"),
        "{err}"
    );
    assert_eq!(seen.requests().len(), 3);
    // A token never travels in clear off this machine.
    let out = run_async(
        [
            "vehicles",
            "--from",
            "grpc://192.0.2.1:50051",
            "--token-file",
            good.to_str().unwrap(),
        ]
        .map(String::from)
        .to_vec(),
    )
    .await;
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("in clear"));
}

/// A Zenoh peer standing in for the service: TLS listener, mutual TLS, answering the vehicle
/// list query.
async fn zenoh_service(dir: &Path, port: u16) -> zenoh::Session {
    let mut z = zenoh::Config::default();
    let s = |p: &str| format!("\"{}\"", dir.join(p).display());
    for (k, v) in [
        ("listen/endpoints", format!("[\"tls/127.0.0.1:{port}\"]")),
        ("scouting/multicast/enabled", "false".into()),
        ("transport/link/tls/listen_certificate", s("uavnavd.pem")),
        ("transport/link/tls/listen_private_key", s("uavnavd.key")),
        ("transport/link/tls/root_ca_certificate", s("ca.pem")),
        ("transport/link/tls/enable_mtls", "true".into()),
    ] {
        z.insert_json5(k, &v).unwrap();
    }
    let session = zenoh::open(z).await.unwrap();
    let q = session
        .declare_queryable(uavnav_client::keys::VEHICLES)
        .await
        .unwrap();
    tokio::spawn(async move {
        while let Ok(query) = q.recv_async().await {
            let list = pb::ListVehiclesResponse {
                vehicles: vec![pb::VehicleSummary {
                    vehicle_id: "alpha-9".into(),
                    ..Default::default()
                }],
            };
            let _ = query
                .reply(uavnav_client::keys::VEHICLES, list.encode_to_vec())
                .await;
        }
    });
    session
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn zenoh_over_tls_needs_a_client_certificate_from_the_ca() {
    let tmp = tempfile::tempdir().unwrap();
    deployment(tmp.path(), &[]);
    let port = common::free_port();
    let service = zenoh_service(tmp.path(), port).await;
    let url = format!("zenoh/tls/127.0.0.1:{port}");
    let client = connect(&url, options(Some(tls(tmp.path(), Some("gs-alpha"))), None))
        .await
        .unwrap();
    let list = client.list_vehicles("").await.unwrap();
    assert_eq!(list.len(), 1);
    assert_eq!(list[0].vehicle_id, "alpha-9");
    client.close().await;
    let mut no_cert = options(Some(tls(tmp.path(), None)), None);
    no_cert.connect_timeout = Duration::from_secs(2);
    let e = connect(&url, no_cert).await.unwrap_err();
    assert!(matches!(e, ClientError::Connect { .. }), "{e}");
    let other = tmp.path().join("other");
    deployment(&other, &[]);
    let mut foreign = options(Some(tls(&other, Some("gs-alpha"))), None);
    foreign.connect_timeout = Duration::from_secs(2);
    let e = connect(&url, foreign).await.unwrap_err();
    assert!(matches!(e, ClientError::Connect { .. }), "{e}");
    let _ = service.close().await;
}

#[test]
fn every_online_subcommand_takes_the_security_options() {
    for sub in [
        "loadtest",
        "replay",
        "watch",
        "record",
        "vehicles",
        "configure",
        "reset",
        "health",
    ] {
        let out = run(&[sub, "--help"]);
        let help = stdout(&out);
        for flag in [
            "--tls-ca",
            "--tls-cert",
            "--tls-key",
            "--tls-domain",
            "--token-file",
            "UAVNAV_TLS_CA",
        ] {
            assert!(help.contains(flag), "{sub} --help lacks {flag}");
        }
        // The token itself is never an option (it would show in `ps`).
        assert!(!help.contains("--token "), "{sub}");
    }
    let out = run(&["certs", "--help"]);
    assert!(stdout(&out).contains("Exit codes"));
}
