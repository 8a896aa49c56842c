//! Golden-output regression on a short flight (the 20 s smoke scenario, fixed seeds, oracle
//! vision): the final pose and a sum over all outputs must not change unnoticed. If a deliberate
//! change moves them, re-run with `--nocapture`, check the accuracy is no worse, update the numbers.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

mod common;

use common::{Oracle, RunCfg, run, scenario};
use uavnav_core::FilterProfile;
use uavnav_sim::Flight;

/// (profile, final N, E, D m, final roll, pitch, yaw rad, Σ over outputs of |p|, m)
const GOLDEN: [(FilterProfile, [f64; 7]); 2] = [
    (
        FilterProfile::Eskf,
        [
            124.73946695735415,
            493.6292041526605,
            -13.47861738917613,
            -0.0025448030412375754,
            0.03477594765212705,
            1.7636580926252,
            1055575.5614753198,
        ],
    ),
    (
        FilterProfile::Paper,
        [
            124.72863037793395,
            493.7596004722294,
            -13.539369160963732,
            0.002821592292132191,
            0.031880210901532556,
            1.7655862554422166,
            1057306.5258021853,
        ],
    ),
];

#[test]
fn smoke_flight_golden_output() {
    let s = scenario("smoke", None);
    let flight = Flight::new(&s).unwrap();
    let mut failures = vec![];
    for (profile, want) in GOLDEN {
        let outs = run(
            &flight,
            &RunCfg::new(profile, true, Some(Oracle::default())),
        );
        let last = outs.last().unwrap();
        let sum: f64 = outs.iter().map(|o| o.pos_ned_m.norm()).sum();
        let got = [
            last.pos_ned_m.x,
            last.pos_ned_m.y,
            last.pos_ned_m.z,
            last.euler_rad.x,
            last.euler_rad.y,
            last.euler_rad.z,
            sum,
        ];
        eprintln!("{profile:?}: {got:?} ({} outputs)", outs.len());
        for (k, (g, w)) in got.iter().zip(want.iter()).enumerate() {
            let tol = if k == 6 {
                1e-6 * w.abs().max(1.0)
            } else {
                1e-6
            };
            if (g - w).abs() > tol {
                failures.push(format!("{profile:?} value {k}: got {g} want {w}"));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
