//! The client library against the real service with TLS and grants (issue 20): a ground station
//! with its certificate gets in; without a certificate, or in clear (`grpc://`) to the TLS port,
//! the call fails at once with a TLS error (not retried: no new connection can fix it); outside
//! its grant it gets `PermissionDenied`.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::{Duration, Instant};

use uavnav_client::{Client, ClientError, ConnectOptions, TlsOptions};
use uavnav_tests::pki::Pki;
use uavnavd::security::{Grant, PrincipalConfig, TlsConfig, Verb};

#[tokio::test]
async fn tls_refusals_fail_fast_and_grants_hold() {
    let dir = tempfile::tempdir().unwrap();
    let pki = Pki::new(dir.path(), "fleet");
    let svc = pki.service("uavnavd");
    let alpha = pki.client("gs-alpha");
    let mut c = uavnav_tests::service::loopback_config();
    c.security.tls = Some(TlsConfig {
        certificate: svc.cert,
        private_key: svc.key,
        client_ca: Some(pki.ca.clone()),
        require_client_certificate: true,
        reload_s: 10.0,
    });
    c.security.principals = vec![PrincipalConfig {
        name: "gs-alpha".into(),
        certificate_names: vec!["gs-alpha".into()],
        token_sha256: vec![],
        grants: vec![Grant {
            vehicles: "alpha-".into(),
            verbs: vec![Verb::List, Verb::Reset, Verb::Configure],
        }],
    }];
    let server = uavnavd::Server::start(c).await.unwrap();
    let port = server.grpc_addr.port();
    let opts = |tls: Option<TlsOptions>| ConnectOptions {
        tls,
        ..ConnectOptions::default()
    };

    // With its certificate: in, and refused outside its fleet.
    let ok = Client::connect(
        &format!("grpcs://localhost:{port}").parse().unwrap(),
        opts(Some(
            TlsOptions::with_ca(&pki.ca).with_identity(&alpha.cert, &alpha.key),
        )),
    )
    .await
    .unwrap();
    ok.list_vehicles("").await.unwrap();
    let e = ok.reset("bravo-1").await.unwrap_err();
    assert!(matches!(e, ClientError::PermissionDenied { .. }), "{e:?}");

    // Without a certificate, and in clear: a TLS error, fast.
    for (url, tls) in [
        (
            format!("grpcs://localhost:{port}"),
            Some(TlsOptions::with_ca(&pki.ca)),
        ),
        (format!("grpc://localhost:{port}"), None),
    ] {
        let t0 = Instant::now();
        let r = match Client::connect(&url.parse().unwrap(), opts(tls)).await {
            Err(e) => Err(e),
            Ok(c) => c.list_vehicles("").await.map(|_| ()),
        };
        let e = r.unwrap_err();
        assert!(
            matches!(e, ClientError::Tls { .. } | ClientError::Connect { .. }),
            "{url}: {e:?}"
        );
        assert!(
            t0.elapsed() < Duration::from_secs(5),
            "{url}: refused after {:?}",
            t0.elapsed()
        );
        if url.starts_with("grpc://") {
            assert!(
                matches!(&e, ClientError::Tls { reason } if reason.contains("use grpcs://localhost")),
                "{url}: {e}"
            );
        }
    }
    server.shutdown().await.unwrap();
}
