//! The ingest time gate: per vehicle, it decides at ingest whether a sample is late, a
//! duplicate, going backwards or from the far future, and when a vehicle's clock jumped (a
//! resync), so a sender learns it at once in its ack. The gate's state lives in the vehicle's
//! shared face (the `gate` of [`VehicleShared`](crate::vehicle::VehicleShared)); the
//! [`Ingestor`](crate::ingest::Ingestor) runs it.

use crate::vehicle::{INPUT_KINDS, InputKind};

/// Why the time gate refused a sample.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GateRefusal {
    /// Older than the reorder window allows.
    Late(String),
    /// The same time as the previous sample of its kind.
    Duplicate(String),
    /// A magnetometer or barometer sample older than the previous one of its kind: the sensor's
    /// clock went backwards.
    Backwards(String),
    /// Too far ahead of the vehicle's stream time.
    Future(String),
}

impl GateRefusal {
    /// The reason text.
    pub fn text(&self) -> &str {
        match self {
            GateRefusal::Late(s)
            | GateRefusal::Duplicate(s)
            | GateRefusal::Backwards(s)
            | GateRefusal::Future(s) => s,
        }
    }
}

/// Whether a kind's samples must come in increasing time order. Magnetometer and barometer samples
/// arrive one per message from one sensor, so an older sample means the sensor's clock jumped back
/// (the estimator would refuse it silently behind the window); IMU batches, fixes and frames may
/// arrive out of order within the reorder window (several links, retransmissions).
fn strictly_ordered(kind: InputKind) -> bool {
    matches!(kind, InputKind::Mag | InputKind::Baro)
}

/// Largest step between two IMU samples of a run that may become the new stream (an IMU runs at
/// 1 Hz at least), ns.
const RUN_MAX_STEP_NS: i64 = 1_000_000_000;

/// The time gate's limits (from `[vehicles]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GateLimits {
    /// The reorder window: a sample older than the stream time by more is late, ns.
    pub window_ns: i64,
    /// How far ahead of the stream time a sample may be (plus the stream's silence), ns.
    pub max_future_ns: i64,
    /// Consecutive consistent IMU samples far from the stream time that make it a new stream...
    pub resync_samples: u32,
    /// ...arriving over at least this much wall time, ns (a burst of retransmitted old data is
    /// not a restarted clock: a new stream comes in real time).
    pub resync_wall_ns: i64,
}

/// What the gate did with an admitted sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admitted {
    /// Admitted into the running stream.
    Stream,
    /// The sample completed a run of samples far from the stream time: the vehicle's clock
    /// jumped. The gate started a new stream with it; the vehicle must be reset before it.
    Resync(crate::metrics::Direction),
}

/// IMU samples refused for being far from the stream time, consecutive and consistent among
/// themselves: a candidate new stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Run {
    last_ns: i64,
    len: u32,
    /// Service wall clock when the run's first sample arrived.
    first_wall_ns: i64,
}

/// Per-vehicle timestamp bookkeeping done at ingest, so a sender learns at once (in its ack)
/// that a sample is late, duplicated or from the far future. It is the one place where late and
/// future are decided (the actor's reorder window only guards its own invariant).
///
/// The stream time is the newest sample admitted, and a sample is admitted only within
/// `max_future_ns` (plus the stream's silence) of it, so a few forged timestamps cannot move it
/// far: the vehicle's own samples, the majority, keep it. A vehicle whose clock really jumped
/// sends a consistent run of far samples; after `resync_samples` of them, over at least
/// `resync_wall_ns` of wall time, the gate starts a new stream ([`Admitted::Resync`]).
#[derive(Debug, Default)]
pub struct TimeGate {
    newest_ns: Option<i64>,
    /// Service wall clock when `newest_ns` was admitted.
    newest_wall_ns: i64,
    last_ns: [Option<i64>; INPUT_KINDS],
    run: Option<Run>,
}

impl TimeGate {
    /// Checks `t_ns` for `kind`, arriving at service wall time `wall_ns`, and records it when
    /// admitted.
    ///
    /// "Too far ahead" is judged against the stream time *plus the wall time elapsed since it
    /// moved*: a vehicle whose link dropped for a minute resumes a minute later in its own time,
    /// and must be taken back, while a timestamp from the far future in a running stream is not.
    pub fn admit(
        &mut self,
        kind: InputKind,
        t_ns: i64,
        wall_ns: i64,
        limits: GateLimits,
        field: impl Fn() -> String,
    ) -> Result<Admitted, GateRefusal> {
        if let Some(newest) = self.newest_ns {
            let silent_ns = wall_ns.saturating_sub(self.newest_wall_ns).max(0);
            let limit_ns = limits.max_future_ns.saturating_add(silent_ns);
            let ahead = i128::from(t_ns) - i128::from(newest);
            let refusal = if ahead > i128::from(limit_ns) {
                Some(GateRefusal::Future(format!(
                    "{}: t_ns {t_ns} is {:.3} s ahead of the vehicle's stream time (limit {:.3} s: {:.3} s + {:.3} s without input)",
                    field(),
                    ahead as f64 * 1e-9,
                    limit_ns as f64 * 1e-9,
                    limits.max_future_ns as f64 * 1e-9,
                    silent_ns as f64 * 1e-9
                )))
            } else if -ahead > i128::from(limits.window_ns) {
                Some(GateRefusal::Late(format!(
                    "{}: t_ns {t_ns} is {:.3} s older than the vehicle's stream time (reorder window {:.3} s)",
                    field(),
                    -ahead as f64 * 1e-9,
                    limits.window_ns as f64 * 1e-9
                )))
            } else {
                None
            };
            if let Some(refusal) = refusal {
                let far = ahead.abs() > i128::from(limits.max_future_ns);
                if kind == InputKind::Imu {
                    if far && self.extend_run(t_ns, wall_ns, limits) {
                        let direction = if ahead > 0 {
                            crate::metrics::Direction::Ahead
                        } else {
                            crate::metrics::Direction::Back
                        };
                        self.clear();
                        self.record(kind, t_ns, wall_ns);
                        return Ok(Admitted::Resync(direction));
                    }
                    if !far {
                        self.run = None;
                    }
                }
                return Err(refusal);
            }
        }
        let last = self.last_ns[kind as usize];
        if last == Some(t_ns) {
            return Err(GateRefusal::Duplicate(format!(
                "{}: duplicate t_ns {t_ns}",
                field()
            )));
        }
        if let Some(last) = last.filter(|&l| strictly_ordered(kind) && t_ns < l) {
            return Err(GateRefusal::Backwards(format!(
                "{}: time went backwards: t_ns {t_ns} is {:.6} s before the previous {} sample ({last})",
                field(),
                (last - t_ns) as f64 * 1e-9,
                kind.field()
            )));
        }
        if kind == InputKind::Imu {
            // The stream goes on: whatever far samples came before were not a new clock.
            self.run = None;
        }
        self.record(kind, t_ns, wall_ns);
        Ok(Admitted::Stream)
    }

    /// Records an admitted sample.
    fn record(&mut self, kind: InputKind, t_ns: i64, wall_ns: i64) {
        self.last_ns[kind as usize] = Some(t_ns);
        if self.newest_ns.is_none_or(|n| t_ns > n) {
            self.newest_ns = Some(t_ns);
            self.newest_wall_ns = wall_ns;
        }
    }

    /// Adds a far IMU sample to the candidate run (a sample that does not follow the run's last
    /// one by a plausible IMU step starts a new run); returns whether the run is now a new stream:
    /// long enough, in samples and in wall time.
    fn extend_run(&mut self, t_ns: i64, wall_ns: i64, limits: GateLimits) -> bool {
        let run = match self.run {
            Some(r) if t_ns > r.last_ns && t_ns - r.last_ns <= RUN_MAX_STEP_NS => Run {
                last_ns: t_ns,
                len: r.len.saturating_add(1),
                first_wall_ns: r.first_wall_ns,
            },
            _ => Run {
                last_ns: t_ns,
                len: 1,
                first_wall_ns: wall_ns,
            },
        };
        self.run = Some(run);
        run.len >= limits.resync_samples
            && wall_ns.saturating_sub(run.first_wall_ns) >= limits.resync_wall_ns
    }

    /// The stream time (the newest admitted sample), if any.
    pub fn stream_ns(&self) -> Option<i64> {
        self.newest_ns
    }

    /// Forgets the stream (after a reset).
    pub fn clear(&mut self) {
        *self = Self::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::Direction;

    /// Runs of 4 samples over 100 (wall) ns make a new stream.
    fn limits(window_ns: i64, max_future_ns: i64) -> GateLimits {
        GateLimits {
            window_ns,
            max_future_ns,
            resync_samples: 4,
            resync_wall_ns: 100,
        }
    }

    fn ok(r: Result<Admitted, GateRefusal>) -> bool {
        r == Ok(Admitted::Stream)
    }

    #[test]
    fn gate_refuses_late_duplicate_and_future() {
        let mut g = TimeGate::default();
        let l = limits(100, 1_000);
        assert!(ok(g.admit(InputKind::Imu, 1_000, 0, l, || "imu".into())));
        assert!(matches!(
            g.admit(InputKind::Imu, 1_000, 0, l, || "imu".into()),
            Err(GateRefusal::Duplicate(_))
        ));
        assert!(
            ok(g.admit(InputKind::Gnss, 950, 0, l, || "gnss".into())),
            "within the window"
        );
        assert!(matches!(
            g.admit(InputKind::Gnss, 800, 0, l, || "gnss".into()),
            Err(GateRefusal::Late(_))
        ));
        assert!(matches!(
            g.admit(InputKind::Imu, 3_000, 0, l, || "imu".into()),
            Err(GateRefusal::Future(_))
        ));
        assert!(ok(g.admit(InputKind::Imu, 1_900, 0, l, || "imu".into())));
    }

    #[test]
    fn gate_refuses_mag_and_baro_going_backwards_but_not_imu() {
        let mut g = TimeGate::default();
        let l = limits(100, 1_000);
        for kind in [InputKind::Mag, InputKind::Baro, InputKind::Imu] {
            assert!(ok(g.admit(kind, 1_000, 0, l, || "x".into())));
        }
        let e = g.admit(InputKind::Mag, 990, 0, l, || "mag".into());
        assert!(
            matches!(e, Err(GateRefusal::Backwards(ref m)) if m.starts_with("mag: time went backwards")),
            "{e:?}"
        );
        assert!(matches!(
            g.admit(InputKind::Baro, 999, 0, l, || "baro".into()),
            Err(GateRefusal::Backwards(_))
        ));
        assert!(
            ok(g.admit(InputKind::Imu, 990, 0, l, || "imu".into())),
            "IMU may be reordered within the window"
        );
        assert!(ok(g.admit(InputKind::Mag, 1_010, 0, l, || "mag".into())));
    }

    #[test]
    fn gate_takes_a_stream_back_after_a_silence_as_long_as_the_jump() {
        let mut g = TimeGate::default();
        let l = limits(20_000_000, 10_000_000_000); // 20 ms window, 10 s ahead at most
        let s = 1_000_000_000i64;
        assert!(ok(g.admit(InputKind::Imu, 100 * s, 0, l, || "imu".into())));
        // 60 s later in the vehicle's time, but only 1 s later on the wall clock: refused...
        let err = g.admit(InputKind::Imu, 160 * s, s, l, || "imu".into());
        assert!(
            matches!(err, Err(GateRefusal::Future(ref m)) if m.contains("without input")),
            "{err:?}"
        );
        // ...after 55 s of silence it is a link that came back: taken.
        assert!(ok(
            g.admit(InputKind::Imu, 160 * s, 55 * s, l, || "imu".into())
        ));
        // A running stream still cannot jump ahead.
        let err = g.admit(InputKind::Imu, 200 * s, 55 * s + 5_000_000, l, || {
            "imu".into()
        });
        assert!(matches!(err, Err(GateRefusal::Future(_))), "{err:?}");
    }

    /// A few far samples, even in a row, do not move the stream; the stream's own samples go on.
    #[test]
    fn a_few_far_samples_cannot_poison_the_stream() {
        let mut g = TimeGate::default();
        let l = limits(20, 1_000);
        let mut t = 10_000;
        for _ in 0..10 {
            assert!(ok(g.admit(InputKind::Imu, t, 0, l, || "imu".into())));
            t += 5;
        }
        // Three forged samples far ahead (fewer than resync_samples) and one far behind.
        for f in [t + 9_900, t + 9_905, t + 9_910, 5] {
            assert!(g.admit(InputKind::Imu, f, 0, l, || "imu".into()).is_err());
        }
        assert_eq!(g.stream_ns(), Some(t - 5));
        for _ in 0..10 {
            assert!(ok(g.admit(InputKind::Imu, t, 0, l, || "imu".into())));
            t += 5;
        }
        // Far samples interleaved with the stream never make a run.
        for k in 0..20 {
            let _ = g.admit(InputKind::Imu, 1_000_000 + k, 0, l, || "imu".into());
            assert!(ok(g.admit(InputKind::Imu, t, 0, l, || "imu".into())));
            t += 5;
        }
    }

    /// A first sample at i64::MAX, then the real stream: the real stream wins after a run.
    #[test]
    fn a_far_first_sample_is_outvoted_by_the_stream() {
        let mut g = TimeGate::default();
        let l = limits(20, 1_000);
        assert!(ok(g.admit(InputKind::Imu, i64::MAX, 0, l, || "imu".into())));
        let mut results = Vec::new();
        for k in 0..6 {
            let (t, wall) = (1_000 + 5 * k, 50 * k);
            results.push(g.admit(InputKind::Imu, t, wall, l, || "imu".into()));
        }
        let late = |r: &Result<Admitted, GateRefusal>| matches!(r, Err(GateRefusal::Late(_)));
        assert!(results[..3].iter().all(late), "{results:?}");
        assert_eq!(results[3], Ok(Admitted::Resync(Direction::Back)));
        assert!(results[4..].iter().all(|r| ok(r.clone())));
        assert_eq!(g.stream_ns(), Some(1_025));
    }

    /// A drone that reboots: its clock restarts near zero and runs on, in real time; a burst of
    /// old data resent by a client is not a restarted clock.
    #[test]
    fn a_restarted_clock_is_taken_back_but_not_a_burst_of_old_data() {
        let mut g = TimeGate::default();
        let l = limits(20_000_000, 1_000_000_000);
        let s = 1_000_000_000i64;
        let imu = |g: &mut TimeGate, t: i64, wall: i64| {
            g.admit(InputKind::Imu, t, wall, l, || "imu".into())
        };
        for k in 0..100 {
            assert!(ok(imu(&mut g, 3600 * s + k * 5_000_000, 0)));
        }
        // Old data, resent in a burst: refused as late, no resync.
        for k in 0..50 {
            let r = imu(&mut g, 3590 * s + k * 5_000_000, 1_000);
            assert!(matches!(r, Err(GateRefusal::Late(_))), "{r:?}");
        }
        assert!(ok(imu(&mut g, 3600 * s + 500_000_000, 1_000)));
        // The reboot's stream, in real time.
        let mut resynced = 0;
        for k in 0..100 {
            match imu(&mut g, s + k * 5_000_000, s + k * 5_000_000) {
                Ok(Admitted::Resync(Direction::Back)) => resynced += 1,
                Ok(Admitted::Stream) => assert_eq!(resynced, 1, "admitted after the resync"),
                r => assert!(k < 3, "sample {k}: {r:?}"),
            }
        }
        assert_eq!(resynced, 1);
        // A forward clock jump (without the silence that would explain it) is taken the same way.
        let mut resynced = 0;
        for k in 0..10 {
            let (t, wall) = (7200 * s + k * 5_000_000, 2 * s + k * 5_000_000);
            if imu(&mut g, t, wall) == Ok(Admitted::Resync(Direction::Ahead)) {
                resynced += 1;
            }
        }
        assert_eq!(resynced, 1);
    }
}
