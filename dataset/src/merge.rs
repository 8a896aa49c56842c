//! Merges per-sensor streams, each already in time order, into one time-ordered stream.

use uavnav_core::SensorEvent;

use crate::error::Result;

/// One time-ordered stream of events (a sensor's `data.csv`, ...).
pub trait EventSource: Send {
    /// The next event, `None` at the end.
    fn next_event(&mut self) -> Option<Result<SensorEvent>>;
}

/// A k-way merge by `t_ns`. Equal times come out in source order (IMU before GNSS before camera),
/// so the output is deterministic. Holds at most one pending event per source, so a camera stream
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
    /// Merges `sources`, listed in tie-break order.
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
                // Strictly earlier wins, so ties keep source order.
                if best.is_none_or(|b| self.heads[b].as_ref().is_some_and(|h| ev.t_ns() < h.t_ns()))
                {
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
