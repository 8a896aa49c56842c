//! Merges per-sensor streams, each already in time order, into one time-ordered stream.

use uavnav_core::SensorEvent;

use crate::error::Result;

/// One time-ordered stream of events (a sensor's `data.csv`, ...).
pub trait EventSource: Send {
    /// The next event, `None` at the end.
    fn next_event(&mut self) -> Option<Result<SensorEvent>>;
}

/// A k-way merge by `(t_ns, SensorEvent::rank)`: equal times come out IMU, GNSS, magnetometer,
/// barometer, camera whatever the order of the sources (the service's reorder window breaks ties
/// the same way), then in source order, so the output is deterministic. Holds at most one pending event per source, so a camera stream
/// keeps at most one image in memory.
pub struct Merge {
    sources: Vec<Box<dyn EventSource>>,
    heads: Vec<Option<SensorEvent>>,
    exhausted: Vec<bool>,
    failed: bool,
}

impl std::fmt::Debug for Merge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Merge")
            .field("sources", &self.sources.len())
            .finish()
    }
}

impl Merge {
    /// Merges `sources` (ties between events of the same rank keep the order of `sources`).
    pub fn new(sources: Vec<Box<dyn EventSource>>) -> Self {
        let n = sources.len();
        Merge {
            sources,
            heads: vec![None; n],
            exhausted: vec![false; n],
            failed: false,
        }
    }

    /// Fills every empty head; the first error ends the stream.
    fn refill(&mut self) -> Result<()> {
        for i in 0..self.sources.len() {
            if self.heads[i].is_none() && !self.exhausted[i] {
                match self.sources[i].next_event() {
                    Some(Ok(ev)) => self.heads[i] = Some(ev),
                    Some(Err(e)) => return Err(e),
                    None => self.exhausted[i] = true,
                }
            }
        }
        Ok(())
    }
}

impl Iterator for Merge {
    type Item = Result<SensorEvent>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        if let Err(e) = self.refill() {
            self.failed = true;
            return Some(Err(e));
        }
        let mut best: Option<usize> = None;
        for (i, head) in self.heads.iter().enumerate() {
            if let Some(ev) = head {
                // Strictly earlier wins, so full ties keep source order.
                let key = (ev.t_ns(), ev.rank());
                if best.is_none_or(|b| {
                    self.heads[b]
                        .as_ref()
                        .is_some_and(|h| key < (h.t_ns(), h.rank()))
                }) {
                    best = Some(i);
                }
            }
        }
        best.and_then(|i| self.heads[i].take()).map(Ok)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use uavnav_core::ImuSample;

    struct Times(Vec<i64>);
    impl EventSource for Times {
        fn next_event(&mut self) -> Option<Result<SensorEvent>> {
            if self.0.is_empty() {
                return None;
            }
            let t_ns = self.0.remove(0);
            Some(Ok(SensorEvent::Imu(ImuSample {
                t_ns,
                gyro_radps: Vector3::zeros(),
                accel_mps2: Vector3::zeros(),
            })))
        }
    }

    struct Events(Vec<SensorEvent>);
    impl EventSource for Events {
        fn next_event(&mut self) -> Option<Result<SensorEvent>> {
            (!self.0.is_empty()).then(|| Ok(self.0.remove(0)))
        }
    }

    #[test]
    fn ties_go_by_rank_whatever_the_source_order() {
        use uavnav_core::{BaroSample, MagSample};
        let baro = SensorEvent::Baro(BaroSample {
            t_ns: 5,
            pressure_pa: 1e5,
            temperature_degc: None,
        });
        let mag = SensorEvent::Mag(MagSample {
            t_ns: 5,
            field_t: Vector3::zeros(),
        });
        let imu = SensorEvent::Imu(ImuSample {
            t_ns: 5,
            gyro_radps: Vector3::zeros(),
            accel_mps2: Vector3::zeros(),
        });
        let m = Merge::new(vec![
            Box::new(Events(vec![baro])),
            Box::new(Events(vec![mag])),
            Box::new(Events(vec![imu])),
        ]);
        let ranks: Vec<u8> = m.map(|e| e.unwrap().rank()).collect();
        assert_eq!(ranks, vec![0, 2, 3]);
    }

    #[test]
    fn merges_in_time_order() {
        let m = Merge::new(vec![
            Box::new(Times(vec![1, 3, 5, 7])),
            Box::new(Times(vec![2, 3, 8])),
            Box::new(Times(vec![])),
        ]);
        let t: Vec<i64> = m.map(|e| e.unwrap().t_ns()).collect();
        assert_eq!(t, vec![1, 2, 3, 3, 5, 7, 8]);
    }
}
