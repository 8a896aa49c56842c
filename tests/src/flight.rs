//! Simulated flights for tests: a shipped scenario's first seconds, every sensor, in time order;
//! or the smoke flight as the wire messages a sender streams.

use uavnav_core::{SensorEvent, VehicleConfig};
use uavnav_sim::scenario::Scenario;

use crate::pb;
use crate::pb::sensor_envelope::Payload;

/// A shipped scenario (`scenarios/{name}.toml`).
fn scenario(name: &str) -> Scenario {
    let path = format!("{}/../scenarios/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("scenario {name}: {e}"));
    Scenario::from_toml_str(&text).unwrap_or_else(|e| panic!("scenario {name}: {e}"))
}

/// The first `seconds` of a shipped scenario (`scenarios/{name}.toml`), every sensor, in time
/// order, with its vehicle configuration.
pub fn sim_flight(name: &str, seconds: f64) -> (VehicleConfig, Vec<SensorEvent>) {
    let flight = uavnav_sim::flight::Flight::new(&scenario(name))
        .unwrap_or_else(|e| panic!("scenario {name}: {e}"));
    let mut events = Vec::new();
    let mut t_end = None;
    for e in flight.events() {
        let e = e.unwrap_or_else(|e| panic!("scenario {name}: {e}"));
        let end = *t_end.get_or_insert(e.t_ns() + (seconds * 1e9) as i64);
        if e.t_ns() > end {
            break;
        }
        events.push(e);
    }
    (flight.vehicle_config(), events)
}

/// A `duration_s` smoke flight without camera as a sender streams it: its wire configuration
/// and its messages (the configuration first, then the sensors in time order, IMU samples four to
/// a batch).
pub fn wire_flight(duration_s: f64) -> (pb::VehicleConfig, Vec<Payload>) {
    let mut s = scenario("smoke");
    s.duration_s = duration_s;
    s.camera.enabled = false;
    let f = uavnav_sim::Flight::new(&s).unwrap_or_else(|e| panic!("smoke flight: {e}"));
    let config = pb::VehicleConfig::from(&f.vehicle_config());
    let mut msgs = vec![Payload::Config(config)];
    let mut imu = Vec::new();
    for ev in f.events() {
        match ev.unwrap_or_else(|e| panic!("smoke flight: {e}")) {
            SensorEvent::Imu(s) => {
                imu.push(s);
                if imu.len() == 4 {
                    msgs.push(Payload::Imu(pb::ImuBatch::from(imu.as_slice())));
                    imu.clear();
                }
            }
            other => {
                if !imu.is_empty() {
                    msgs.push(Payload::Imu(pb::ImuBatch::from(imu.as_slice())));
                    imu.clear();
                }
                msgs.push(Payload::from(&other));
            }
        }
    }
    if !imu.is_empty() {
        msgs.push(Payload::Imu(pb::ImuBatch::from(imu.as_slice())));
    }
    (config, msgs)
}
