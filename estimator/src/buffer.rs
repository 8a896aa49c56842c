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
    /// How many of `events` are boxed egomotions (they hold [`Egomotion`]'s bytes besides).
    egomotions: usize,
}

/// Bound on queued events: a stalled IMU, or a stream whose aiding sensors run ahead of it, must
/// not grow memory without limit. A second of horizon at the fastest rates seen on real vehicles
/// (magnetometer 100 Hz, barometer 50 Hz, GNSS 10 Hz, camera 30 Hz with its clones) queues about
/// 220 events. A power of two, so that the vector's doubling never reserves beyond it.
pub const MAX_EVENTS: usize = 512;

/// Bound on the IMU samples a filter keeps behind its newest one (the eskf's history from its
/// fusion horizon, the paper profile's attitude history): at 1 kHz, two seconds. Beyond it the
/// horizon is pushed forward, and measurements that then arrive behind it are dropped as late
/// (counted): stamps crowded closer than the configured rate must not grow memory. A power of two
/// (see [`MAX_EVENTS`]); 56 bytes each.
pub const MAX_IMU_HISTORY: usize = 2048;

/// Bound on queued egomotions among [`MAX_EVENTS`] (each boxed, about 0.6 kB): two seconds of a
/// 30 Hz camera.
pub const MAX_EGOMOTIONS: usize = 64;

/// The most bytes a [`DelayBuffer`] holds: its vector at [`MAX_EVENTS`] and [`MAX_EGOMOTIONS`]
/// boxed egomotions (the service's per-vehicle memory bound counts on it).
pub const MAX_BYTES: usize =
    MAX_EVENTS * size_of::<Event>() + MAX_EGOMOTIONS * size_of::<Egomotion>();

/// The most bytes a filter's delayed buffers hold: the IMU history at [`MAX_IMU_HISTORY`] and the
/// event buffer at [`MAX_BYTES`] (`Estimator::buffered_bytes` reports the current figure).
pub const MAX_BUFFERED_BYTES: usize =
    MAX_IMU_HISTORY * size_of::<uavnav_core::ImuSample>() + MAX_BYTES;

impl DelayBuffer {
    /// Inserts an event in time order. Returns false (event dropped) when full.
    pub fn push(&mut self, e: Event) -> bool {
        let ego = matches!(e, Event::Ego(_));
        if self.events.len() >= MAX_EVENTS || (ego && self.egomotions >= MAX_EGOMOTIONS) {
            return false;
        }
        self.egomotions += usize::from(ego);
        let key = (e.t_ns(), e.rank());
        let idx = self.events.partition_point(|x| (x.t_ns(), x.rank()) <= key);
        self.events.insert(idx, e);
        true
    }

    /// Bytes held: the vector's reservation and the boxed egomotions.
    pub fn bytes(&self) -> usize {
        self.events.capacity() * size_of::<Event>() + self.egomotions * size_of::<Egomotion>()
    }

    /// Time of the earliest event.
    pub fn peek_t_ns(&self) -> Option<i64> {
        self.events.first().map(Event::t_ns)
    }

    /// Removes and returns the earliest event if its time is `<= t_ns`.
    pub fn pop_until(&mut self, t_ns: i64) -> Option<Event> {
        if self.peek_t_ns().is_some_and(|t| t <= t_ns) {
            let e = self.events.remove(0);
            self.egomotions -= usize::from(matches!(e, Event::Ego(_)));
            Some(e)
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
        let Self { events, egomotions } = self;
        events.clear();
        *egomotions = 0;
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

    #[test]
    fn a_flood_is_refused_at_the_byte_bound() {
        let ego = |t: i64| {
            Event::Ego(Box::new(Egomotion {
                t0_ns: t - 1,
                t1_ns: t,
                cam1_from_cam0: nalgebra::UnitQuaternion::identity(),
                t_dir_cam1: None,
                t_cam1_m: None,
                scale_distance_m: None,
                rot_cov: nalgebra::Matrix3::identity(),
                t_cov: nalgebra::Matrix3::identity(),
                joint_cov: nalgebra::Matrix6::identity(),
                tracked: 0,
                inliers: 0,
                quality: 1.0,
                solver: uavnav_core::EgomotionSolver::RotationOnly,
            }))
        };
        let mut b = DelayBuffer::default();
        let taken_egos = (0..1000).filter(|&t| b.push(ego(t))).count();
        assert_eq!(taken_egos, MAX_EGOMOTIONS);
        let taken = (0..10_000).filter(|&t| b.push(g(t))).count();
        assert_eq!(taken + taken_egos, MAX_EVENTS);
        assert!(b.bytes() <= MAX_BYTES, "{} > {MAX_BYTES}", b.bytes());
        // Draining gives the egomotion slots back.
        while b.pop_until(i64::MAX).is_some() {}
        assert!(b.push(ego(5)));
        b.clear();
        assert_eq!(b.egomotions, 0);
    }
}
