//! Sensor events → timed wire messages: IMU samples batched, each message due at the sensor time
//! of its last sample (the instant the data would exist on a live vehicle), relative to the first.

use uavnav_core::{ImuSample, SensorEvent};

use uavnav_client::pb;
use uavnav_client::pb::sensor_envelope::Payload;

/// One message of a vehicle's stream.
#[derive(Debug, Clone)]
pub struct TimedMessage {
    /// When it is due, ns after the stream's first sample (sensor time).
    pub offset_ns: i64,
    /// Sensor time of its last sample.
    pub last_t_ns: i64,
    /// The wire payload.
    pub payload: Payload,
}

/// How a stream is cut into messages.
#[derive(Debug, Clone, PartialEq)]
pub struct ScheduleParams {
    /// Most IMU samples per `ImuBatch` (a batch is also cut by any other sensor's message).
    pub imu_batch: usize,
}

impl Default for ScheduleParams {
    fn default() -> Self {
        // 4 samples = 20 ms at 200 Hz: small enough for low latency, large enough to amortise framing.
        Self { imu_batch: 4 }
    }
}

/// Cuts a time-ordered event stream into [`TimedMessage`]s incrementally (for long recordings).
#[derive(Debug)]
pub struct Batcher {
    params: ScheduleParams,
    t0_ns: Option<i64>,
    imu: Vec<ImuSample>,
}

impl Batcher {
    /// A batcher with `params`.
    pub fn new(params: ScheduleParams) -> Self {
        Self {
            params,
            t0_ns: None,
            imu: Vec::new(),
        }
    }

    /// Sensor time of the first event (the schedule's zero).
    pub fn t0_ns(&self) -> Option<i64> {
        self.t0_ns
    }

    /// Feeds one event; returns the messages it completes, in order.
    pub fn push(&mut self, ev: &SensorEvent) -> Vec<TimedMessage> {
        let t0 = *self.t0_ns.get_or_insert(ev.t_ns());
        let mut out = Vec::new();
        match ev {
            SensorEvent::Imu(s) => {
                self.imu.push(*s);
                if self.imu.len() >= self.params.imu_batch.max(1) {
                    out.extend(self.flush_imu(t0));
                }
            }
            other => {
                out.extend(self.flush_imu(t0));
                out.push(TimedMessage {
                    offset_ns: other.t_ns() - t0,
                    last_t_ns: other.t_ns(),
                    payload: Payload::from(other),
                });
            }
        }
        out
    }

    /// The pending IMU batch, if any.
    pub fn finish(&mut self) -> Option<TimedMessage> {
        let t0 = self.t0_ns?;
        self.flush_imu(t0)
    }

    fn flush_imu(&mut self, t0: i64) -> Option<TimedMessage> {
        let last = self.imu.last()?.t_ns;
        let batch = pb::ImuBatch::from(self.imu.as_slice());
        self.imu.clear();
        Some(TimedMessage {
            offset_ns: last - t0,
            last_t_ns: last,
            payload: Payload::Imu(batch),
        })
    }
}

/// A whole stream at once: the optional configuration first (due at 0), then the batched events.
pub fn build<I: IntoIterator<Item = SensorEvent>>(
    config: Option<&pb::VehicleConfig>,
    events: I,
    params: &ScheduleParams,
) -> Vec<TimedMessage> {
    let mut b = Batcher::new(params.clone());
    let mut out = Vec::new();
    for ev in events {
        out.extend(b.push(&ev));
    }
    out.extend(b.finish());
    if let Some(c) = config {
        let t0 = b.t0_ns().unwrap_or(0);
        out.insert(
            0,
            TimedMessage {
                offset_ns: 0,
                last_t_ns: t0,
                payload: Payload::Config(*c),
            },
        );
    }
    out
}

/// Shifts every sensor time in a payload by `dt_ns` (to loop a recording without going back in time).
pub fn shift_payload(p: &Payload, dt_ns: i64) -> Payload {
    let mut p = p.clone();
    match &mut p {
        Payload::Imu(b) => b.samples.iter_mut().for_each(|s| s.t_ns += dt_ns),
        Payload::Gnss(g) => g.t_ns += dt_ns,
        Payload::Mag(m) => m.t_ns += dt_ns,
        Payload::Baro(b) => b.t_ns += dt_ns,
        Payload::Camera(c) => {
            c.t_ns += dt_ns;
            if let Some(img) = c.image.as_mut() {
                img.timestamp = uavnav_proto::foxglove_conv::timestamp(c.t_ns);
            }
        }
        Payload::Config(_) => {}
    }
    p
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;

    fn imu(t_ns: i64) -> SensorEvent {
        SensorEvent::Imu(ImuSample {
            t_ns,
            gyro_radps: Vector3::zeros(),
            accel_mps2: Vector3::new(0.0, 0.0, -9.8),
        })
    }

    #[test]
    fn batches_are_cut_by_size_and_by_other_sensors() {
        let gnss = SensorEvent::Gnss(uavnav_core::GnssFix {
            t_ns: 1_025,
            lat_deg: 41.0,
            lon_deg: 14.0,
            alt_m: 100.0,
            velocity: None,
            sigma_h_m: 1.0,
            sigma_v_m: 1.0,
            fix_type: uavnav_core::FixType::Fix3d,
            num_sats: 9,
        });
        let evs = vec![
            imu(1_000),
            imu(1_005),
            imu(1_010),
            imu(1_015),
            imu(1_020),
            gnss,
            imu(1_030),
        ];
        let msgs = build(
            Some(&pb::VehicleConfig::default()),
            evs,
            &ScheduleParams { imu_batch: 4 },
        );
        let shape: Vec<(i64, &str, usize)> = msgs
            .iter()
            .map(|m| match &m.payload {
                Payload::Imu(b) => (m.offset_ns, "imu", b.samples.len()),
                Payload::Gnss(_) => (m.offset_ns, "gnss", 1),
                Payload::Mag(_) => (m.offset_ns, "mag", 1),
                Payload::Baro(_) => (m.offset_ns, "baro", 1),
                Payload::Config(_) => (m.offset_ns, "config", 1),
                Payload::Camera(_) => (m.offset_ns, "camera", 1),
            })
            .collect();
        assert_eq!(
            shape,
            vec![
                (0, "config", 1),
                (15, "imu", 4),
                (20, "imu", 1),
                (25, "gnss", 1),
                (30, "imu", 1)
            ]
        );
    }
}
