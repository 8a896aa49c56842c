//! Prints the error against truth every few seconds for one run (a debugging aid).
//!
//! `cargo run --release -p uavnav-estimator --example trace -- SCENARIO eskf|paper [novision] [nognss]`
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

#[path = "../tests/common/mod.rs"]
mod common;

use common::{Oracle, RunCfg, run, scenario};
use uavnav_core::FilterProfile;
use uavnav_core::rotation::euler_error;
use uavnav_core::truth::truth_at;
use uavnav_sim::Flight;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let name = args
        .first()
        .cloned()
        .unwrap_or_else(|| "paper-small-lever".into());
    let profile: FilterProfile = args
        .get(1)
        .map(|s| s.parse().expect("profile"))
        .unwrap_or_default();
    let vision = !args.iter().any(|a| a == "novision");
    let gnss = !args.iter().any(|a| a == "nognss");
    let s = scenario(&name, None);
    let flight = Flight::new(&s).expect("flight");
    let outs = run(
        &flight,
        &RunCfg::new(profile, gnss, vision.then(Oracle::default)),
    );
    let t0 = s.t0_ns;
    for o in outs.iter().step_by(1000) {
        let t = truth_at(flight.truth(), o.t_ns).expect("truth");
        let ea = euler_error(&o.nav_from_body, &t.nav_from_body).map(f64::to_degrees);
        let sa = o.sigma_att_rad.map(f64::to_degrees);
        let ep = o.pos_ned_m - t.pos_ned_m;
        let ev = o.vel_ned_mps - t.vel_ned_mps;
        let h = &o.health;
        println!(
            "t={:6.1} {:?} att_err=[{:6.3} {:6.3} {:6.3}]±[{:5.3} {:5.3} {:5.3}] pos_err=[{:7.2} {:7.2} {:7.2}]±[{:5.2} {:5.2}] vel_err=[{:6.3} {:6.3} {:6.3}] tr gp={:.2} gv={:.2} vr={:.2} vt={:.2} rej={}/{}/{}/{}",
            (o.t_ns - t0) as f64 * 1e-9,
            h.mode,
            ea.x,
            ea.y,
            ea.z,
            sa.x,
            sa.y,
            sa.z,
            ep.x,
            ep.y,
            ep.z,
            o.sigma_pos_ned_m.x,
            o.sigma_pos_ned_m.y,
            ev.x,
            ev.y,
            ev.z,
            h.gnss_pos.test_ratio,
            h.gnss_vel.test_ratio,
            h.vision_rot.test_ratio,
            h.vision_trans.test_ratio,
            h.gnss_pos.rejected,
            h.gnss_vel.rejected,
            h.vision_rot.rejected,
            h.vision_trans.rejected,
        );
    }
}
