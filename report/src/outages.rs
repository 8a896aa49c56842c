//! GNSS outage windows derived from the data: where fixes stop for longer than a threshold.

/// Default minimum gap between fixes counted as an outage, ns (a 1–10 Hz receiver never skips
/// this long by itself).
pub const DEFAULT_MIN_GAP_NS: i64 = 2_000_000_000;

/// The `[start, end)` windows where consecutive GNSS fix times are more than `min_gap_ns` apart:
/// `start` is the last fix before the gap and `end` the first fix after it, so the estimator's
/// last output before `end` carries the whole coasting drift. Input order does not matter;
/// duplicate times are ignored.
pub fn gnss_outages(gnss_t_ns: &[i64], min_gap_ns: i64) -> Vec<(i64, i64)> {
    let mut t = gnss_t_ns.to_vec();
    t.sort_unstable();
    t.dedup();
    t.windows(2)
        .filter(|w| w[1] - w[0] > min_gap_ns)
        .map(|w| (w[0], w[1]))
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    const S: i64 = 1_000_000_000;

    #[test]
    fn regular_fixes_have_no_outage() {
        let t: Vec<i64> = (0..100).map(|k| k * S / 5).collect();
        assert!(gnss_outages(&t, DEFAULT_MIN_GAP_NS).is_empty());
    }

    #[test]
    fn gaps_longer_than_threshold_are_windows() {
        // 5 Hz, a 120 s hole after 10 s and a 3 s hole after 200 s, plus a 1.5 s hiccup
        let mut t: Vec<i64> = (0..=50).map(|k| k * S / 5).collect();
        t.extend((650..=1100).map(|k| k * S / 5));
        let dropped = |x: i64| (200 * S < x && x < 203 * S) || (100 * S < x && x < 101 * S + S / 2);
        t.retain(|&x| !dropped(x));
        let w = gnss_outages(&t, DEFAULT_MIN_GAP_NS);
        assert_eq!(w, vec![(10 * S, 130 * S), (200 * S, 203 * S)]);
    }

    #[test]
    fn unsorted_and_duplicate_input() {
        let t = [5 * S, 0, 0, S, 5 * S];
        assert_eq!(gnss_outages(&t, 2 * S), vec![(S, 5 * S)]);
        assert!(gnss_outages(&[], S).is_empty());
        assert!(gnss_outages(&[3], S).is_empty());
    }

    #[test]
    fn gap_equal_to_threshold_is_not_an_outage() {
        assert!(gnss_outages(&[0, 2 * S], 2 * S).is_empty());
        assert_eq!(gnss_outages(&[0, 2 * S + 1], 2 * S), vec![(0, 2 * S + 1)]);
    }
}
