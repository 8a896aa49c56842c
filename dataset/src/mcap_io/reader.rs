//! Reads MCAP recordings as a stream: a first pass collects configuration, origin and truth; the
//! event stream is a second, lazy pass (one message in memory at a time, plus a small reorder
//! window for batched IMU messages).

use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use prost::Message;
use uavnav_core::{
    BaroSample, CameraFrame, GnssFix, ImageFormat, ImuSample, Lla, MagSample, SensorEvent,
    TruthSample, VehicleConfig,
};
use uavnav_proto::{ConvertError, convert::sensors::imu_batch, v1};

use super::{Stream, parse_topic};
use crate::error::{DatasetError, Result};

/// Events held back to restore time order across channels (IMU batches span time). An event more
/// than this many events out of place is an error.
pub const REORDER_WINDOW: usize = 512;

fn open_messages(path: &Path) -> Result<mcap::io::MessageReader<BufReader<File>>> {
    let file = File::open(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            DatasetError::MissingFile {
                path: path.to_owned(),
                what: "MCAP recording".into(),
            }
        } else {
            DatasetError::io(path, e)
        }
    })?;
    Ok(mcap::io::MessageReader::new(BufReader::new(file)))
}

/// An opened MCAP recording, restricted to one vehicle.
#[derive(Debug, Clone)]
pub struct McapDataset {
    path: PathBuf,
    vehicle_id: String,
    config: VehicleConfig,
    has_config: bool,
    origin: Option<Lla>,
    truth: Option<Vec<TruthSample>>,
    reference: Option<crate::Reference>,
}

/// Where a message sits, for error messages.
fn context(topic: &str, sequence: u32, log_time: u64) -> String {
    format!("{topic} message seq {sequence} (log time {log_time} ns)")
}

fn decode<M: Message + Default>(path: &Path, msg: &mcap::Message<'_>) -> Result<M> {
    M::decode(msg.data.as_ref()).map_err(|e| {
        DatasetError::mcap(
            path,
            format!(
                "{}: undecodable: {e}",
                context(&msg.channel.topic, msg.sequence, msg.log_time)
            ),
        )
    })
}

fn invalid(path: &Path, msg: &mcap::Message<'_>, e: ConvertError) -> DatasetError {
    DatasetError::Invalid {
        path: path.to_owned(),
        context: context(&msg.channel.topic, msg.sequence, msg.log_time),
        source: e,
    }
}

/// The vehicles that have at least one `/uavnav/{vehicle}/...` channel, sorted.
pub fn vehicles(path: &Path) -> Result<Vec<String>> {
    let mut out = BTreeSet::new();
    for msg in open_messages(path)? {
        let msg = msg.map_err(|e| DatasetError::mcap(path, e))?;
        if let Some((v, _)) = parse_topic(&msg.channel.topic) {
            out.insert(v.to_owned());
        }
    }
    Ok(out.into_iter().collect())
}

impl McapDataset {
    /// Opens a recording for `vehicle`, or for its only vehicle when `None`.
    pub fn open(path: &Path, vehicle: Option<&str>) -> Result<Self> {
        let vehicle_id = match vehicle {
            Some(v) => v.to_owned(),
            None => {
                let all = vehicles(path)?;
                match all.as_slice() {
                    [only] => only.clone(),
                    [] => {
                        return Err(DatasetError::mcap(
                            path,
                            "no /uavnav/{vehicle}/... channels",
                        ));
                    }
                    many => {
                        return Err(DatasetError::mcap(
                            path,
                            format!("holds several vehicles ({}): choose one", many.join(", ")),
                        ));
                    }
                }
            }
        };
        let mut ds = McapDataset {
            path: path.to_owned(),
            vehicle_id,
            config: VehicleConfig::default(),
            has_config: false,
            origin: None,
            truth: None,
            reference: None,
        };
        ds.read_fixed()?;
        Ok(ds)
    }

    /// First pass: the first configuration and info, and all truth of the vehicle.
    fn read_fixed(&mut self) -> Result<()> {
        let path = self.path.clone();
        let mut truth = Vec::new();
        let mut reference = Vec::new();
        let mut reference_source = None;
        let mut seen_info = false;
        for msg in open_messages(&path)? {
            let msg = msg.map_err(|e| DatasetError::mcap(&path, e))?;
            let Some((vehicle, stream)) = parse_topic(&msg.channel.topic) else {
                continue;
            };
            if vehicle != self.vehicle_id {
                continue;
            }
            match stream {
                Stream::Config if !self.has_config => {
                    let wire: v1::VehicleConfig = decode(&path, &msg)?;
                    self.config =
                        VehicleConfig::try_from(&wire).map_err(|e| invalid(&path, &msg, e))?;
                    self.has_config = true;
                }
                Stream::Info if !seen_info => {
                    let info: v1::DatasetInfo = decode(&path, &msg)?;
                    self.origin = info
                        .origin
                        .as_ref()
                        .map(Lla::try_from)
                        .transpose()
                        .map_err(|e| invalid(&path, &msg, e.within("origin")))?;
                    seen_info = true;
                }
                Stream::Truth => {
                    let wire: v1::TruthSample = decode(&path, &msg)?;
                    truth.push(TruthSample::try_from(&wire).map_err(|e| invalid(&path, &msg, e))?);
                }
                Stream::Reference => {
                    let wire: v1::TruthSample = decode(&path, &msg)?;
                    reference
                        .push(TruthSample::try_from(&wire).map_err(|e| invalid(&path, &msg, e))?);
                    if reference_source.is_none() {
                        reference_source = msg
                            .channel
                            .metadata
                            .get(super::REFERENCE_METADATA_KEY)
                            .cloned();
                    }
                }
                _ => {}
            }
        }
        truth.sort_by_key(|s| s.t_ns);
        self.truth = (!truth.is_empty()).then_some(truth);
        reference.sort_by_key(|s| s.t_ns);
        self.reference = (!reference.is_empty()).then_some(crate::Reference {
            source: reference_source,
            samples: reference,
        });
        Ok(())
    }

    /// The recording.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The vehicle.
    pub fn vehicle_id(&self) -> &str {
        &self.vehicle_id
    }

    /// The first recorded configuration (the default when the recording has none; see
    /// [`Self::has_config`]).
    pub fn config(&self) -> &VehicleConfig {
        &self.config
    }

    /// Whether the recording holds a configuration for the vehicle.
    pub fn has_config(&self) -> bool {
        self.has_config
    }

    /// The truth origin.
    pub fn origin(&self) -> Option<Lla> {
        self.origin
    }

    /// The truth, if recorded.
    pub fn truth(&self) -> Option<&[TruthSample]> {
        self.truth.as_deref()
    }

    /// The reference (`/uavnav/{vehicle}/reference`), if recorded.
    pub fn reference(&self) -> Option<&crate::Reference> {
        self.reference.as_ref()
    }

    /// A fresh, lazy, time-ordered stream of the vehicle's sensor events.
    pub fn events(&self) -> Result<McapEvents> {
        McapEvents::open(&self.path, Some(self.vehicle_id.clone()))
    }
}

/// One sensor event of a fleet recording.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleEvent {
    /// The vehicle.
    pub vehicle_id: Arc<str>,
    /// The event.
    pub event: SensorEvent,
}

/// Time-ordered sensor events from a recording (one vehicle, or all with `vehicle = None`).
pub struct McapEvents {
    path: PathBuf,
    messages: mcap::io::MessageReader<BufReader<File>>,
    vehicle: Option<String>,
    vehicle_ids: BTreeMap<String, Arc<str>>,
    /// (t_ns, arrival counter) → event; the counter keeps equal times in file order.
    pending: BTreeMap<(i64, u64), VehicleEvent>,
    counter: u64,
    last_t_ns: Option<i64>,
    done: bool,
}

impl std::fmt::Debug for McapEvents {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapEvents")
            .field("path", &self.path)
            .field("vehicle", &self.vehicle)
            .finish()
    }
}

impl McapEvents {
    /// Streams the events of `vehicle` (or of every vehicle) in `path`.
    pub fn open(path: &Path, vehicle: Option<String>) -> Result<Self> {
        Ok(McapEvents {
            path: path.to_owned(),
            messages: open_messages(path)?,
            vehicle,
            vehicle_ids: BTreeMap::new(),
            pending: BTreeMap::new(),
            counter: 0,
            last_t_ns: None,
            done: false,
        })
    }

    /// Decodes one message into zero or more events, queued in `pending`.
    fn queue(&mut self, msg: &mcap::Message<'_>) -> Result<()> {
        let Some((vehicle, stream)) = parse_topic(&msg.channel.topic) else {
            return Ok(());
        };
        if self.vehicle.as_deref().is_some_and(|v| v != vehicle) {
            return Ok(());
        }
        let path = self.path.clone();
        let events: Vec<SensorEvent> = match stream {
            Stream::Imu => {
                let batch: v1::ImuBatch = decode(&path, msg)?;
                let samples: Vec<ImuSample> =
                    imu_batch(&batch).map_err(|e| invalid(&path, msg, e))?;
                samples.into_iter().map(SensorEvent::Imu).collect()
            }
            Stream::Gnss => {
                let wire: v1::GnssFix = decode(&path, msg)?;
                vec![SensorEvent::Gnss(
                    GnssFix::try_from(&wire).map_err(|e| invalid(&path, msg, e))?,
                )]
            }
            Stream::Mag => {
                let wire: v1::MagSample = decode(&path, msg)?;
                vec![SensorEvent::Mag(
                    MagSample::try_from(&wire).map_err(|e| invalid(&path, msg, e))?,
                )]
            }
            Stream::Baro => {
                let wire: v1::BaroSample = decode(&path, msg)?;
                vec![SensorEvent::Baro(
                    BaroSample::try_from(&wire).map_err(|e| invalid(&path, msg, e))?,
                )]
            }
            Stream::Camera => {
                let image: foxglove::messages::CompressedImage = decode(&path, msg)?;
                vec![SensorEvent::Camera(
                    camera_frame(&image, msg.publish_time).map_err(|e| invalid(&path, msg, e))?,
                )]
            }
            _ => return Ok(()),
        };
        let id = match self.vehicle_ids.get(vehicle) {
            Some(id) => id.clone(),
            None => {
                let id: Arc<str> = Arc::from(vehicle);
                self.vehicle_ids.insert(vehicle.to_owned(), id.clone());
                id
            }
        };
        for event in events {
            self.counter += 1;
            self.pending.insert(
                (event.t_ns(), self.counter),
                VehicleEvent {
                    vehicle_id: id.clone(),
                    event,
                },
            );
        }
        Ok(())
    }

    /// Pops the earliest pending event, checking it is not before one already emitted.
    fn pop(&mut self) -> Option<Result<VehicleEvent>> {
        let ((t_ns, _), ev) = self.pending.pop_first()?;
        if let Some(prev) = self.last_t_ns.filter(|&p| t_ns < p) {
            self.done = true;
            return Some(Err(DatasetError::mcap(
                &self.path,
                format!(
                    "event at {t_ns} ns comes after {prev} ns: out of order beyond the {REORDER_WINDOW}-event window"
                ),
            )));
        }
        self.last_t_ns = Some(t_ns);
        Some(Ok(ev))
    }
}

/// A `foxglove.CompressedImage` from the camera channel as a core frame.
fn camera_frame(
    image: &foxglove::messages::CompressedImage,
    publish_time: u64,
) -> Result<CameraFrame, ConvertError> {
    let wire = uavnav_proto::topics::camera_frame_from_image(image.clone(), publish_time)?;
    let frame = CameraFrame::try_from(&wire)?;
    debug_assert!(matches!(frame.format, ImageFormat::Jpeg | ImageFormat::Png));
    Ok(frame)
}

impl Iterator for McapEvents {
    type Item = Result<VehicleEvent>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        while self.pending.len() <= REORDER_WINDOW {
            match self.messages.next() {
                Some(Ok(msg)) => {
                    if let Err(e) = self.queue(&msg) {
                        self.done = true;
                        return Some(Err(e));
                    }
                }
                Some(Err(e)) => {
                    self.done = true;
                    return Some(Err(DatasetError::mcap(&self.path, e)));
                }
                None => break,
            }
        }
        self.pop()
    }
}
