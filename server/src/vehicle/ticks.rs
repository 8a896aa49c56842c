//! An actor's health ticks: aligned to its start plus whole periods, so that an idle vehicle can
//! sleep past several of them and come back on the grid.

use std::time::Duration;

/// The health ticks of one actor: start + k * period.
#[derive(Debug)]
pub(crate) struct Ticks {
    start: tokio::time::Instant,
    period: Duration,
    /// The tick the timer is set for.
    pub(crate) scheduled: u64,
    /// The tick of the last report.
    pub(crate) reported: u64,
    /// The timer is set beyond the next period (the vehicle was idle at the last tick).
    pub(crate) idle: bool,
}

impl Ticks {
    pub(crate) fn new(start: tokio::time::Instant, period: Duration) -> Self {
        Self {
            start,
            period: period.max(Duration::from_millis(1)),
            scheduled: 0,
            reported: 0,
            idle: false,
        }
    }

    pub(crate) fn at(&self, k: u64) -> tokio::time::Instant {
        let ns = self.period.as_nanos().saturating_mul(u128::from(k));
        self.start + Duration::from_nanos(u64::try_from(ns).unwrap_or(u64::MAX / 2))
    }

    /// The tick `t` is in (the last one at or before it).
    pub(crate) fn index_at(&self, t: tokio::time::Instant) -> u64 {
        let since = t.saturating_duration_since(self.start).as_nanos();
        u64::try_from(since / self.period.as_nanos()).unwrap_or(u64::MAX / 2)
    }

    /// The first tick after `t`.
    pub(crate) fn next_after(&self, t: tokio::time::Instant) -> u64 {
        self.index_at(t) + 1
    }

    /// The first tick at or after `t`.
    pub(crate) fn index_at_or_after(&self, t: tokio::time::Instant) -> u64 {
        let k = self.index_at(t);
        if self.at(k) >= t { k } else { k + 1 }
    }
}

/// An idle vehicle (no message for a whole period, nothing held) reports its health once in this
/// many periods instead of every period: an idle fleet costs next to nothing, and a watcher
/// still sees each idle vehicle alive (10 s at the default period).
pub const IDLE_HEALTH_EVERY: u32 = 10;
