//! The plausibility check of a loaded configuration: values that cannot work are refused with
//! the key named, before anything starts.

use super::{Config, ConfigError};

impl Config {
    /// Rejects values that cannot work.
    pub fn check(&self) -> Result<(), ConfigError> {
        let bad = |m: &str| Err(ConfigError::Invalid(m.to_string()));
        if self.grpc.max_message_bytes < 8 << 20 {
            return bad("grpc.max_message_bytes must be at least 8 MiB (1080p JPEG frames)");
        }
        if self.grpc.ack_buffer == 0
            || self.vehicles.input_queue == 0
            || self.vehicles.camera_queue == 0
        {
            return bad(
                "grpc.ack_buffer, vehicles.input_queue and vehicles.camera_queue must be > 0",
            );
        }
        let v = &self.vehicles;
        if v.input_queue_bytes < 64 << 10
            || v.input_queue_bytes > u32::MAX as usize
            || v.input_bytes < v.input_queue_bytes
        {
            return bad(
                "vehicles.input_queue_bytes must be within 64 KiB..4 GiB and vehicles.input_bytes at least as large",
            );
        }
        let g = &self.grpc;
        if g.arrival_bytes < 3 * g.max_message_bytes as u64 {
            return bad(
                "grpc.arrival_bytes must be at least 3 × grpc.max_message_bytes (one compressed message of the largest size)",
            );
        }
        let seconds = |x: f64| x.is_finite() && x > 0.0 && x <= 86_400.0;
        if g.max_connections == 0
            || self.http.max_connections == 0
            || g.max_streams_per_connection == 0
            || g.max_streams == 0
        {
            return bad(
                "grpc.max_connections, grpc.max_streams_per_connection, grpc.max_streams and http.max_connections must be > 0",
            );
        }
        if g.max_streams_per_peer == 0 {
            return bad("grpc.max_streams_per_peer must be > 0");
        }
        if !(seconds(g.idle_timeout_s)
            && seconds(self.http.idle_timeout_s)
            && seconds(self.http.header_timeout_s))
        {
            return bad(
                "grpc.idle_timeout_s, http.idle_timeout_s and http.header_timeout_s must be in (0, 86400]",
            );
        }
        if !(g.keepalive_interval_s == 0.0 || seconds(g.keepalive_interval_s))
            || !seconds(g.keepalive_timeout_s)
        {
            return bad(
                "grpc.keepalive_interval_s must be 0 (off) or in (0, 86400], grpc.keepalive_timeout_s in (0, 86400]",
            );
        }
        if g.keepalive_interval_s > 0.0
            && g.idle_timeout_s <= g.keepalive_interval_s + g.keepalive_timeout_s
        {
            return bad(
                "grpc.idle_timeout_s must exceed grpc.keepalive_interval_s + grpc.keepalive_timeout_s (a live idle client answers pings only that often)",
            );
        }
        let v = &self.vehicles;
        if !(v.reorder_window_ms >= 0.0 && v.reorder_window_ms <= 10_000.0) {
            return bad("vehicles.reorder_window_ms must be in [0, 10000]");
        }
        if !(v.idle_evict_s > 0.0 && v.max_future_s > 0.0) || v.max_vehicles == 0 {
            return bad(
                "vehicles.idle_evict_s, vehicles.max_future_s and vehicles.max_vehicles must be > 0",
            );
        }
        if !(v.max_future_s.is_finite() && v.max_future_s <= 86_400.0) {
            return bad("vehicles.max_future_s must be at most 86400 (a day)");
        }
        if v.clock_resync_samples < 2 {
            return bad("vehicles.clock_resync_samples must be at least 2");
        }
        if !(v.clock_resync_s >= 0.0 && v.clock_resync_s <= 3600.0) {
            return bad("vehicles.clock_resync_s must be in [0, 3600]");
        }
        let vis = &self.vision;
        if v.camera_queue_bytes < vis.max_image_bytes || vis.queue_bytes < vis.max_image_bytes {
            return bad(
                "vehicles.camera_queue_bytes and vision.queue_bytes must hold at least one frame of vision.max_image_bytes",
            );
        }
        if vis.max_camera_width_px == 0
            || vis.max_camera_height_px == 0
            || vis.max_camera_pixels == 0
            || vis.max_total_camera_pixels < vis.max_camera_pixels
            || vis.max_camera_width_px > 16_384
            || vis.max_camera_height_px > 16_384
        {
            return bad(
                "vision.max_camera_width_px and vision.max_camera_height_px must be in [1, 16384], vision.max_camera_pixels > 0 and at most vision.max_total_camera_pixels",
            );
        }
        if !(self.zenoh.stalled_link_ms >= 0.0 && self.zenoh.stalled_link_ms <= 10_000.0) {
            return bad("zenoh.stalled_link_ms must be in [0, 10000]");
        }
        if !(self.zenoh.repeat_health_per_s >= 0.0 && self.zenoh.repeat_health_per_s <= 1e6) {
            return bad("zenoh.repeat_health_per_s must be in [0, 1e6]");
        }
        if !(1..=100_000).contains(&self.zenoh.max_sessions) {
            return bad("zenoh.max_sessions must be in [1, 100000]");
        }
        if self.health.period_ms == 0 {
            return bad("health.period_ms must be > 0");
        }
        let r = &self.record;
        if r.rotate_bytes == 0 || r.retain_bytes == 0 || r.queue_bytes == 0 {
            return bad(
                "record.rotate_bytes, record.retain_bytes and record.queue_bytes must be > 0",
            );
        }
        if !(r.rotate_s > 0.0 && r.rotate_s.is_finite()) {
            return bad("record.rotate_s must be > 0");
        }
        crate::security::Authorizer::new(&self.security.principals)
            .map_err(|e| ConfigError::Invalid(e.to_string()))?;
        crate::security::exposure(self).map_err(ConfigError::Invalid)?;
        Ok(())
    }
}
