//! A bounded reorder window: items go in in any order and come out in timestamp order once the
//! newest timestamp seen is more than the window ahead of them.
//!
//! Ties in time are broken by kind (`SensorEvent::rank`: IMU, GNSS, magnetometer, barometer, camera;
//! a measurement at `t` is fused after the IMU has propagated to `t`, and the dataset reader's merge
//! breaks ties the same way) and then by arrival order, so the output is deterministic.

use std::collections::VecDeque;

/// Why an item was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    /// Older than what was already released: fusing it would break time order.
    Late,
    /// Same time and kind as an item already buffered.
    Duplicate,
}

/// The order of items: time, then kind, then arrival.
type Key = (i64, u8, u64);

/// The reorder buffer. `K` is a small ordinal that breaks ties between kinds.
///
/// A sorted ring rather than a tree: inputs nearly always arrive in order, so an insert is a push at
/// the back, a release a pop at the front, and an out-of-order insert shifts only the few items of
/// the window behind it (a B-tree shifts its leaf's items on every release instead).
#[derive(Debug)]
pub struct ReorderBuffer<T> {
    window_ns: i64,
    items: VecDeque<(Key, T)>,
    newest_ns: Option<i64>,
    released_ns: Option<i64>,
    seq: u64,
    capacity: usize,
}

impl<T> ReorderBuffer<T> {
    /// A buffer holding back `window_ns` of sensor time and at most `capacity` items (beyond it the
    /// oldest items are released early, so memory stays bounded whatever the input).
    pub fn new(window_ns: i64, capacity: usize) -> Self {
        Self {
            window_ns: window_ns.max(0),
            items: VecDeque::new(),
            newest_ns: None,
            released_ns: None,
            seq: 0,
            capacity: capacity.max(1),
        }
    }

    /// Inserts an item of `kind` at `t_ns`.
    pub fn push(&mut self, t_ns: i64, kind: u8, item: T) -> Result<(), Refused> {
        if self.released_ns.is_some_and(|r| t_ns < r) {
            return Err(Refused::Late);
        }
        self.seq += 1;
        let key = (t_ns, kind, self.seq);
        // Where the key goes: after every item that sorts before it (all of them, usually).
        let at = match self.items.back() {
            Some((k, _)) if *k > key => self.items.partition_point(|(k, _)| *k < key),
            _ => self.items.len(),
        };
        // A duplicate (same time and kind) sorts just before the key (its arrival is older).
        if at > 0 && self.items[at - 1].0.0 == t_ns && self.items[at - 1].0.1 == kind {
            return Err(Refused::Duplicate);
        }
        self.items.insert(at, (key, item));
        self.newest_ns = Some(self.newest_ns.map_or(t_ns, |n| n.max(t_ns)));
        Ok(())
    }

    /// The next item whose hold time has passed (or that overflows the capacity), oldest first.
    pub fn pop_ready(&mut self) -> Option<(i64, T)> {
        let newest = self.newest_ns?;
        let ((t, _, _), _) = self.items.front()?;
        let due = *t <= newest.saturating_sub(self.window_ns);
        if due || self.items.len() > self.capacity {
            return self.pop_first();
        }
        None
    }

    /// The oldest item regardless of the window (for flushing an idle or stopping vehicle).
    pub fn pop_first(&mut self) -> Option<(i64, T)> {
        let ((t, _, _), item) = self.items.pop_front()?;
        self.released_ns = Some(self.released_ns.map_or(t, |r| r.max(t)));
        Some((t, item))
    }

    /// Items waiting.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// Whether nothing waits.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// Forgets everything, including the release watermark (after an estimator reset).
    pub fn clear(&mut self) {
        self.items.clear();
        self.newest_ns = None;
        self.released_ns = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn holds_for_the_window_then_releases_in_order() {
        let mut b = ReorderBuffer::new(10, 100);
        b.push(5, 0, 'a').unwrap();
        b.push(3, 1, 'b').unwrap();
        assert_eq!(b.pop_ready(), None);
        b.push(14, 0, 'c').unwrap();
        assert_eq!(b.pop_ready(), Some((3, 'b')));
        assert_eq!(b.pop_ready(), None, "5 > 14 - 10");
        b.push(15, 0, 'd').unwrap();
        assert_eq!(b.pop_ready(), Some((5, 'a')));
        assert_eq!(b.push(4, 1, 'x'), Err(Refused::Late));
        assert_eq!(b.push(15, 0, 'y'), Err(Refused::Duplicate));
        assert_eq!(b.push(15, 1, 'z'), Ok(()));
    }

    #[test]
    fn ties_go_by_kind_then_arrival() {
        use uavnav_core::{BaroSample, MagSample, SensorEvent};
        let mag = SensorEvent::Mag(MagSample {
            t_ns: 7,
            field_t: nalgebra::Vector3::zeros(),
        });
        let baro = SensorEvent::Baro(BaroSample {
            t_ns: 7,
            pressure_pa: 1e5,
            temperature_degc: None,
        });
        let mut b = ReorderBuffer::new(0, 100);
        b.push(7, 4, "cam").unwrap();
        b.push(7, baro.rank(), "baro").unwrap();
        b.push(7, 0, "imu").unwrap();
        b.push(7, mag.rank(), "mag").unwrap();
        b.push(7, 1, "gnss").unwrap();
        let out: Vec<_> = std::iter::from_fn(|| b.pop_first())
            .map(|(_, x)| x)
            .collect();
        assert_eq!(out, ["imu", "gnss", "mag", "baro", "cam"]);
        // The service's kinds carry the same ranks.
        use crate::vehicle::InputKind;
        assert_eq!(InputKind::Mag as u8, mag.rank());
        assert_eq!(InputKind::Baro as u8, baro.rank());
    }

    #[test]
    fn out_of_order_duplicates_are_found() {
        let mut b = ReorderBuffer::new(100, 100);
        for t in [10, 30, 20, 40] {
            b.push(t, 0, t).unwrap();
        }
        assert_eq!(b.push(20, 0, 0), Err(Refused::Duplicate));
        assert_eq!(b.push(30, 0, 0), Err(Refused::Duplicate));
        assert_eq!(b.push(20, 1, 21), Ok(()));
        assert_eq!(b.push(25, 0, 25), Ok(()));
        let out: Vec<_> = std::iter::from_fn(|| b.pop_first())
            .map(|(_, x)| x)
            .collect();
        assert_eq!(out, [10, 20, 21, 25, 30, 40]);
    }

    #[test]
    fn capacity_bounds_memory() {
        let mut b = ReorderBuffer::new(i64::MAX / 4, 3);
        for t in 0..10 {
            b.push(t, 0, t).unwrap();
            while b.pop_ready().is_some() {}
            assert!(b.len() <= 3);
        }
    }

    proptest! {
        /// Any permutation of a stream whose disorder is within the window comes out sorted and
        /// complete.
        #[test]
        fn sorts_bounded_disorder(jitter in proptest::collection::vec(0i64..10, 1..200)) {
            let window = 10;
            let mut items: Vec<i64> = (0..jitter.len() as i64).map(|i| i * 3).collect();
            // Arrival time = t + jitter (< window): sort by arrival.
            let mut arrivals: Vec<(i64, i64)> = items.iter().zip(&jitter).map(|(&t, &j)| (t + j, t)).collect();
            arrivals.sort();
            let mut b = ReorderBuffer::new(window, 10_000);
            let mut out = Vec::new();
            for (_, t) in arrivals {
                prop_assert!(b.push(t, 0, t).is_ok());
                while let Some((_, x)) = b.pop_ready() { out.push(x); }
            }
            while let Some((_, x)) = b.pop_first() { out.push(x); }
            items.sort();
            prop_assert_eq!(out, items);
        }
    }
}
