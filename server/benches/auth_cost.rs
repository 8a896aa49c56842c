//! What authorization costs per message, through the service facade (`Service::feed`), in
//! process: an accepted IMU envelope for the caller's own vehicle against one refused with
//! PERMISSION_DENIED for another fleet's, with authorization on, and the accepted one with
//! authorization off. Not a criterion benchmark: it prints a table of ns per message
//! (`cargo bench -p uavnavd --bench auth_cost`). A refused message must cost less than an
//! accepted one: it is refused before the vehicle is looked up.
//!
//! `auth_cost CASE [N]` (CASE: `accepted`, `refused` or `open`) runs only that case, N messages
//! (default 200,000) after the warm-up, so that an instruction counter sees one case alone:
//! `valgrind --tool=callgrind --toggle-collect='*Service::feed*' auth_cost refused 100000`
//! counts the facade's instructions (divide by N); the whole process's count at two N, the
//! difference divided by the difference of N, includes the vehicle's actor.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::sync::Arc;
use std::time::Instant;

use uavnav_proto::v1 as pb;
use uavnavd::ingest::Payload;
use uavnavd::metrics::Transport;
use uavnavd::security::{Access, AuthTransport, Authorizer, Grant, PrincipalConfig, Verb};
use uavnavd::service::Service;

const N: usize = 200_000;

fn service(principals: &[PrincipalConfig]) -> (Service, tokio::sync::watch::Sender<bool>) {
    let mut c = uavnavd::Config::default();
    c.zenoh.enabled = false;
    let (ingestor, stop) =
        uavnavd::server::ingest_path(&c, uavnavd::engine::default_factory()).unwrap();
    (
        Service::new(ingestor, Arc::new(Authorizer::new(principals).unwrap())),
        stop,
    )
}

/// ns per `feed` of `n` one-sample IMU batches to `id`, sensor time moving on 5 ms a sample.
async fn per_message(s: &Service, access: &Access, id: &str, n: usize) -> (f64, pb::IngestStatus) {
    let mut status = pb::IngestStatus::Unspecified;
    let t0 = Instant::now();
    for k in 0..n {
        let batch = pb::ImuBatch {
            samples: vec![pb::ImuSample {
                t_ns: 1_000_000_000 + k as i64 * 5_000_000,
                accel_z_mps2: -9.81,
                ..Default::default()
            }],
        };
        status = s
            .feed(access, Transport::Grpc, id, Payload::Imu(&batch))
            .await
            .status;
    }
    (t0.elapsed().as_nanos() as f64 / n as f64, status)
}

/// Which case to run alone, and how many messages (`None`: the whole table).
fn case_from_args() -> Option<(String, usize)> {
    // `cargo bench` passes `--bench` to a harness-less bench: flags are not ours.
    let mut args = std::env::args().skip(1).filter(|a| !a.starts_with("--"));
    let case = args.next()?;
    let n = args.next().map_or(N, |n| n.parse().unwrap());
    assert!(
        matches!(case.as_str(), "accepted" | "refused" | "open"),
        "case: accepted, refused or open, not {case:?}"
    );
    Some((case, n))
}

fn main() {
    let one = case_from_args();
    let alpha = PrincipalConfig {
        name: "gs-alpha".into(),
        certificate_names: vec!["gs-alpha".into()],
        token_sha256: vec![],
        grants: vec![Grant {
            vehicles: "alpha-".into(),
            verbs: vec![Verb::Feed, Verb::Watch],
        }],
    };
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let (secured, _stop1) = service(std::slice::from_ref(&alpha));
        let access = secured.authenticate(AuthTransport::Grpc, &["gs-alpha".into()], None).unwrap();
        let (open, _stop2) = service(&[]);
        // Warm up: the vehicles exist, their actors run.
        let _ = per_message(&secured, &access, "alpha-1", 1_000).await;
        let _ = per_message(&open, &Access::Open, "alpha-1", 1_000).await;
        if let Some((case, n)) = one {
            let (svc, acc, id) = match case.as_str() {
                "accepted" => (&secured, &access, "alpha-2"),
                "refused" => (&secured, &access, "bravo-1"),
                _ => (&open, &Access::Open, "alpha-2"),
            };
            let (ns, status) = per_message(svc, acc, id, n).await;
            println!("{case}: {n} messages, {ns:.0} ns per message, {status:?}");
            return;
        }
        println!("| message | authorization | ns per message | status |");
        println!("|---|---|---|---|");
        for (what, svc, acc, id) in [
            ("IMU for its own vehicle", &open, &Access::Open, "alpha-2"),
            ("IMU for its own vehicle", &secured, &access, "alpha-2"),
            ("IMU for another fleet's vehicle", &secured, &access, "bravo-1"),
        ] {
            let (ns, status) = per_message(svc, acc, id, N).await;
            let auth = if matches!(acc, Access::Open) { "off" } else { "on" };
            println!("| {what} | {auth} | {ns:.0} | {status:?} |");
        }
        let t0 = Instant::now();
        for _ in 0..N {
            let _ = secured.authenticate(AuthTransport::Grpc, &["gs-alpha".into()], Some(b"Bearer not-a-token"));
        }
        println!(
            "| (one call's authentication: certificate and a bad token) | on | {:.0} | Unauthenticated |",
            t0.elapsed().as_nanos() as f64 / N as f64
        );
    });
}
