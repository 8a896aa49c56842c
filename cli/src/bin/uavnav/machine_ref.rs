//! `uavnav loadtest --metrics`: this machine's speed, measured before the load and printed beside
//! the service's cost per input, so that a capacity figure taken on a slow day can be told from a
//! service that became slower. The machines this project is measured on have given the same
//! service 3.5 µs per input one day and 6 µs another (README, capacity).
//!
//! The reference is the estimator alone (no service, no network) on the built-in smoke flight,
//! driven as the service drives it: every vehicle of the run takes a message of the run's size
//! (`--imu-batch` samples; 4, 20 ms at 200 Hz, by default) in turn, so that each one's state has
//! left the cache when its next message comes; and one vehicle alone, whose state stays cached. The gap between the two is the price of the
//! fleet's size on this machine's caches.

use std::time::Instant;

use uavnav_estimator::{Estimator, EstimatorParams};
use uavnav_sim::{Flight, Scenario};

/// Messages timed per vehicle of the fleet.
const FLEET_LAPS: usize = 20;
/// Messages timed for the single vehicle (one run; the best of [`SINGLE_RUNS`] is kept).
const SINGLE_LAPS: usize = 100;
/// Runs of the single-vehicle timing (the least disturbed one is the machine's speed).
const SINGLE_RUNS: usize = 20;
/// Seconds of flight before the timed samples: the filter is initialised and fusing GNSS.
const WARM_UP_S: f64 = 12.0;

/// What the reference measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reference {
    /// Vehicles of the fleet timing.
    pub vehicles: usize,
    /// IMU samples per message.
    pub per_message: usize,
    /// µs per IMU sample, the vehicles taking messages in turn.
    pub fleet_us: f64,
    /// µs per IMU sample, one vehicle alone.
    pub single_us: f64,
}

/// Measures the reference for a fleet of `vehicles` taking messages of `per_message` IMU samples,
/// on the flight of `scenario_toml`.
pub fn measure(
    scenario_toml: &str,
    vehicles: usize,
    per_message: usize,
) -> Result<Reference, String> {
    let mut s = Scenario::from_toml_str(scenario_toml).map_err(|e| format!("{e:?}"))?;
    s.camera.enabled = false; // frames would be rendered, and the estimator alone is timed
    let per_message = per_message.max(1);
    let laps = FLEET_LAPS.max(SINGLE_LAPS) + 1;
    let timed_s = (laps * per_message) as f64 / s.imu.rate_hz;
    s.duration_s = s.duration_s.max(WARM_UP_S + timed_s + 1.0);
    let flight = Flight::new(&s).map_err(|e| e.to_string())?;
    let imu = flight.imu();
    let start = imu
        .iter()
        .position(|x| (x.t_ns - imu[0].t_ns) as f64 * 1e-9 >= WARM_UP_S)
        .ok_or("the reference flight is shorter than its warm-up")?;
    let samples = imu
        .get(start..start + laps * per_message)
        .ok_or("the reference flight is too short")?;
    let warm = warmed_up(&flight, start)?;
    let message = |k: usize| &samples[k * per_message..(k + 1) * per_message];
    let per_sample_us = |t0: Instant, messages: usize| {
        t0.elapsed().as_secs_f64() * 1e6 / (messages * per_message) as f64
    };

    // The fleet: one untimed message first, so that each clone's buffers (cut to their length by
    // the clone) grow back to their steady size.
    let vehicles = vehicles.max(1);
    let mut fleet: Vec<Estimator> = (0..vehicles).map(|_| warm.clone()).collect();
    push_all(&mut fleet, message(0));
    let t0 = Instant::now();
    for k in 1..=FLEET_LAPS {
        push_all(&mut fleet, message(k));
    }
    let fleet_us = per_sample_us(t0, vehicles * FLEET_LAPS);
    drop(fleet);

    let mut single_us = f64::INFINITY;
    for _ in 0..SINGLE_RUNS {
        let mut one = vec![warm.clone()];
        push_all(&mut one, message(0));
        let t0 = Instant::now();
        for k in 1..=SINGLE_LAPS {
            push_all(&mut one, message(k));
        }
        single_us = single_us.min(per_sample_us(t0, SINGLE_LAPS));
    }
    Ok(Reference {
        vehicles,
        per_message,
        fleet_us,
        single_us,
    })
}

/// The estimator after the flight's first `until` IMU samples and the fixes among them.
fn warmed_up(flight: &Flight, until: usize) -> Result<Estimator, String> {
    let mut config = flight.vehicle_config();
    config.camera = None;
    let mut est = Estimator::new(&config, EstimatorParams::default(), Some(flight.origin()));
    let mut fixes = flight.gnss().iter().peekable();
    for s in &flight.imu()[..until] {
        while let Some(f) = fixes.next_if(|f| f.t_ns <= s.t_ns) {
            est.push_gnss(f)
                .map_err(|e| format!("reference flight: {e}"))?;
        }
        est.push_imu(s)
            .map_err(|e| format!("reference flight: {e}"))?;
    }
    Ok(est)
}

/// Every estimator of `fleet` takes `message`, one after the other.
fn push_all(fleet: &mut [Estimator], message: &[uavnav_core::ImuSample]) {
    for e in fleet {
        for s in message {
            // The flight is valid by construction; a refusal would only make the figure smaller.
            let _ = std::hint::black_box(e.push_imu(s));
        }
    }
}

/// The line `uavnav loadtest --metrics` prints.
pub fn line(r: &Reference) -> String {
    format!(
        "Machine reference: the estimator alone takes {:.2} µs per IMU sample for {} vehicle{} \
         taking {}-sample messages in turn ({:.2} µs for one vehicle alone); the service's cost \
         per input includes it",
        r.fleet_us,
        r.vehicles,
        if r.vehicles == 1 { "" } else { "s" },
        r.per_message,
        r.single_us
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_line_names_both_figures() {
        let l = line(&Reference {
            vehicles: 2000,
            per_message: 4,
            fleet_us: 1.456,
            single_us: 0.934,
        });
        assert!(
            l.contains("1.46 µs per IMU sample for 2000 vehicles taking 4-sample messages"),
            "{l}"
        );
        assert!(l.contains("0.93 µs for one vehicle alone"), "{l}");
    }
}
