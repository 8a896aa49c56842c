//! # uavnav-dataset
//!
//! Streaming dataset I/O for uavnav: EuRoC/ASL folders (extended with `gnss0`) and MCAP
//! recordings, read and written, and converters between them; autopilot flight logs (ArduPilot
//! DataFlash `.BIN`, PX4 ULog `.ulg`, MAVLink telemetry `.tlog`) are read as datasets too. A flight's camera frames are never
//! all in memory: events are read lazily and merged in time order; truth is read fully (small).
//!
//! Truth and reference are kept apart: [`Dataset::truth`] is ground truth (a simulator's, a
//! motion-capture system's); [`Dataset::reference`] is another estimator's output, such as the
//! autopilot's own EKF in a flight log, which can be compared against but is not truth.
//!
//! | module / item | what it holds |
//! |---|---|
//! | [`Dataset`] | opens an ASL folder, an `.mcap` file or a flight log by path: config, origin, truth or [`Reference`], [`EventStream`] |
//! | [`asl`] | the ASL layout ([`asl::layout`]), its reader ([`asl::AslDataset`]) and [`AslWriter`] |
//! | [`mcap_io`] | topics and times ([`mcap_io`] doc), [`McapWriter`], [`mcap_io::reader::McapDataset`], fleet [`mcap_io::reader::McapEvents`] |
//! | [`convert`] | [`convert::convert`] (by extension), [`convert::asl_to_mcap`], [`convert::mcap_to_asl`] |
//! | [`flight_log`] | a `uavnav_logs::FlightLog` as a dataset ([`flight_log::LogDataset`]) |
//! | [`poses`] | pose outputs as `poses.csv` rows and TUM lines |
//! | [`error`] | [`DatasetError`]: every error names the file, and the line where there is one |
//! | [`yaml`], [`csv`], [`merge`] | the `sensor.yaml` subset parser, the streaming `data.csv` reader, the k-way time merge |
//!
//! Quick use:
//! ```no_run
//! let ds = uavnav_dataset::Dataset::open("flight.mcap")?;
//! println!("{} {:?}", ds.vehicle_id(), ds.config().camera.is_some());
//! for event in ds.events()? {
//!     let event = event?; // uavnav_core::SensorEvent, in time order
//! }
//! # Ok::<(), uavnav_dataset::DatasetError>(())
//! ```

pub mod asl;
pub mod convert;
pub mod csv;
pub mod error;
pub mod flight_log;
pub mod mcap_io;
pub mod merge;
pub mod poses;
pub mod yaml;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use uavnav_core::{Lla, SensorEvent, TruthSample, VehicleConfig};

pub use asl::{AslDataset, AslWriter, MissingImages};
pub use error::{DatasetError, Result};
pub use mcap_io::writer::{Compression, McapOptions, McapWriter};

/// The on-disk format of a dataset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// An ASL/EuRoC folder.
    Asl,
    /// An MCAP recording.
    Mcap,
    /// An autopilot flight log (ArduPilot DataFlash `.BIN`, PX4 ULog `.ulg`, MAVLink telemetry `.tlog`),
    /// read only.
    Log,
}

impl Format {
    /// `.mcap` (any case) is MCAP, `.bin` and `.ulg` (any case) a flight log, anything else an
    /// ASL folder ([`Dataset::open_with`] also recognises a flight log by its content).
    pub fn of_path(path: &Path) -> Format {
        match path.extension().and_then(|e| e.to_str()) {
            Some(ext) if ext.eq_ignore_ascii_case("mcap") => Format::Mcap,
            _ if flight_log::has_log_extension(path) => Format::Log,
            _ => Format::Asl,
        }
    }
}

/// Another estimator's output recorded with the data (an autopilot's own EKF): something to
/// compare against, not ground truth. In the frame of [`Dataset::origin`].
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    /// What produced it (`"EKF1"`, a PX4 topic), when known.
    pub source: Option<String>,
    /// The samples, in time order (EuRoC ground-truth fields; biases 0 when not logged).
    pub samples: Vec<TruthSample>,
}

impl Reference {
    /// How reports name it: `reference (autopilot estimate, EKF1)`.
    pub fn label(&self) -> String {
        match &self.source {
            Some(s) => format!("reference (autopilot estimate, {s})"),
            None => "reference (autopilot estimate)".to_owned(),
        }
    }
}

/// How to open a dataset.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReadOptions {
    /// For MCAP recordings with several vehicles: which one (required then).
    pub vehicle: Option<String>,
    /// What to do with ASL camera rows whose image file is missing.
    pub missing_images: MissingImages,
    /// GNSS delay, s, replacing the dataset's (`GnssConfig::delay_ns`; for a flight log, the
    /// autopilot's parameter).
    pub gnss_delay_s: Option<f64>,
    /// Flight logs: import what comes before the first damaged byte (a log cut by a power loss)
    /// instead of failing; the import's notes say where it stopped.
    pub stop_at_damage: bool,
}

#[derive(Debug, Clone)]
enum Inner {
    Asl(AslDataset),
    Mcap(mcap_io::reader::McapDataset),
    Log(flight_log::LogDataset),
}

/// One vehicle's dataset: ASL folder, MCAP recording or flight log.
#[derive(Debug, Clone)]
pub struct Dataset {
    path: PathBuf,
    inner: Inner,
    /// The configuration with [`ReadOptions::gnss_delay_s`] applied.
    config: VehicleConfig,
}

/// Longest GNSS delay accepted from [`ReadOptions::gnss_delay_s`], s (the `gnss0/sensor.yaml`
/// bound).
pub use asl::sensor_yaml::MAX_GNSS_DELAY_S;

impl Dataset {
    /// Opens `path` with default options.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        Self::open_with(path, &ReadOptions::default())
    }

    /// Opens `path`: an `.mcap` file, a flight log (`.BIN`, `.ulg`, or any file whose first bytes
    /// are a DataFlash message or the ULog magic), or an ASL folder (the `mav0` folder or its
    /// parent).
    pub fn open_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<Self> {
        let path = path.as_ref();
        if let Some(d) = options.gnss_delay_s
            && !(0.0..=MAX_GNSS_DELAY_S).contains(&d)
        {
            return Err(DatasetError::Unsupported {
                path: path.to_owned(),
                message: format!("GNSS delay {d} s is outside 0..={MAX_GNSS_DELAY_S} s"),
            });
        }
        let inner = match Format::of_path(path) {
            Format::Mcap => Inner::Mcap(mcap_io::reader::McapDataset::open(
                path,
                options.vehicle.as_deref(),
            )?),
            Format::Log => Inner::Log(flight_log::LogDataset::open(path, options)?),
            Format::Asl if path.is_file() => {
                // A log under another name (`log.1`, `00000042`): recognised by its first bytes.
                let data = std::fs::read(path).map_err(|e| DatasetError::io(path, e))?;
                match flight_log::LogDataset::from_bytes(path, &data, options) {
                    Ok(log) => Inner::Log(log),
                    Err(DatasetError::Log {
                        error: uavnav_logs::LogError::UnknownFormat,
                        ..
                    }) => {
                        return Err(DatasetError::Unsupported {
                            path: path.to_owned(),
                            message: "not a folder (ASL), an .mcap file nor a flight log \
                                      (ArduPilot .BIN, PX4 .ulg, MAVLink .tlog)"
                                .into(),
                        });
                    }
                    Err(e) => return Err(e),
                }
            }
            Format::Asl => {
                if !path.is_dir() {
                    return Err(DatasetError::Unsupported {
                        path: path.to_owned(),
                        message: "not a folder (ASL), an .mcap file nor a flight log".into(),
                    });
                }
                Inner::Asl(AslDataset::open(path, options.missing_images)?)
            }
        };
        let mut config = match &inner {
            Inner::Asl(d) => d.config().clone(),
            Inner::Mcap(d) => d.config().clone(),
            Inner::Log(d) => d.config().clone(),
        };
        if let (Some(d), Some(g)) = (options.gnss_delay_s, config.gnss.as_mut()) {
            g.delay_ns = uavnav_core::s_to_ns(d);
        }
        Ok(Dataset {
            path: path.to_owned(),
            inner,
            config,
        })
    }

    /// The path it was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The format.
    pub fn format(&self) -> Format {
        match self.inner {
            Inner::Asl(_) => Format::Asl,
            Inner::Mcap(_) => Format::Mcap,
            Inner::Log(_) => Format::Log,
        }
    }

    /// The vehicle id.
    pub fn vehicle_id(&self) -> &str {
        match &self.inner {
            Inner::Asl(d) => d.vehicle_id(),
            Inner::Mcap(d) => d.vehicle_id(),
            Inner::Log(d) => d.vehicle_id(),
        }
    }

    /// The vehicle configuration (with [`ReadOptions::gnss_delay_s`] applied).
    pub fn config(&self) -> &VehicleConfig {
        &self.config
    }

    /// The origin of the local NED frame of the truth, or of the reference when there is no truth.
    pub fn origin(&self) -> Option<Lla> {
        match &self.inner {
            Inner::Asl(d) => d.origin(),
            Inner::Mcap(d) => d.origin(),
            Inner::Log(d) => d.origin(),
        }
    }

    /// The ground truth, if any (never an autopilot's estimate: see [`Self::reference`]).
    pub fn truth(&self) -> Option<&[TruthSample]> {
        match &self.inner {
            Inner::Asl(d) => d.truth(),
            Inner::Mcap(d) => d.truth(),
            Inner::Log(_) => None,
        }
    }

    /// Another estimator's output recorded with the data (a flight log's autopilot EKF; an ASL
    /// folder whose `state_groundtruth_estimate0` says it is not ground truth; an MCAP
    /// `reference` topic), if any.
    pub fn reference(&self) -> Option<&Reference> {
        match &self.inner {
            Inner::Asl(d) => d.reference(),
            Inner::Mcap(d) => d.reference(),
            Inner::Log(d) => d.reference(),
        }
    }

    /// What the reader dropped or assumed (a flight log's import notes, an ASL folder's trim from
    /// its `conversion.json`); empty otherwise.
    pub fn notes(&self) -> &[String] {
        match &self.inner {
            Inner::Log(d) => d.notes(),
            Inner::Asl(d) => d.notes(),
            Inner::Mcap(_) => &[],
        }
    }

    /// A fresh, lazy stream of the sensor events in time order (each call starts again).
    pub fn events(&self) -> Result<EventStream> {
        Ok(match &self.inner {
            Inner::Asl(d) => {
                let skipped = Arc::new(AtomicUsize::new(0));
                EventStream {
                    inner: Events::Merge(merge::Merge::new(d.sources(skipped.clone())?)),
                    skipped,
                }
            }
            Inner::Mcap(d) => EventStream {
                inner: Events::Mcap(Box::new(d.events()?)),
                skipped: Arc::default(),
            },
            Inner::Log(d) => EventStream {
                inner: Events::Merge(d.merge()),
                skipped: Arc::default(),
            },
        })
    }
}

#[derive(Debug)]
enum Events {
    Merge(merge::Merge),
    Mcap(Box<mcap_io::reader::McapEvents>),
}

/// Time-ordered sensor events of one vehicle. The first error ends the stream.
#[derive(Debug)]
pub struct EventStream {
    inner: Events,
    skipped: Arc<AtomicUsize>,
}

impl EventStream {
    /// Camera rows skipped so far because their image file is missing (ASL, [`MissingImages::Skip`]).
    pub fn skipped_images(&self) -> usize {
        self.skipped.load(Ordering::Relaxed)
    }
}

impl Iterator for EventStream {
    type Item = Result<SensorEvent>;

    fn next(&mut self) -> Option<Self::Item> {
        match &mut self.inner {
            Events::Merge(m) => m.next(),
            Events::Mcap(m) => m.next().map(|r| r.map(|ve| ve.event)),
        }
    }
}
