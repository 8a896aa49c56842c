//! Plot-ready series: the time base, yaw unwrapping, decimation, y ranges and clipping.

use std::f64::consts::TAU;

use uavnav_core::rotation::wrap_pi;

/// Seconds since `t0_ns`.
pub fn seconds_since(t0_ns: i64, t_ns: i64) -> f64 {
    (t_ns - t0_ns) as f64 * 1e-9
}

/// Removes the ±π jumps of an angle sequence (rad) so a heading through north plots as a line.
/// Done at full rate, before decimation, so fast turns cannot alias.
pub fn unwrap_angles(angles: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(angles.len());
    let mut prev: Option<(f64, f64)> = None; // (raw, unwrapped)
    for &a in angles {
        let u = match prev {
            Some((raw, unwrapped)) if a.is_finite() && raw.is_finite() => {
                unwrapped + wrap_pi(a - raw)
            }
            _ => a,
        };
        out.push(u);
        prev = Some((a, u));
    }
    out
}

/// Shifts an unwrapped angle series by a whole number of turns so its first value lies within
/// ±π of `reference` (the truth at that time): estimate and truth then share one branch.
pub fn align_turns(series: &mut [f64], reference: f64) {
    let Some(&first) = series.first() else {
        return;
    };
    if !first.is_finite() || !reference.is_finite() {
        return;
    }
    let turns = ((first - reference) / TAU).round();
    if turns != 0.0 {
        series.iter_mut().for_each(|v| *v -= turns * TAU);
    }
}

/// Keeps every k-th point so at most `max_points` remain (the last point is always kept, so
/// the line reaches the end of the data).
pub fn decimate(points: &[(f64, f64)], max_points: usize) -> Vec<(f64, f64)> {
    let max_points = max_points.max(2);
    if points.len() <= max_points {
        return points.to_vec();
    }
    let stride = points.len().div_ceil(max_points - 1);
    let mut out: Vec<(f64, f64)> = points.iter().step_by(stride).copied().collect();
    if let Some(&last) = points.last()
        && out.last() != Some(&last)
    {
        out.push(last);
    }
    out
}

/// A closed interval `[lo, hi]` for an axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
}

impl Range {
    /// The hull of the finite values, or `None` if there are none.
    pub fn of(values: impl IntoIterator<Item = f64>) -> Option<Range> {
        values
            .into_iter()
            .filter(|v| v.is_finite())
            .fold(None, |acc: Option<Range>, v| {
                Some(match acc {
                    None => Range { lo: v, hi: v },
                    Some(r) => Range {
                        lo: r.lo.min(v),
                        hi: r.hi.max(v),
                    },
                })
            })
    }

    /// The hull of two optional ranges.
    pub fn union(a: Option<Range>, b: Option<Range>) -> Option<Range> {
        match (a, b) {
            (Some(a), Some(b)) => Some(Range {
                lo: a.lo.min(b.lo),
                hi: a.hi.max(b.hi),
            }),
            (a, None) => a,
            (None, b) => b,
        }
    }

    /// Widened by `fraction` of its span on each side; a degenerate range gets a unit-ish span
    /// so the axis still has ticks.
    pub fn padded(self, fraction: f64) -> Range {
        let span = self.hi - self.lo;
        let pad = if span > 1e-12 {
            span * fraction
        } else {
            0.5 * self.lo.abs().max(self.hi.abs()).max(1e-3)
        };
        Range {
            lo: self.lo - pad,
            hi: self.hi + pad,
        }
    }

    /// Whether `v` lies inside.
    pub fn contains(&self, v: f64) -> bool {
        v >= self.lo && v <= self.hi
    }
}

/// Splits a polyline into the runs of consecutive points that are finite and inside the
/// `x` × `y` box (the plotting library does not clip lines to the chart area, so out-of-range
/// stretches are left as gaps instead of being drawn over the axes).
pub fn visible_segments(points: &[(f64, f64)], x: Range, y: Range) -> Vec<Vec<(f64, f64)>> {
    let mut segments = Vec::new();
    let mut current = Vec::new();
    for &(t, v) in points {
        if x.contains(t) && y.contains(v) {
            current.push((t, v));
        } else if !current.is_empty() {
            segments.push(std::mem::take(&mut current));
        }
    }
    if !current.is_empty() {
        segments.push(current);
    }
    segments
}

/// The points whose time lies in `[lo, hi]`.
pub fn in_time(points: &[(f64, f64)], x: Range) -> impl Iterator<Item = &(f64, f64)> {
    points.iter().filter(move |(t, _)| x.contains(*t))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn unwrap_removes_jumps() {
        let raw = [3.0, 3.1, -3.1, -3.0, 3.1];
        let u = unwrap_angles(&raw);
        for w in u.windows(2) {
            assert!((w[1] - w[0]).abs() < 0.5, "{u:?}");
        }
        assert!((u[2] - (2.0 * PI - 3.1)).abs() < 1e-12);
    }

    #[test]
    fn align_moves_whole_turns() {
        let mut s = vec![2.0 * TAU + 0.1, 2.0 * TAU + 0.2];
        align_turns(&mut s, 0.0);
        assert!((s[0] - 0.1).abs() < 1e-12 && (s[1] - 0.2).abs() < 1e-12);
    }

    #[test]
    fn decimate_bounds_count_and_keeps_ends() {
        let p: Vec<(f64, f64)> = (0..50_000).map(|k| (k as f64, k as f64)).collect();
        let d = decimate(&p, 5000);
        assert!(d.len() <= 5001, "{}", d.len());
        assert_eq!(d.first(), p.first());
        assert_eq!(d.last(), p.last());
        assert_eq!(decimate(&p[..10], 5000).len(), 10);
    }

    #[test]
    fn segments_break_at_out_of_range_and_nan() {
        let p = [
            (0.0, 0.0),
            (1.0, 5.0),
            (2.0, 0.5),
            (3.0, f64::NAN),
            (4.0, 0.2),
        ];
        let y = Range { lo: -1.0, hi: 1.0 };
        let s = visible_segments(&p, Range { lo: 0.0, hi: 10.0 }, y);
        let expected = vec![vec![(0.0, 0.0)], vec![(2.0, 0.5)], vec![(4.0, 0.2)]];
        assert_eq!(s, expected);
        let s = visible_segments(&p, Range { lo: 1.0, hi: 3.0 }, y);
        assert_eq!(s, vec![vec![(2.0, 0.5)]]);
    }

    #[test]
    fn range_padding_and_degenerate() {
        let r = Range::of([1.0, 3.0, f64::NAN]).unwrap().padded(0.1);
        assert!((r.lo - 0.8).abs() < 1e-12 && (r.hi - 3.2).abs() < 1e-12);
        let d = Range::of([0.0]).unwrap().padded(0.1);
        assert!(d.hi > d.lo);
        assert!(Range::of([f64::NAN]).is_none());
    }
}
