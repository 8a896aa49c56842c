//! # uavnav-dataset
//!
//! Streaming dataset I/O for uavnav: EuRoC/ASL folders (extended with `gnss0`) and MCAP
//! recordings, read and written, and converters between them. A flight's camera frames are never
//! all in memory: events are read lazily and merged in time order; truth is read fully (small).
//!
//! | module / item | what it holds |
//! |---|---|
//! | [`Dataset`] | opens an ASL folder or an `.mcap` file by path: config, origin, truth, [`EventStream`] |
//! | [`asl`] | the ASL layout ([`asl::layout`]), its reader ([`asl::AslDataset`]) and [`AslWriter`] |
//! | [`mcap_io`] | topics and times ([`mcap_io`] doc), [`McapWriter`], [`mcap_io::reader::McapDataset`], fleet [`mcap_io::reader::McapEvents`] |
//! | [`convert`] | [`convert::convert`] (by extension), [`convert::asl_to_mcap`], [`convert::mcap_to_asl`] |
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
pub mod mcap_io;
pub mod merge;
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
}

impl Format {
    /// `.mcap` (any case) is MCAP, anything else an ASL folder.
    pub fn of_path(path: &Path) -> Format {
        match path.extension().and_then(|e| e.to_str()) {
            Some(ext) if ext.eq_ignore_ascii_case("mcap") => Format::Mcap,
            _ => Format::Asl,
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
}

#[derive(Debug, Clone)]
enum Inner {
    Asl(AslDataset),
    Mcap(mcap_io::reader::McapDataset),
}

/// One vehicle's dataset, ASL folder or MCAP recording.
#[derive(Debug, Clone)]
pub struct Dataset {
    path: PathBuf,
    inner: Inner,
}

impl Dataset {
    /// Opens `path` with default options.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        Self::open_with(path, &ReadOptions::default())
    }

    /// Opens `path`: an `.mcap` file, or an ASL folder (the `mav0` folder or its parent).
    pub fn open_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<Self> {
        let path = path.as_ref();
        let inner = match Format::of_path(path) {
            Format::Mcap => Inner::Mcap(mcap_io::reader::McapDataset::open(
                path,
                options.vehicle.as_deref(),
            )?),
            Format::Asl => {
                if !path.is_dir() {
                    return Err(DatasetError::Unsupported {
                        path: path.to_owned(),
                        message: "not a folder (ASL) nor an .mcap file".into(),
                    });
                }
                Inner::Asl(AslDataset::open(path, options.missing_images)?)
            }
        };
        Ok(Dataset {
            path: path.to_owned(),
            inner,
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
        }
    }

    /// The vehicle id.
    pub fn vehicle_id(&self) -> &str {
        match &self.inner {
            Inner::Asl(d) => d.vehicle_id(),
            Inner::Mcap(d) => d.vehicle_id(),
        }
    }

    /// The vehicle configuration.
    pub fn config(&self) -> &VehicleConfig {
        match &self.inner {
            Inner::Asl(d) => d.config(),
            Inner::Mcap(d) => d.config(),
        }
    }

    /// The origin of the truth's local NED frame.
    pub fn origin(&self) -> Option<Lla> {
        match &self.inner {
            Inner::Asl(d) => d.origin(),
            Inner::Mcap(d) => d.origin(),
        }
    }

    /// The ground truth, if any.
    pub fn truth(&self) -> Option<&[TruthSample]> {
        match &self.inner {
            Inner::Asl(d) => d.truth(),
            Inner::Mcap(d) => d.truth(),
        }
    }

    /// A fresh, lazy stream of the sensor events in time order (each call starts again).
    pub fn events(&self) -> Result<EventStream> {
        Ok(match &self.inner {
            Inner::Asl(d) => {
                let skipped = Arc::new(AtomicUsize::new(0));
                EventStream {
                    inner: Events::Asl(merge::Merge::new(d.sources(skipped.clone())?)),
                    skipped,
                }
            }
            Inner::Mcap(d) => EventStream {
                inner: Events::Mcap(Box::new(d.events()?)),
                skipped: Arc::default(),
            },
        })
    }
}

#[derive(Debug)]
enum Events {
    Asl(merge::Merge),
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
            Events::Asl(m) => m.next(),
            Events::Mcap(m) => m.next().map(|r| r.map(|ve| ve.event)),
        }
    }
}
