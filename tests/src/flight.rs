//! Simulated flights for tests: a shipped scenario's first seconds, every sensor, in time order.

use uavnav_core::{SensorEvent, VehicleConfig};

/// The first `seconds` of a shipped scenario (`scenarios/{name}.toml`), every sensor, in time
/// order, with its vehicle configuration.
pub fn sim_flight(name: &str, seconds: f64) -> (VehicleConfig, Vec<SensorEvent>) {
    let path = format!("{}/../scenarios/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("scenario {name}: {e}"));
    let scenario = uavnav_sim::scenario::Scenario::from_toml_str(&text)
        .unwrap_or_else(|e| panic!("scenario {name}: {e}"));
    let flight = uavnav_sim::flight::Flight::new(&scenario)
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
