//! The service's worst-case resident memory, from its configuration: every place that can hold
//! memory in proportion to its input has a bound in bytes, and this sums them (`uavnavd
//! --memory-budget` prints it; the README states the formula; `cargo bench -p uavnavd --bench
//! memory` checks it under attack).
//!
//! ```text
//! RSS ≤ base
//!     + max_vehicles × vehicle                       (actors, estimators, reorder windows)
//!     + min(max_vehicles × input_queue_bytes, input_bytes)             (queued sensor data)
//!     + min(max_vehicles × camera_queue_bytes, vision.queue_bytes)     (queued camera frames)
//!     + max_total_camera_pixels × front_end_per_pixel                  (vision front ends)
//!     + (workers + vision.queue) × max_image_bytes
//!       + workers × decode_per_pixel × max_camera_pixels               (vision jobs)
//!     + record.queue_bytes                                             (recorder, when on)
//!     + grpc.arrival_bytes                                            (gRPC messages arriving)
//!     + grpc.max_connections × connection_window                      (gRPC connections)
//!     + min(grpc.max_connections × max_streams_per_connection,
//!           grpc.max_streams) × grpc_stream                                 (gRPC streams)
//!     + pose_ring × (batch + max_batch_poses × pose) + health_ring × health   (output rings)
//!     + http.max_connections × http_connection
//!     + zenoh.max_sessions × zenoh_link                                (Zenoh, when on)
//! ```
//!
//! The per-item constants below were measured on this service (release build, x86-64, mimalloc)
//! and rounded up; the measured figures are in their docs.

use crate::config::Config;

/// The process with no vehicle and no connection: code, runtimes, the Zenoh session, the vision
/// workers' stacks. Measured 27–33 MiB (release, Zenoh on).
pub const BASE_BYTES: u64 = 64 << 20;

/// One vehicle at its largest without camera: actor, queues' fixed parts, reorder window (its
/// capacity), latency memory, the estimator, the last pose batch and health report (measured
/// 38–44 kB per vehicle streaming IMU + GNSS, 2,000 vehicles; rounded up to 64 KiB), plus the
/// estimator's delayed buffers at their caps (IMU history and pending measurements, which crowded
/// stamps or aiding data ahead of the IMU fill: `uavnav_estimator::buffer::MAX_BUFFERED_BYTES`,
/// about 210 kB).
pub const VEHICLE_BYTES: u64 = (64 << 10) + uavnav_estimator::buffer::MAX_BUFFERED_BYTES as u64;

/// Vision front end memory per configured camera pixel (image pyramids of two frames, gradients,
/// tracks). Measured about 4.7 bytes per pixel (a 64 Mi pixel camera held +300 MB).
pub const FRONT_END_BYTES_PER_PIXEL: u64 = 8;

/// Decoded image memory per pixel while a vision job decodes a frame (a 16-bit RGBA PNG).
pub const DECODE_BYTES_PER_PIXEL: u64 = 8;

/// One HTTP connection (headers, a small body, hyper's buffers).
pub const HTTP_CONNECTION_BYTES: u64 = 256 << 10;

/// HTTP/2 receive window of a gRPC connection and of each of its streams, bytes (set on the
/// server rather than left to hyper's default, which is the same 1 MiB): what a connection's
/// peer may send before the service reads it.
pub const GRPC_CONNECTION_WINDOW: u32 = 1 << 20;

/// One open gRPC stream besides its arriving messages: HTTP/2 stream state and tonic's codec
/// buffers (measured 42 KiB per stream with 128 idle watch streams; 64 KiB), hyper's send buffer
/// for a peer that stops reading (set by the service:
/// [`STREAM_SEND_BUFFER`](crate::transport::grpc_serve::STREAM_SEND_BUFFER)), the encoded chunk
/// tonic hands hyper beyond it (it yields at 32 KiB), and the response queue
/// ([`RESPONSE_QUEUE_BYTES`](crate::transport::response_queue::RESPONSE_QUEUE_BYTES)).
/// `cargo bench -p uavnavd --bench memory -- --only 6` measures it with 128 watch streams that
/// stop reading while poses flow.
pub const GRPC_STREAM_BYTES: u64 = (64 << 10)
    + crate::transport::grpc_serve::STREAM_SEND_BUFFER as u64
    + (32 << 10)
    + crate::transport::response_queue::RESPONSE_QUEUE_BYTES as u64;

/// One health report as the ring holds it: the message, its id and heap (no repeated fields
/// but short ones), rounded up.
pub const HEALTH_REPORT_BYTES: u64 = 2 << 10;

/// The output hub's rings at their fullest: every slot keeps its batch or report until every
/// watcher has taken it, so a watcher that stops reading keeps them all. A pose slot holds at
/// most [`MAX_BATCH_POSES`](crate::output::hub::MAX_BATCH_POSES) poses (the actor splits larger
/// batches).
pub fn output_ring_bytes() -> u64 {
    use crate::output::hub::{HEALTH_CAPACITY, MAX_BATCH_POSES, POSE_CAPACITY, Pose, PoseBatch};
    // The Arc's two counts and the allocator's rounding of the two allocations.
    let pose_slot =
        std::mem::size_of::<PoseBatch>() + MAX_BATCH_POSES * std::mem::size_of::<Pose>() + 2 * 64;
    (POSE_CAPACITY * pose_slot) as u64 + HEALTH_CAPACITY as u64 * HEALTH_REPORT_BYTES
}

/// One Zenoh link's transmission and reception buffers (its batch size, 64 KiB, times the
/// priority queues' batches, both ways).
pub const ZENOH_LINK_BYTES: u64 = 4 << 20;

/// One term of the budget.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Term {
    /// What holds the memory.
    pub what: &'static str,
    /// The configuration that bounds it.
    pub bound_by: &'static str,
    /// Bytes.
    pub bytes: u64,
}

/// The worst-case resident memory of a configuration, term by term.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MemoryBudget {
    /// The terms.
    pub terms: Vec<Term>,
}

impl MemoryBudget {
    /// The budget of `config`.
    pub fn of(config: &Config) -> Self {
        let u = |x: usize| x as u64;
        let v = u(config.vehicles.max_vehicles);
        let vis = &config.vision;
        let workers = u(vis.effective_workers());
        let g = &config.grpc;
        let mut terms = vec![
            Term {
                what: "process base",
                bound_by: "constant",
                bytes: BASE_BYTES,
            },
            Term {
                what: "vehicles",
                bound_by: "vehicles.max_vehicles",
                bytes: v * VEHICLE_BYTES,
            },
            Term {
                what: "queued sensor data",
                bound_by: "vehicles.input_queue_bytes, vehicles.input_bytes",
                bytes: (v * u(config.vehicles.input_queue_bytes))
                    .min(u(config.vehicles.input_bytes)),
            },
            Term {
                what: "queued camera frames",
                bound_by: "vehicles.camera_queue_bytes, vision.queue_bytes",
                bytes: (v * u(config.vehicles.camera_queue_bytes)).min(u(vis.queue_bytes)),
            },
            Term {
                what: "vision front ends",
                bound_by: "vision.max_total_camera_pixels",
                bytes: vis.max_total_camera_pixels * FRONT_END_BYTES_PER_PIXEL,
            },
            Term {
                what: "vision jobs",
                bound_by: "vision.workers, vision.queue, vision.max_image_bytes, vision.max_camera_pixels",
                bytes: (workers + u(vis.queue)) * u(vis.max_image_bytes)
                    + workers * DECODE_BYTES_PER_PIXEL * vis.max_camera_pixels,
            },
            Term {
                what: "gRPC messages arriving",
                bound_by: "grpc.arrival_bytes",
                // Every stream holds its largest message's buffers from one shared budget
                // (transport::arrivals).
                bytes: g.arrival_bytes,
            },
            Term {
                what: "gRPC connections",
                bound_by: "grpc.max_connections",
                bytes: u(g.max_connections) * u64::from(GRPC_CONNECTION_WINDOW),
            },
            Term {
                what: "gRPC streams",
                bound_by: "grpc.max_streams, grpc.max_connections, grpc.max_streams_per_connection",
                // Every stream holds a slot of `grpc.max_streams` (transport::stream_limit).
                bytes: (u(g.max_connections) * u64::from(g.max_streams_per_connection))
                    .min(u(g.max_streams))
                    * GRPC_STREAM_BYTES,
            },
            Term {
                what: "output rings",
                bound_by: "constant (output::hub: POSE_CAPACITY, MAX_BATCH_POSES, HEALTH_CAPACITY)",
                bytes: output_ring_bytes(),
            },
            Term {
                what: "HTTP connections",
                bound_by: "http.max_connections",
                bytes: u(config.http.max_connections) * HTTP_CONNECTION_BYTES,
            },
        ];
        if config.record.directory.is_some() {
            terms.push(Term {
                what: "recorder queue",
                bound_by: "record.queue_bytes",
                bytes: config.record.queue_bytes,
            });
        }
        if config.zenoh.enabled {
            terms.push(Term {
                what: "Zenoh links",
                bound_by: "zenoh.max_sessions",
                bytes: config.zenoh.max_sessions as u64 * ZENOH_LINK_BYTES,
            });
        }
        Self { terms }
    }

    /// The sum, bytes.
    pub fn total(&self) -> u64 {
        self.terms.iter().map(|t| t.bytes).sum()
    }
}

impl std::fmt::Display for MemoryBudget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mib = |b: u64| b as f64 / f64::from(1u32 << 20);
        for t in &self.terms {
            writeln!(
                f,
                "{:>12.1} MiB  {:<24} ({})",
                mib(t.bytes),
                t.what,
                t.bound_by
            )?;
        }
        write!(f, "{:>12.1} MiB  worst case in all", mib(self.total()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_health_report_fits_its_ring_slot() {
        let mut h = uavnav_proto::v1::VehicleHealth {
            vehicle_id: "x".repeat(crate::ingest::validate::MAX_ID_LEN),
            ..Default::default()
        };
        h.input_rates = Some(Default::default());
        h.latency = Some(Default::default());
        h.innovation_ratios = Some(Default::default());
        h.counters = Some(Default::default());
        h.vision = Some(Default::default());
        h.heading = Some(uavnav_proto::v1::HeadingStatus {
            source: i32::MAX,
            magnetometer: i32::MAX,
            magnetometer_disturbed: u64::MAX,
            yaw_resets: u32::MAX,
            magnetometer_calibration: i32::MAX,
            magnetometer_offset_t: Some(uavnav_proto::v1::Vector3 {
                x: f64::MAX,
                y: f64::MAX,
                z: f64::MAX,
            }),
            magnetometer_calibration_test_ratio: f64::MAX,
            magnetometer_calibration_restarts: u32::MAX,
        });
        h.gnss_velocity_delay_s = Some(f64::MAX);
        h.imu_noise = Some(uavnav_proto::v1::ImuNoise {
            gyro_ratio: f64::MAX,
            accel_ratio: f64::MAX,
        });
        let held = std::mem::size_of_val(&h) + prost::Message::encoded_len(&h) + 64;
        assert!(held as u64 <= HEALTH_REPORT_BYTES, "{held} bytes");
    }

    #[test]
    fn every_bound_of_the_configuration_moves_its_term() {
        let mut c = Config::default();
        c.zenoh.enabled = false;
        let before = MemoryBudget::of(&c).total();
        c.vehicles.max_vehicles /= 2;
        let fewer = MemoryBudget::of(&c).total();
        assert!(fewer < before);
        c.vision.max_total_camera_pixels /= 2;
        assert!(MemoryBudget::of(&c).total() < fewer);
        c.zenoh.enabled = true;
        let with_zenoh = MemoryBudget::of(&c);
        assert!(with_zenoh.terms.iter().any(|t| t.what == "Zenoh links"));
        c.grpc.arrival_bytes /= 2;
        assert!(MemoryBudget::of(&c).total() < with_zenoh.total());
        let before_streams = MemoryBudget::of(&c).total();
        c.grpc.max_streams /= 2;
        let fewer_streams = MemoryBudget::of(&c).total();
        assert!(fewer_streams < before_streams);
        c.grpc.max_connections /= 2;
        assert!(MemoryBudget::of(&c).total() < fewer_streams);
        // Per-connection streams count once the product is below the fleet-wide limit.
        c.grpc.max_streams_per_connection = 1;
        assert!(MemoryBudget::of(&c).total() < fewer_streams);
        c.zenoh.max_sessions /= 2;
        let fewer_links = MemoryBudget::of(&c).total();
        c.zenoh.max_sessions *= 2;
        assert!(fewer_links < MemoryBudget::of(&c).total());
        assert!(with_zenoh.to_string().contains("worst case in all"));
    }
}
