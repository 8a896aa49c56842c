//! Issue 20 on Zenoh: the service listens on mutual TLS only, and its access control (derived from
//! the same grants as gRPC, keyed on the certificate's common name) lets a ground station put only
//! on its fleet's input keys and subscribe only to its fleet's outputs. A peer in clear, without a
//! certificate, with a stranger's or with an expired one of the service's CA never connects (and
//! one that keeps retrying with the expired certificate neither feeds nor receives); fleet alpha's puts on bravo's keys never
//! create a vehicle; a forged pose and a fake service token from a ground-station certificate
//! never reach a watcher; the admin space is closed.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::Duration;

use crate::common::*;
use prost::Message;
use uavnav_proto::keys::{self, Leaf};
use uavnav_proto::v1 as pb;
use uavnav_tests::net::{eventually, free_port};
use uavnav_tests::pki::{Pem, Pki};
use uavnavd::security::{Grant, PrincipalConfig, TlsConfig, Verb};

fn grant(name: &str, fleet: &str, verbs: Vec<Verb>) -> PrincipalConfig {
    PrincipalConfig {
        name: name.into(),
        certificate_names: vec![name.into()],
        token_sha256: vec![],
        grants: vec![Grant {
            vehicles: fleet.into(),
            verbs,
        }],
    }
}

/// A Zenoh client of the service over TLS, with `identity` as its certificate (None: no
/// certificate), trusting `ca`.
async fn station(
    endpoint: &str,
    ca: &std::path::Path,
    identity: Option<&Pem>,
) -> zenoh::Result<zenoh::Session> {
    let mut c = zenoh::Config::default();
    let q = |p: &std::path::Path| format!("\"{}\"", p.display());
    c.insert_json5("mode", "\"client\"").unwrap();
    c.insert_json5("connect/endpoints", &format!("[\"{endpoint}\"]"))
        .unwrap();
    c.insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    c.insert_json5("transport/link/tls/root_ca_certificate", &q(ca))
        .unwrap();
    if let Some(p) = identity {
        c.insert_json5("transport/link/tls/connect_certificate", &q(&p.cert))
            .unwrap();
        c.insert_json5("transport/link/tls/connect_private_key", &q(&p.key))
            .unwrap();
        c.insert_json5("transport/link/tls/enable_mtls", "true")
            .unwrap();
    }
    // A client that cannot reach its router fails at open instead of retrying for ever.
    c.insert_json5("connect/timeout_ms", "3000").unwrap();
    c.insert_json5("connect/exit_on_failure", "true").unwrap();
    zenoh::open(c).await
}

/// A Zenoh peer with `identity` that opens without a link and keeps trying to connect to
/// `endpoint` in the background (every 200–500 ms): what a misconfigured drone does for ever.
async fn lingering_peer(
    endpoint: &str,
    ca: &std::path::Path,
    identity: &Pem,
) -> zenoh::Result<zenoh::Session> {
    let mut c = zenoh::Config::default();
    let q = |p: &std::path::Path| format!("\"{}\"", p.display());
    for (key, value) in [
        ("mode", "\"peer\"".to_string()),
        ("connect/endpoints", format!("[\"{endpoint}\"]")),
        ("listen/endpoints", "[]".into()),
        ("scouting/multicast/enabled", "false".into()),
        ("connect/exit_on_failure", "false".into()),
        // (`retry` is absent by default: set as a whole.)
        (
            "connect/retry",
            "{ period_init_ms: 200, period_max_ms: 500 }".into(),
        ),
        ("transport/link/tls/root_ca_certificate", q(ca)),
        ("transport/link/tls/connect_certificate", q(&identity.cert)),
        ("transport/link/tls/connect_private_key", q(&identity.key)),
        ("transport/link/tls/enable_mtls", "true".into()),
    ] {
        c.insert_json5(key, &value).unwrap();
    }
    zenoh::open(c).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn zenoh_grants_follow_the_certificate() {
    let dir = tempfile::tempdir().unwrap();
    let pki = Pki::new(dir.path(), "fleet");
    let svc = pki.service("uavnavd");
    let port = free_port();
    let endpoint = format!("tls/localhost:{port}");
    let mut cfg = test_config();
    cfg.zenoh.enabled = true;
    cfg.zenoh.mode = uavnavd::config::ZenohMode::Router;
    cfg.zenoh.listen = vec![format!("tls/127.0.0.1:{port}")];
    cfg.zenoh.instance = format!("sec-{port}");
    cfg.zenoh.multicast_scouting = false;
    cfg.security.tls = Some(TlsConfig {
        certificate: svc.cert.clone(),
        private_key: svc.key.clone(),
        client_ca: Some(pki.ca.clone()),
        require_client_certificate: true,
        reload_s: 10.0,
    });
    let all = vec![Verb::Feed, Verb::Configure, Verb::Watch];
    cfg.security.principals = vec![
        grant("gs-alpha", "alpha-", all.clone()),
        grant("gs-bravo", "bravo-", all),
    ];
    let server = start(cfg).await;

    // No certificate, a stranger's certificate: no session.
    assert!(
        station(&endpoint, &pki.ca, None).await.is_err(),
        "a peer without a certificate must not connect"
    );
    let sdir = tempfile::tempdir().unwrap();
    let stranger = Pki::new(sdir.path(), "stranger");
    assert!(
        station(&endpoint, &pki.ca, Some(&stranger.client("gs-alpha")))
            .await
            .is_err(),
        "a certificate of another CA must not connect"
    );
    // In clear to the TLS port, and an expired certificate of the service's own CA, naming a
    // configured principal: no session either.
    assert!(
        station(&format!("tcp/localhost:{port}"), &pki.ca, None)
            .await
            .is_err(),
        "a plaintext peer must not connect"
    );
    let expired = pki.expired_client("gs-alpha");
    assert!(
        station(&endpoint, &pki.ca, Some(&expired)).await.is_err(),
        "an expired certificate must not connect"
    );
    // The same expired certificate on a peer that keeps retrying for the rest of the test: it
    // subscribes to alpha-1's poses and puts on alpha-3's keys (alpha's fleet: only the
    // certificate's age stops it).
    let stale = lingering_peer(&endpoint, &pki.ca, &expired).await.unwrap();
    let stale_poses = stale
        .declare_subscriber(keys::vehicle_key("alpha-1", Leaf::Pose))
        .await
        .unwrap();

    let alpha = station(&endpoint, &pki.ca, Some(&pki.client("gs-alpha")))
        .await
        .unwrap();
    let bravo = station(&endpoint, &pki.ca, Some(&pki.client("gs-bravo")))
        .await
        .unwrap();
    // bravo's ground station (a session of its own that puts nothing: a session's puts reach
    // its own subscribers locally, without the service) watches its vehicle's poses with its
    // prefix, and (in vain) everything.
    let watcher = station(&endpoint, &pki.ca, Some(&pki.client("gs-bravo")))
        .await
        .unwrap();
    let bravo_poses = watcher
        .declare_subscriber(keys::vehicle_key("bravo-1", Leaf::Pose))
        .await
        .unwrap();
    let bravo_wide = watcher
        .declare_subscriber(keys::ALL_VEHICLE_KEYS)
        .await
        .unwrap();
    // alpha's own poses, to a session with alpha's valid certificate (alpha puts no pose, so
    // nothing it receives on this key is local): the positive control of the stale peer.
    let alpha_poses = alpha
        .declare_subscriber(keys::vehicle_key("alpha-1", Leaf::Pose))
        .await
        .unwrap();
    let services = watcher
        .liveliness()
        .declare_subscriber(format!("{}/**", keys::SERVICE_PREFIX))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(500)).await;

    let enc = |name: &str| uavnavd::zenoh_io::encoding(name);
    let put = async |s: &zenoh::Session, id: &str, leaf: Leaf, body: Vec<u8>, name: &str| {
        s.put(keys::vehicle_key(id, leaf), body)
            .encoding(enc(name))
            .await
            .unwrap();
    };
    // Positive control: each fleet feeds its own vehicle.
    for (s, id) in [(&alpha, "alpha-1"), (&bravo, "bravo-1")] {
        put(
            s,
            id,
            Leaf::Config,
            vehicle_config(false).encode_to_vec(),
            "uavnav.v1.VehicleConfig",
        )
        .await;
        put(
            s,
            id,
            Leaf::Gnss,
            fix(1_000).encode_to_vec(),
            "uavnav.v1.GnssFix",
        )
        .await;
        for k in 0..20 {
            let b = pb::ImuBatch {
                samples: vec![imu(2_000 + k * 5_000_000)],
            };
            put(s, id, Leaf::Imu, b.encode_to_vec(), "uavnav.v1.ImuBatch").await;
        }
    }
    // alpha on bravo's keys: a new vehicle and an existing one.
    put(
        &alpha,
        "bravo-2",
        Leaf::Config,
        vehicle_config(false).encode_to_vec(),
        "uavnav.v1.VehicleConfig",
    )
    .await;
    put(
        &alpha,
        "bravo-2",
        Leaf::Gnss,
        fix(1_000).encode_to_vec(),
        "uavnav.v1.GnssFix",
    )
    .await;
    // Forged outputs from a ground-station certificate: a pose on bravo-1's key, a service token.
    let forged = pb::PoseEstimate {
        vehicle_id: "bravo-1".into(),
        t_ns: 123,
        ..Default::default()
    };
    put(
        &alpha,
        "bravo-1",
        Leaf::Pose,
        forged.encode_to_vec(),
        "uavnav.v1.PoseEstimate",
    )
    .await;
    put(
        &bravo,
        "bravo-1",
        Leaf::Pose,
        forged.encode_to_vec(),
        "uavnav.v1.PoseEstimate",
    )
    .await;
    let _fake = alpha
        .liveliness()
        .declare_token(keys::service_key("impostor"))
        .await
        .unwrap();

    // The stale peer feeds alpha-3 for 3 s, through several of its connection attempts.
    for k in 0..10 {
        put(
            &stale,
            "alpha-3",
            Leaf::Config,
            vehicle_config(false).encode_to_vec(),
            "uavnav.v1.VehicleConfig",
        )
        .await;
        put(
            &stale,
            "alpha-3",
            Leaf::Gnss,
            fix(1_000 + k * 1_000_000).encode_to_vec(),
            "uavnav.v1.GnssFix",
        )
        .await;
        tokio::time::sleep(Duration::from_millis(300)).await;
    }

    let reg = server.registry().clone();
    assert!(
        eventually(Duration::from_secs(10), || {
            reg.get("alpha-1")
                .is_some_and(|h| h.shared.pose().is_some())
                && reg
                    .get("bravo-1")
                    .is_some_and(|h| h.shared.pose().is_some())
        })
        .await,
        "both fleets' own vehicles are fed over Zenoh"
    );
    // bravo receives its vehicle's real poses, never the forged one, and nothing of alpha's.
    let mut real = 0;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(3);
    while let Ok(Ok(s)) = tokio::time::timeout_at(deadline, bravo_poses.recv_async()).await {
        let p = pb::PoseEstimate::decode(s.payload().to_bytes().as_ref()).unwrap();
        assert_ne!(p.t_ns, 123, "the forged pose reached a watcher");
        real += 1;
    }
    assert!(real > 0, "bravo gets its own poses");
    // alpha-1's poses reach alpha's valid session, never the expired one, whose puts never
    // created alpha-3.
    let mut alpha_real = 0;
    while let Ok(Some(_)) = alpha_poses.try_recv() {
        alpha_real += 1;
    }
    assert!(
        alpha_real > 0,
        "alpha gets its own poses (positive control)"
    );
    assert!(
        stale_poses.try_recv().unwrap().is_none(),
        "a peer with an expired certificate received a pose"
    );
    assert!(
        reg.get("alpha-3").is_none(),
        "a peer with an expired certificate fed a vehicle"
    );
    // A wildcard over every vehicle gets bravo's own outputs only: the service's egress rules
    // filter each put by its key.
    let mut wide = 0;
    while let Ok(Some(s)) = bravo_wide.try_recv() {
        let key = s.key_expr().as_str();
        assert!(
            key.starts_with("uavnav/v1/vehicle/bravo-")
                && (key.ends_with("/pose") || key.ends_with("/health")),
            "a wildcard subscription got {key}"
        );
        assert!(
            !key.contains("alpha-"),
            "bravo's wildcard got alpha's {key}"
        );
        wide += 1;
    }
    assert!(wide > 0, "the wildcard got bravo's own outputs");
    while let Ok(Some(t)) = services.try_recv() {
        assert!(
            !t.key_expr().as_str().ends_with("impostor"),
            "a fake service token reached a watcher"
        );
    }
    assert!(
        reg.get("bravo-2").is_none(),
        "alpha's puts on bravo's keys never create a vehicle"
    );
    let bravo1 = reg.get("bravo-1").unwrap();
    assert_eq!(
        bravo1.shared.stats.accepted(),
        reg.get("alpha-1").unwrap().shared.stats.accepted(),
        "bravo-1 got bravo's inputs only (as many as alpha-1 got from alpha)"
    );
    // The service's admin space is closed (a session answers for its own `@/{zid}/session/**`
    // locally; nothing may come from the service's).
    let own = format!("@/{}/", alpha.zid());
    let admin = alpha.get("@/**").await.unwrap();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(2);
    while let Ok(Ok(r)) = tokio::time::timeout_at(deadline, admin.recv_async()).await {
        if let Ok(sample) = r.result() {
            let key = sample.key_expr().as_str();
            assert!(
                key.starts_with(&own),
                "the service's admin space answered: {key}"
            );
        }
    }
    drop((alpha, bravo, watcher, stale));
    server.shutdown().await.unwrap();
}
