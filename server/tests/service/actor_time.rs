//! The vehicle actors' timing on a paused clock (`uavnav_tests::paused`): idle eviction after
//! `vehicles.idle_evict_s` frees a slot for a new vehicle while an active vehicle stays, and
//! health reports come once per `health.period_ms` with rates over exactly that period while the
//! vehicle is active, once in ten periods while it is idle — checked to the tick, in no real
//! time.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::time::Duration;

use uavnav_proto::v1 as pb;
use uavnav_tests::paused::Fleet;
use uavnav_tests::service::loopback_config;

const S: Duration = Duration::from_secs(1);

fn accepted(v: &uavnavd::ingest::Verdict) -> bool {
    v.status == pb::IngestStatus::Accepted
}

#[tokio::test]
async fn an_idle_vehicle_is_evicted_and_its_slot_reused_while_an_active_one_stays() {
    let mut cfg = loopback_config();
    cfg.vehicles.max_vehicles = 2;
    cfg.vehicles.idle_evict_s = 300.0;
    cfg.health.period_ms = 1000;
    let mut fleet = Fleet::start(&cfg);
    assert!(accepted(&fleet.imu("idle", 4).await));
    assert!(accepted(&fleet.imu("active", 4).await));
    // The fleet is full: a third vehicle is refused, naming the limit.
    let refused = fleet.imu("new", 4).await;
    assert_eq!(
        refused.status,
        pb::IngestStatus::ResourceExhausted,
        "{refused:?}"
    );
    assert!(refused.reason.contains("vehicle limit of 2"), "{refused:?}");

    // "active" sends every 100 s; "idle" never again.
    for _ in 0..2 {
        fleet.run_for(100 * S).await;
        assert!(accepted(&fleet.imu("active", 4).await));
    }
    // 299.5 s after its last input "idle" is still there (the check runs at each health tick).
    fleet.run_for(Duration::from_millis(99_500)).await;
    assert_eq!(fleet.ids(), ["active", "idle"]);
    assert!(!accepted(&fleet.imu("new", 4).await), "still full");
    assert_eq!(fleet.metrics().evictions.get(), 0);

    // The tick at 300 s evicts it, and only it.
    fleet.run_for(S).await;
    assert_eq!(fleet.ids(), ["active"]);
    assert_eq!(fleet.metrics().evictions.get(), 1);
    assert_eq!(fleet.metrics().vehicles.get(), 1);
    assert!(
        accepted(&fleet.imu("new", 4).await),
        "the freed slot is reused"
    );
    assert_eq!(fleet.ids(), ["active", "new"]);

    // "active" went 100 s without input, far from its limit: it stays for the next 199 s, then goes.
    fleet.run_for(199 * S).await;
    assert_eq!(fleet.ids(), ["active", "new"]);
    fleet.run_for(2 * S).await;
    assert_eq!(fleet.ids(), ["new"]);
    assert_eq!(fleet.metrics().evictions.get(), 2);
}

#[tokio::test]
async fn health_comes_once_per_period_with_rates_over_that_period() {
    let mut cfg = loopback_config();
    cfg.health.period_ms = 1000;
    let mut fleet = Fleet::start(&cfg);
    assert!(accepted(&fleet.imu("uav", 1).await));
    // A report at start (the first tick) and one per second after it: 0 s, 1 s.
    fleet.run_for(Duration::from_millis(1500)).await;
    let first: Vec<_> = fleet.health_reports();
    assert_eq!(first.len(), 2, "{first:?}");
    assert_eq!(first[1].input_rates.as_ref().unwrap().imu_hz, 0.0);

    // 50 samples within the third period (1 s to 2 s): exactly 50 Hz over it, then 0 Hz.
    assert!(accepted(&fleet.imu("uav", 50).await));
    fleet.run_for(Duration::from_millis(1000)).await;
    fleet.run_for(Duration::from_millis(1000)).await;
    let next = fleet.tagged_health_reports();
    let rates: Vec<f64> = next
        .iter()
        .map(|r| r.health.input_rates.as_ref().unwrap().imu_hz)
        .collect();
    assert_eq!(rates, [50.0, 0.0]);
    // Both say something new (the rates changed each time).
    assert!(next.iter().all(|r| !r.repeat));

    // Idle since: one report in ten periods (an idle fleet costs next to nothing), no more, no
    // fewer; nothing but their clocks differs from the last report: repeats (which Zenoh
    // publishes within a fleet-wide budget).
    fleet.run_for(10 * S).await;
    let idle = fleet.tagged_health_reports();
    assert_eq!(idle.len(), 1);
    assert!(idle[0].repeat, "{idle:?}");
    fleet.run_for(20 * S).await;
    let idle = fleet.tagged_health_reports();
    assert_eq!(idle.len(), 2);
    assert!(idle.iter().all(|r| r.repeat));
    assert!(next.iter().all(|r| r.health.vehicle_id == "uav"));
    // Input again: every period again, and news.
    assert!(accepted(&fleet.imu("uav", 10).await));
    fleet.run_for(3 * S).await;
    let again = fleet.tagged_health_reports();
    assert_eq!(again.len(), 2);
    assert!(!again[0].repeat);
}
