//! The delayed-measurement buffer: measurements wait here, sorted by their time of validity, until
//! the fusion horizon reaches them (PX4 EKF2 `RingBuffer` per source, merged here into one queue so
//! out-of-order arrivals are fused in time order).

use uavnav_core::Egomotion;

use crate::aid_sources::gnss_pos::GnssMeas;

/// A buffered event at the fusion horizon.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A GNSS fix (already in the local frame).
    Gnss(GnssMeas),
    /// A vision egomotion, fused at its frame-1 time.
    Ego(Box<Egomotion>),
    /// Clone the pose at this frame time (frame 0 of a pending egomotion).
    CloneAt(i64),
    /// A magnetometer sample, field already in the body frame.
    Mag(i64, nalgebra::Vector3<f64>),
    /// A barometer sample: static pressure, Pa.
    Baro(i64, f64),
}

impl Event {
    /// Time at which the event is processed, ns.
    pub fn t_ns(&self) -> i64 {
        match self {
            Event::Gnss(g) => g.t_ns,
            Event::Ego(e) => e.t1_ns,
            Event::CloneAt(t) => *t,
            Event::Mag(t, _) | Event::Baro(t, _) => *t,
        }
    }

    /// Processing order among events at the same time: clones after fusions (the clone must hold
    /// the corrected state), GNSS before vision.
    fn rank(&self) -> u8 {
        match self {
            Event::Gnss(_) => 0,
            Event::Mag(..) | Event::Baro(..) => 1,
            Event::Ego(_) => 2,
            Event::CloneAt(_) => 3,
        }
    }
}

/// Time-ordered queue of pending events (stable for equal keys).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DelayBuffer {
    events: Vec<Event>,
}

/// Bound on queued events (a stalled IMU must not grow memory without limit).
pub const MAX_EVENTS: usize = 4096;

impl DelayBuffer {
    /// Inserts an event in time order. Returns false (event dropped) when full.
    pub fn push(&mut self, e: Event) -> bool {
        if self.events.len() >= MAX_EVENTS {
            return false;
        }
        let key = (e.t_ns(), e.rank());
        let idx = self.events.partition_point(|x| (x.t_ns(), x.rank()) <= key);
        self.events.insert(idx, e);
        true
    }

    /// Time of the earliest event.
    pub fn peek_t_ns(&self) -> Option<i64> {
        self.events.first().map(Event::t_ns)
    }

    /// Removes and returns the earliest event if its time is `<= t_ns`.
    pub fn pop_until(&mut self, t_ns: i64) -> Option<Event> {
        if self.peek_t_ns().is_some_and(|t| t <= t_ns) {
            Some(self.events.remove(0))
        } else {
            None
        }
    }

    /// Whether a clone request at exactly `t_ns` is pending.
    pub fn has_clone_at(&self, t_ns: i64) -> bool {
        self.events
            .iter()
            .any(|e| matches!(e, Event::CloneAt(t) if *t == t_ns))
    }

    /// Frame-0 times of the pending egomotions.
    pub fn pending_ego_t0(&self) -> Vec<i64> {
        self.events
            .iter()
            .filter_map(|e| {
                if let Event::Ego(m) = e {
                    Some(m.t0_ns)
                } else {
                    None
                }
            })
            .collect()
    }

    /// Number of pending events.
    pub fn len(&self) -> usize {
        self.events.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.events.is_empty()
    }

    /// Drops everything.
    pub fn clear(&mut self) {
        self.events.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn g(t: i64) -> Event {
        Event::Gnss(GnssMeas {
            t_ns: t,
            pos_ned_m: Vector3::zeros(),
            vel_ned_mps: Some(Vector3::zeros()),
            vel_h_mps: Some(nalgebra::Vector2::zeros()),
            sigma_h_m: 1.0,
            sigma_v_m: 1.0,
            sigma_vel_mps: 0.1,
        })
    }

    #[test]
    fn out_of_order_comes_out_sorted() {
        let mut b = DelayBuffer::default();
        for t in [30, 10, 20, 10] {
            assert!(b.push(g(t)));
        }
        b.push(Event::CloneAt(10));
        let mut out = vec![];
        while let Some(e) = b.pop_until(25) {
            out.push((e.t_ns(), e.rank()));
        }
        assert_eq!(out, vec![(10, 0), (10, 0), (10, 3), (20, 0)]);
        assert_eq!(b.len(), 1);
    }
}
