//! Bad scenario files give one clear error with a line number, never a panic.
#![allow(clippy::unwrap_used)]

use uavnav_sim::{Flight, Scenario, SimError};

const SMOKE: &str = include_str!("../../scenarios/smoke.toml");

/// The smoke scenario with one line replaced; returns the error and the replaced line's number.
fn broken(find: &str, replace: &str) -> (uavnav_sim::ScenarioError, usize) {
    let line = SMOKE.lines().position(|l| l.starts_with(find)).unwrap() + 1;
    let text: String =
        SMOKE.lines().map(|l| if l.starts_with(find) { replace.to_string() } else { l.to_string() } + "\n").collect();
    (Scenario::from_toml_str(&text).unwrap_err(), line)
}

#[test]
fn shipped_scenarios_parse_and_fly() {
    for text in [
        SMOKE,
        include_str!("../../scenarios/paper-small-lever.toml"),
        include_str!("../../scenarios/paper-big-lever.toml"),
        include_str!("../../scenarios/mag-baro.toml"),
        include_str!("../../scenarios/multirotor.toml"),
    ] {
        let s = Scenario::from_toml_str(text).unwrap();
        Flight::new(&s).unwrap();
    }
}

#[test]
fn unknown_key() {
    let (e, line) = broken("rate_hz = 200.0", "rate_hzz = 200.0");
    assert_eq!(e.line, line, "{e}");
    assert!(e.message.contains("rate_hzz"), "{e}");
}

#[test]
fn wrong_type() {
    let (e, line) = broken("fx = 500.0", "fx = \"wide\"");
    assert_eq!(e.line, line, "{e}");
    assert!(
        e.to_string().starts_with(&format!("line {line}, column")),
        "{e}"
    );
}

#[test]
fn negative_rate() {
    let (e, line) = broken("rate_hz = 5.0", "rate_hz = -5.0");
    assert_eq!(e.line, line, "{e}");
    assert!(e.message.contains("> 0"), "{e}");
}

#[test]
fn bad_window_and_pulse() {
    let (e, line) = broken("outages = ", "outages = [{ start_s = 15.0, end_s = 12.0 }]");
    assert_eq!(e.line, line, "{e}");
    assert!(e.message.contains("start_s"), "{e}");
    let (e, _) = broken(
        "ramp_s = 3.0                      # ramp in and out",
        "ramp_s = 6.0",
    );
    let header = SMOKE
        .lines()
        .position(|l| l.starts_with("[[trajectory.turns]]"))
        .unwrap()
        + 1;
    assert_eq!(
        e.line, header,
        "pulse errors point at their table's header: {e}"
    );
    assert!(e.message.contains("twice"), "{e}");
}

#[test]
fn garbage_and_empty_input() {
    let e = Scenario::from_toml_str("seed = = 3").unwrap_err();
    assert_eq!(e.line, 1);
    let e = Scenario::from_toml_str("").unwrap_err();
    assert!(e.message.contains("seed"), "{e}");
}

#[test]
fn impossible_flights_are_rejected() {
    let mut s = Scenario::from_toml_str(SMOKE).unwrap();
    s.trajectory.turns[0].rate_dps = 40.0;
    assert!(matches!(Flight::new(&s), Err(SimError::Invalid(m)) if m.contains("bank")));
    let mut s = Scenario::from_toml_str(SMOKE).unwrap();
    s.terrain.elevation_m = 195.0;
    assert!(
        matches!(Flight::new(&s), Err(SimError::Invalid(m)) if m.contains("above the terrain"))
    );
}
