//! Writes MCAP recordings (see the module doc of [`crate::mcap_io`] for topics and times).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use prost::Message;
use uavnav_core::{Lla, LocalFrame, SensorEvent, TruthSample, VehicleConfig};
use uavnav_proto::input::InputRef;
use uavnav_proto::{foxglove_conv, v1};

use super::{REFERENCE_METADATA_KEY, Stream, schema_data, topic};
use crate::error::{DatasetError, Result};

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Compression {
    /// zstd (default: best ratio at good speed).
    #[default]
    Zstd,
    /// LZ4 (faster, larger).
    Lz4,
    /// No compression.
    None,
}

/// Recording options.
#[derive(Debug, Clone, PartialEq)]
pub struct McapOptions {
    /// Chunk compression.
    pub compression: Compression,
    /// Target uncompressed chunk size, bytes.
    pub chunk_size_bytes: u64,
    /// Also write Foxglove display channels (`gnss/location`, `pose/frame`).
    pub display_channels: bool,
}

impl Default for McapOptions {
    fn default() -> Self {
        McapOptions {
            compression: Compression::Zstd,
            chunk_size_bytes: 4 * 1024 * 1024,
            display_channels: true,
        }
    }
}

/// An MCAP recording being written. Call [`McapWriter::finish`] to write the summary.
pub struct McapWriter {
    path: PathBuf,
    out: mcap::Writer<BufWriter<File>>,
    options: McapOptions,
    schemas: BTreeMap<Stream, u16>,
    /// Topic → (channel id, next sequence number).
    channels: BTreeMap<String, (u16, u32)>,
}

impl std::fmt::Debug for McapWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapWriter")
            .field("path", &self.path)
            .field("channels", &self.channels.len())
            .finish()
    }
}

/// MCAP time from a signed nanosecond time.
fn mcap_time(path: &Path, t_ns: i64) -> Result<u64> {
    u64::try_from(t_ns).map_err(|_| {
        DatasetError::mcap(
            path,
            format!("time {t_ns} ns is negative: MCAP times are unsigned"),
        )
    })
}

impl McapWriter {
    /// Creates (truncates) a recording.
    pub fn create(path: &Path, options: &McapOptions) -> Result<Self> {
        let file = File::create(path).map_err(|e| DatasetError::io(path, e))?;
        let compression = match options.compression {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::None => None,
        };
        let out = mcap::WriteOptions::new()
            .compression(compression)
            .chunk_size(Some(options.chunk_size_bytes))
            .profile("")
            .library(concat!("uavnav-dataset ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(|e| DatasetError::mcap(path, e))?;
        Ok(McapWriter {
            path: path.to_owned(),
            out,
            options: options.clone(),
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
        })
    }

    /// The channel of `vehicle`'s `stream`, created on first use.
    fn channel(&mut self, vehicle: &str, stream: Stream) -> Result<(u16, u32)> {
        self.channel_with(vehicle, stream, None)
    }

    /// [`Self::channel`], with one more metadata entry when the channel is created.
    fn channel_with(
        &mut self,
        vehicle: &str,
        stream: Stream,
        extra: Option<(&str, &str)>,
    ) -> Result<(u16, u32)> {
        let topic = topic(vehicle, stream);
        if let Some((id, seq)) = self.channels.get_mut(&topic) {
            *seq += 1;
            return Ok((*id, *seq));
        }
        if vehicle.is_empty() || vehicle.contains('/') {
            return Err(DatasetError::mcap(
                &self.path,
                format!("invalid vehicle id '{vehicle}'"),
            ));
        }
        let schema_id = match self.schemas.get(&stream) {
            Some(id) => *id,
            None => {
                let data = schema_data(stream.schema()).ok_or_else(|| {
                    DatasetError::mcap(&self.path, format!("no schema for {}", stream.schema()))
                })?;
                let id = self
                    .out
                    .add_schema(stream.schema(), "protobuf", &data)
                    .map_err(|e| DatasetError::mcap(&self.path, e))?;
                self.schemas.insert(stream, id);
                id
            }
        };
        let mut metadata = BTreeMap::from([("vehicle_id".to_owned(), vehicle.to_owned())]);
        if let Some((k, v)) = extra {
            metadata.insert(k.to_owned(), v.to_owned());
        }
        let id = self
            .out
            .add_channel(schema_id, &topic, "protobuf", &metadata)
            .map_err(|e| DatasetError::mcap(&self.path, e))?;
        self.channels.insert(topic, (id, 0));
        Ok((id, 0))
    }

    /// Writes one protobuf message on `vehicle`'s `stream` with the given publish and log times.
    pub fn write_message<M: Message>(
        &mut self,
        vehicle: &str,
        stream: Stream,
        message: &M,
        publish_time_ns: i64,
        log_time_ns: i64,
    ) -> Result<()> {
        let header = mcap::records::MessageHeader {
            channel_id: 0,
            sequence: 0,
            log_time: mcap_time(&self.path, log_time_ns)?,
            publish_time: mcap_time(&self.path, publish_time_ns)?,
        };
        let (channel_id, sequence) = self.channel(vehicle, stream)?;
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence,
            ..header
        };
        self.out
            .write_to_known_channel(&header, &message.encode_to_vec())
            .map_err(|e| DatasetError::mcap(&self.path, e))
    }

    /// Writes a sensor event (publish time = its `t_ns`). A GNSS fix also goes to the display
    /// channel when enabled.
    pub fn write_event(
        &mut self,
        vehicle: &str,
        event: &SensorEvent,
        log_time_ns: i64,
    ) -> Result<()> {
        let t = event.t_ns();
        match event {
            SensorEvent::Imu(s) => {
                let batch = v1::ImuBatch::from(std::slice::from_ref(s));
                self.write_message(vehicle, Stream::Imu, &batch, t, log_time_ns)
            }
            SensorEvent::Gnss(f) => {
                self.write_message(vehicle, Stream::Gnss, &v1::GnssFix::from(f), t, log_time_ns)?;
                if self.options.display_channels {
                    let fix = foxglove_conv::location_fix(f);
                    self.write_message(vehicle, Stream::GnssLocation, &fix, t, log_time_ns)?;
                }
                Ok(())
            }
            SensorEvent::Mag(m) => self.write_message(
                vehicle,
                Stream::Mag,
                &v1::MagSample::from(m),
                t,
                log_time_ns,
            ),
            SensorEvent::Baro(b) => {
                let wire = v1::BaroSample::from(b);
                self.write_message(vehicle, Stream::Baro, &wire, t, log_time_ns)
            }
            SensorEvent::Camera(c) => {
                let frame = v1::CameraFrame::from(c);
                let image = frame
                    .image
                    .ok_or_else(|| DatasetError::mcap(&self.path, "frame without image"))?;
                if image.timestamp.is_none() {
                    return Err(DatasetError::mcap(
                        &self.path,
                        format!("frame time {t} ns not representable"),
                    ));
                }
                self.write_message(vehicle, Stream::Camera, &image, t, log_time_ns)
            }
        }
    }

    /// Writes one input as a live recorder received it, at `log_time_ns` (its wall clock), and
    /// returns the bytes of the message written. The one place of the live layout, shared by the
    /// service's recorder and `uavnav record` so that their files read alike: publish time is the
    /// sensor time (an IMU batch's last sample; the arrival for an empty batch and for a
    /// configuration, which has no sensor time); a camera frame is stored as its plain image (the
    /// layout's camera channel), and one without an image is not written (0 bytes).
    pub fn write_input(
        &mut self,
        vehicle: &str,
        input: InputRef<'_>,
        log_time_ns: i64,
    ) -> Result<u64> {
        let log = log_time_ns;
        let bytes = match input {
            InputRef::Imu(m) => {
                let t = m.samples.last().map_or(log, |s| s.t_ns);
                self.write_message(vehicle, Stream::Imu, m, t, log)?;
                m.encoded_len()
            }
            InputRef::Gnss(m) => {
                self.write_message(vehicle, Stream::Gnss, m, m.t_ns, log)?;
                m.encoded_len()
            }
            InputRef::Mag(m) => {
                self.write_message(vehicle, Stream::Mag, m, m.t_ns, log)?;
                m.encoded_len()
            }
            InputRef::Baro(m) => {
                self.write_message(vehicle, Stream::Baro, m, m.t_ns, log)?;
                m.encoded_len()
            }
            InputRef::Camera(c) => {
                let Some(image) = &c.image else {
                    return Ok(0);
                };
                self.write_message(vehicle, Stream::Camera, image, c.t_ns, log)?;
                image.encoded_len()
            }
            InputRef::Config(m) => {
                self.write_message(vehicle, Stream::Config, m, log, log)?;
                m.encoded_len()
            }
        };
        Ok(bytes as u64)
    }

    /// Writes the vehicle configuration (publish time = log time = `t_ns`).
    pub fn write_config(&mut self, vehicle: &str, config: &VehicleConfig, t_ns: i64) -> Result<()> {
        self.write_message(
            vehicle,
            Stream::Config,
            &v1::VehicleConfig::from(config),
            t_ns,
            t_ns,
        )
    }

    /// Writes the dataset info (the truth origin).
    pub fn write_info(&mut self, vehicle: &str, origin: Option<&Lla>, t_ns: i64) -> Result<()> {
        let info = v1::DatasetInfo {
            vehicle_id: vehicle.to_owned(),
            origin: origin.map(Into::into),
        };
        self.write_message(vehicle, Stream::Info, &info, t_ns, t_ns)
    }

    /// Writes a reference sample (another estimator's output, not truth; publish time = its
    /// `t_ns`). `source` (what produced it) goes into the channel metadata as `reference` when
    /// the channel is created.
    pub fn write_reference(
        &mut self,
        vehicle: &str,
        s: &TruthSample,
        source: Option<&str>,
        log_time_ns: i64,
    ) -> Result<()> {
        let header = mcap::records::MessageHeader {
            channel_id: 0,
            sequence: 0,
            log_time: mcap_time(&self.path, log_time_ns)?,
            publish_time: mcap_time(&self.path, s.t_ns)?,
        };
        let extra = source.map(|src| (REFERENCE_METADATA_KEY, src));
        let (channel_id, sequence) = self.channel_with(vehicle, Stream::Reference, extra)?;
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence,
            ..header
        };
        self.out
            .write_to_known_channel(&header, &v1::TruthSample::from(s).encode_to_vec())
            .map_err(|e| DatasetError::mcap(&self.path, e))
    }

    /// Writes a truth sample (publish time = its `t_ns`).
    pub fn write_truth(&mut self, vehicle: &str, s: &TruthSample, log_time_ns: i64) -> Result<()> {
        self.write_message(
            vehicle,
            Stream::Truth,
            &v1::TruthSample::from(s),
            s.t_ns,
            log_time_ns,
        )
    }

    /// Writes a pose estimate; with `frame`, also its `foxglove.PoseInFrame` on the display channel
    /// when it has a position (an attitude-only estimate, running without GNSS, has no place in
    /// the frame: it is recorded on the pose channel only).
    pub fn write_pose(
        &mut self,
        vehicle: &str,
        pose: &v1::PoseEstimate,
        log_time_ns: i64,
        frame: Option<&LocalFrame>,
    ) -> Result<()> {
        self.write_message(vehicle, Stream::Pose, pose, pose.t_ns, log_time_ns)?;
        if let (true, Some(frame), Some(_)) =
            (self.options.display_channels, frame, pose.position.as_ref())
        {
            let display =
                foxglove_conv::pose_in_frame(pose, frame).map_err(|e| DatasetError::Invalid {
                    path: self.path.clone(),
                    context: format!("pose of {vehicle} at {} ns", pose.t_ns),
                    source: e,
                })?;
            self.write_message(vehicle, Stream::PoseFrame, &display, pose.t_ns, log_time_ns)?;
        }
        Ok(())
    }

    /// Writes a health report (publish time = its `t_ns`).
    pub fn write_health(
        &mut self,
        vehicle: &str,
        health: &v1::VehicleHealth,
        log_time_ns: i64,
    ) -> Result<()> {
        self.write_message(vehicle, Stream::Health, health, health.t_ns, log_time_ns)
    }

    /// Writes the summary and index and flushes the file.
    pub fn finish(mut self) -> Result<()> {
        self.out
            .finish()
            .map_err(|e| DatasetError::mcap(&self.path, e))?;
        // The BufWriter would swallow a write error on drop: flush explicitly.
        let mut file = self.out.into_inner();
        std::io::Write::flush(&mut file).map_err(|e| DatasetError::io(&self.path, e))
    }
}
