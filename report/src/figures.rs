//! The figures: plot-ready series from (outputs, truth) and the panels of each PNG, mirroring
//! the paper's Fig. 2/3 (Euler angles against truth), Fig. 4 (NED velocity) and Fig. 5 (down
//! position with a zoom on the outage), plus attitude and horizontal-position errors.

use plotters::style::RGBColor;
use uavnav_core::Mode;
use uavnav_core::TruthSample;
use uavnav_core::rotation::euler_zyx;

use crate::accuracy::{SETTLE_NS, euler_error, truth_at};

use crate::Run;
use crate::plot::{Line, Panel, TRUTH_COLOR, run_color};
use crate::series::{Range, align_turns, in_time, seconds_since, unwrap_angles};

type Pts = Vec<(f64, f64)>;

/// Truth on the plotted window: Euler angles (deg, yaw unwrapped), NED velocity, down position.
#[derive(Debug, Default)]
struct TruthSeries {
    att_deg: [Pts; 3],
    vel_mps: [Pts; 3],
    down_m: Pts,
}

/// One run's series; outputs still initialising are left out (not yet a pose).
#[derive(Debug)]
struct RunSeries {
    label: String,
    color: RGBColor,
    att_deg: [Pts; 3],
    att_err_deg: [Pts; 3],
    att_3sigma_deg: [Pts; 3],
    vel_mps: [Pts; 3],
    down_m: Pts,
    h_err_m: Pts,
    h_3sigma_m: Pts,
}

/// Everything the figures draw, on one time base (seconds since the first output).
#[derive(Debug)]
pub struct FigureData {
    truth: TruthSeries,
    runs: Vec<RunSeries>,
    /// Shown time range, s.
    x: Range,
    /// Start of the "settled" part used to scale the axes, s.
    settle_s: f64,
    /// GNSS outages, s.
    bands: Vec<(f64, f64)>,
    /// What the runs are compared with, in legends and titles (`truth`, `reference`).
    against: String,
}

impl FigureData {
    /// Builds the series; `t0_ns`/`t_end_ns` bound the outputs of all runs.
    pub fn new(
        runs: &[Run],
        truth: &[TruthSample],
        outages: &[(i64, i64)],
        t0_ns: i64,
        t_end_ns: i64,
    ) -> Self {
        let truth_series = truth_series(truth, t0_ns, t_end_ns);
        let runs = runs
            .iter()
            .enumerate()
            .map(|(i, r)| run_series(r, i, truth, &truth_series, t0_ns))
            .collect();
        let end_s = seconds_since(t0_ns, t_end_ns);
        Self {
            truth: truth_series,
            runs,
            x: Range {
                lo: 0.0,
                hi: end_s.max(1e-3),
            },
            settle_s: SETTLE_NS as f64 * 1e-9,
            bands: outages
                .iter()
                .map(|&(a, b)| (seconds_since(t0_ns, a), seconds_since(t0_ns, b)))
                .collect(),
            against: "truth".into(),
        }
    }

    /// Names what the runs are compared with in legends and titles (default `truth`; a
    /// reference that is not truth is called so).
    pub fn against(mut self, short: &str) -> Self {
        self.against = short.to_owned();
        self
    }
}

fn truth_series(truth: &[TruthSample], t0_ns: i64, t_end_ns: i64) -> TruthSeries {
    let window: Vec<&TruthSample> = truth
        .iter()
        .filter(|s| s.t_ns >= t0_ns && s.t_ns <= t_end_ns)
        .collect();
    let t: Vec<f64> = window
        .iter()
        .map(|s| seconds_since(t0_ns, s.t_ns))
        .collect();
    let euler: Vec<_> = window.iter().map(|s| euler_zyx(&s.nav_from_body)).collect();
    let yaw = unwrap_angles(&euler.iter().map(|e| e.z).collect::<Vec<_>>());
    let mut out = TruthSeries::default();
    for (i, s) in window.iter().enumerate() {
        let angles = [euler[i].x, euler[i].y, yaw[i]];
        for (k, angle) in angles.iter().enumerate() {
            out.att_deg[k].push((t[i], angle.to_degrees()));
            out.vel_mps[k].push((t[i], s.vel_ned_mps[k]));
        }
        out.down_m.push((t[i], s.pos_ned_m.z));
    }
    out
}

fn run_series(
    run: &Run,
    index: usize,
    truth: &[TruthSample],
    truth_series: &TruthSeries,
    t0_ns: i64,
) -> RunSeries {
    let outs: Vec<_> = run
        .outputs
        .iter()
        .filter(|o| o.health.mode != Mode::Initialising)
        .collect();
    let mut s = RunSeries {
        label: run.label.clone(),
        color: run_color(index),
        att_deg: Default::default(),
        att_err_deg: Default::default(),
        att_3sigma_deg: Default::default(),
        vel_mps: Default::default(),
        down_m: Vec::new(),
        h_err_m: Vec::new(),
        h_3sigma_m: Vec::new(),
    };
    let mut yaw = unwrap_angles(&outs.iter().map(|o| o.euler_rad.z).collect::<Vec<_>>());
    if let Some(first) = outs.first() {
        let t_first = seconds_since(t0_ns, first.t_ns);
        if let Some(reference) = nearest_value(&truth_series.att_deg[2], t_first) {
            align_turns(&mut yaw, reference.to_radians());
        }
    }
    for (i, o) in outs.iter().enumerate() {
        let t = seconds_since(t0_ns, o.t_ns);
        let angles = [o.euler_rad.x, o.euler_rad.y, yaw[i]];
        let pv = o.health.mode.has_position();
        for (k, angle) in angles.iter().enumerate() {
            s.att_deg[k].push((t, angle.to_degrees()));
            if pv {
                s.vel_mps[k].push((t, o.vel_ned_mps[k]));
            }
        }
        if pv {
            s.down_m.push((t, o.pos_ned_m.z));
        }
        let Some(tr) = truth_at(truth, o.t_ns) else {
            continue;
        };
        let e = euler_error(&o.nav_from_body, &tr.nav_from_body);
        for k in 0..3 {
            s.att_err_deg[k].push((t, e[k].to_degrees()));
            s.att_3sigma_deg[k].push((t, 3.0 * o.sigma_att_rad[k].to_degrees()));
        }
        if pv {
            s.h_err_m
                .push((t, (o.pos_ned_m - tr.pos_ned_m).xy().norm()));
            s.h_3sigma_m.push((t, 3.0 * o.sigma_pos_ned_m.xy().norm()));
        }
    }
    s
}

/// The value of the sample nearest in time (series sorted by time).
fn nearest_value(points: &[(f64, f64)], t: f64) -> Option<f64> {
    let i = points.partition_point(|p| p.0 < t);
    let candidates = [i.checked_sub(1), (i < points.len()).then_some(i)];
    candidates
        .into_iter()
        .flatten()
        .min_by(|&a, &b| (points[a].0 - t).abs().total_cmp(&(points[b].0 - t).abs()))
        .map(|k| points[k].1)
}

/// Values of the settled part (t ≥ settle) of `points`, or all of them when none is settled
/// (short recordings): initial transients would otherwise squash the axis.
fn settled(points: &[(f64, f64)], settle_s: f64) -> impl Iterator<Item = f64> + '_ {
    let any = points.iter().any(|p| p.0 >= settle_s);
    points
        .iter()
        .filter(move |p| !any || p.0 >= settle_s)
        .map(|p| p.1)
}

fn fallback(r: Option<Range>) -> Range {
    r.unwrap_or(Range { lo: -1.0, hi: 1.0 })
}

impl FigureData {
    fn truth_line(&self, points: &Pts) -> Line {
        Line {
            label: Some(self.against.clone()),
            color: TRUTH_COLOR,
            dashed: false,
            width: 1,
            points: points.clone(),
        }
    }

    /// Truth and every run of one quantity, y scaled on truth ∪ settled estimates.
    fn value_panel(
        &self,
        title: &str,
        y_label: &str,
        truth: &Pts,
        of_run: impl Fn(&RunSeries) -> &Pts,
        legend: bool,
    ) -> Panel {
        let mut y = Range::of(truth.iter().map(|p| p.1));
        let mut lines = vec![self.truth_line(truth)];
        for r in &self.runs {
            let pts = of_run(r);
            y = Range::union(y, Range::of(settled(pts, self.settle_s)));
            lines.push(Line {
                label: Some(r.label.clone()),
                color: r.color,
                dashed: false,
                width: 2,
                points: pts.clone(),
            });
        }
        Panel {
            title: title.into(),
            y_label: y_label.into(),
            x: self.x,
            y: fallback(y).padded(0.05),
            lines,
            bands: self.bands.clone(),
            legend,
        }
    }

    /// Fig. 2/3: roll, pitch and yaw against truth.
    pub fn attitude(&self) -> Vec<Panel> {
        let names = ["Roll φ", "Pitch θ", "Yaw ψ (unwrapped)"];
        let units = ["roll [deg]", "pitch [deg]", "yaw [deg]"];
        (0..3)
            .map(|k| {
                self.value_panel(
                    names[k],
                    units[k],
                    &self.truth.att_deg[k],
                    |r| &r.att_deg[k],
                    k == 0,
                )
            })
            .collect()
    }

    /// Roll, pitch and yaw errors with the stated ±3σ (dashed), scaled on the settled errors.
    pub fn attitude_error(&self) -> Vec<Panel> {
        let names = ["Roll error", "Pitch error", "Yaw error"];
        (0..3)
            .map(|k| {
                let mut lines = Vec::new();
                let (mut y, mut sigma) = (None, None);
                for r in &self.runs {
                    y = Range::union(y, Range::of(settled(&r.att_err_deg[k], self.settle_s)));
                    sigma = Range::union(
                        sigma,
                        Range::of(settled(&r.att_3sigma_deg[k], self.settle_s)),
                    );
                    lines.push(Line {
                        label: Some(r.label.clone()),
                        color: r.color,
                        dashed: false,
                        width: 2,
                        points: r.att_err_deg[k].clone(),
                    });
                    for sign in [1.0, -1.0] {
                        lines.push(Line {
                            label: (sign > 0.0).then(|| format!("±3σ {}", r.label)),
                            color: r.color,
                            dashed: true,
                            width: 1,
                            points: r.att_3sigma_deg[k]
                                .iter()
                                .map(|&(t, v)| (t, sign * v))
                                .collect(),
                        });
                    }
                }
                // scaled on the errors; the 3σ bounds join the axis unless they dwarf the errors
                let err = fallback(y).lo.abs().max(fallback(y).hi.abs()).max(1e-3);
                let bound = sigma.map_or(0.0, |r| r.hi).min(4.0 * err);
                let m = err.max(bound) * 1.25;
                Panel {
                    title: format!(
                        "{} (estimate − {}; axis scaled after {:.0} s)",
                        names[k], self.against, self.settle_s
                    ),
                    y_label: "error [deg]".into(),
                    x: self.x,
                    y: Range { lo: -m, hi: m },
                    lines,
                    bands: self.bands.clone(),
                    legend: k == 0,
                }
            })
            .collect()
    }

    /// Fig. 4: north, east and down velocity against truth.
    pub fn velocity(&self) -> Vec<Panel> {
        let names = ["North velocity", "East velocity", "Down velocity"];
        let units = ["v north [m/s]", "v east [m/s]", "v down [m/s]"];
        (0..3)
            .map(|k| {
                self.value_panel(
                    names[k],
                    units[k],
                    &self.truth.vel_mps[k],
                    |r| &r.vel_mps[k],
                    k == 0,
                )
            })
            .collect()
    }

    /// Fig. 5: down position over the whole run, then one zoom per outage (at most three).
    pub fn position_down(&self) -> Vec<Panel> {
        let mut panels = vec![self.value_panel(
            "Down position",
            "down [m]",
            &self.truth.down_m,
            |r| &r.down_m,
            true,
        )];
        for (n, &(a, b)) in self.bands.iter().take(3).enumerate() {
            let margin = 0.1 * (b - a).max(1e-3);
            let x = Range {
                lo: a - margin,
                hi: b + margin,
            };
            let mut y = Range::of(in_time(&self.truth.down_m, x).map(|p| p.1));
            for r in &self.runs {
                y = Range::union(y, Range::of(in_time(&r.down_m, x).map(|p| p.1)));
            }
            let mut panel = self.value_panel(
                &format!(
                    "Down position, zoom on GNSS outage {} ({a:.1}–{b:.1} s)",
                    n + 1
                ),
                "down [m]",
                &self.truth.down_m,
                |r| &r.down_m,
                false,
            );
            panel.x = x;
            panel.y = fallback(y).padded(0.1);
            panels.push(panel);
        }
        panels
    }

    /// Horizontal position error with the stated 3σ (dashed).
    pub fn horizontal_error(&self) -> Vec<Panel> {
        let mut lines = Vec::new();
        let mut y = None;
        for r in &self.runs {
            y = Range::union(y, Range::of(settled(&r.h_err_m, self.settle_s)));
            lines.push(Line {
                label: Some(r.label.clone()),
                color: r.color,
                dashed: false,
                width: 2,
                points: r.h_err_m.clone(),
            });
            lines.push(Line {
                label: Some(format!("3σ {}", r.label)),
                color: r.color,
                dashed: true,
                width: 1,
                points: r.h_3sigma_m.clone(),
            });
        }
        let hi = fallback(y).hi.max(1e-2) * 1.2;
        vec![Panel {
            title: "Horizontal position error (grey: GNSS outages)".into(),
            y_label: "error [m]".into(),
            x: self.x,
            y: Range { lo: 0.0, hi },
            lines,
            bands: self.bands.clone(),
            legend: true,
        }]
    }
}
