//! An autopilot's flight log (ArduPilot DataFlash `.BIN`, PX4 ULog `.ulg`, MAVLink
//! telemetry `.tlog`) opened as a dataset.
//!
//! The log is imported whole by `uavnav-logs` (a few MB; the importer needs every message to
//! derive the time base, filter the fixes and build the reference), then served like any other
//! dataset: the configuration the import derived (rates, noise, GNSS delay, airframe), the sensor
//! streams merged by the same rule as an ASL folder's (so a log and its ASL conversion give the
//! same event sequence), and the autopilot's own estimate as a [`Reference`] — never as truth.
//!
//! GNSS fixes stay stamped as logged; the autopilot's GNSS delay goes into
//! `GnssConfig::delay_ns`, which the estimator subtracts.

use std::path::Path;
use std::sync::Arc;

use uavnav_core::{BaroSample, GnssFix, ImuSample, Lla, MagSample, SensorEvent, VehicleConfig};
use uavnav_logs::{FlightLog, ImportOptions, LogKind};

use crate::error::{DatasetError, Result};
use crate::merge::{EventSource, Merge};
use crate::{ReadOptions, Reference};

/// The extensions recognised without looking at the content (any case).
pub const LOG_EXTENSIONS: [&str; 3] = ["bin", "ulg", "tlog"];

/// Whether `path` names a flight log by its extension.
pub fn has_log_extension(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| LOG_EXTENSIONS.iter().any(|l| e.eq_ignore_ascii_case(l)))
}

/// The sensor streams of an imported log, shared by every event stream opened on it.
#[derive(Debug)]
struct Streams {
    imu: Vec<ImuSample>,
    gnss: Vec<GnssFix>,
    mag: Vec<MagSample>,
    baro: Vec<BaroSample>,
}

/// An opened flight log.
#[derive(Debug, Clone)]
pub struct LogDataset {
    vehicle_id: String,
    kind: LogKind,
    config: VehicleConfig,
    origin: Option<Lla>,
    reference: Option<Reference>,
    notes: Vec<String>,
    streams: Arc<Streams>,
}

/// The vehicle id of a log: its file stem, with characters MCAP topics and keys cannot carry
/// replaced (`/` never occurs in a stem; spaces and dots are replaced for the Zenoh keys).
fn vehicle_id_of(path: &Path) -> String {
    let stem = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or_default();
    let id: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if id.is_empty() {
        crate::asl::reader::DEFAULT_VEHICLE_ID.to_owned()
    } else {
        id
    }
}

impl LogDataset {
    /// Reads and imports `path`. Decoding errors keep the importer's byte offset in their text.
    pub fn open(path: &Path, options: &ReadOptions) -> Result<Self> {
        let data = std::fs::read(path).map_err(|e| DatasetError::io(path, e))?;
        Self::from_bytes(path, &data, options)
    }

    /// Imports a log already read into memory (`path` names it in errors and gives the vehicle id).
    pub fn from_bytes(path: &Path, data: &[u8], options: &ReadOptions) -> Result<Self> {
        let import = ImportOptions {
            gnss_delay_s: options.gnss_delay_s,
            stop_at_damage: options.stop_at_damage,
            ..ImportOptions::default()
        };
        let log = uavnav_logs::import(data, &import).map_err(|error| DatasetError::Log {
            path: path.to_owned(),
            error,
        })?;
        Ok(Self::from_log(vehicle_id_of(path), log))
    }

    /// Wraps an imported log.
    pub fn from_log(vehicle_id: String, log: FlightLog) -> Self {
        let reference = (!log.reference.is_empty()).then(|| Reference {
            source: log.reference_name.clone(),
            samples: log.reference,
        });
        LogDataset {
            vehicle_id,
            kind: log.source,
            config: log.config,
            // The reference's frame is the only local frame a log defines.
            origin: reference.as_ref().and(log.reference_origin),
            reference,
            notes: log.notes,
            streams: Arc::new(Streams {
                imu: log.imu,
                gnss: log.gnss,
                mag: log.mag,
                baro: log.baro,
            }),
        }
    }

    /// The vehicle id (the file stem).
    pub fn vehicle_id(&self) -> &str {
        &self.vehicle_id
    }

    /// Which autopilot wrote the log.
    pub fn kind(&self) -> LogKind {
        self.kind
    }

    /// The configuration the import derived.
    pub fn config(&self) -> &VehicleConfig {
        &self.config
    }

    /// The origin of the reference's local NED frame.
    pub fn origin(&self) -> Option<Lla> {
        self.origin
    }

    /// The autopilot's own estimate.
    pub fn reference(&self) -> Option<&Reference> {
        self.reference.as_ref()
    }

    /// What the import dropped or assumed.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// The merged event stream (same tie rule as an ASL folder).
    pub(crate) fn merge(&self) -> Merge {
        let sources: Vec<Box<dyn EventSource>> = [Which::Imu, Which::Gnss, Which::Mag, Which::Baro]
            .into_iter()
            .map(|which| {
                Box::new(StreamSource {
                    streams: Arc::clone(&self.streams),
                    which,
                    next: 0,
                }) as Box<dyn EventSource>
            })
            .collect();
        Merge::new(sources)
    }
}

#[derive(Debug, Clone, Copy)]
enum Which {
    Imu,
    Gnss,
    Mag,
    Baro,
}

/// One sensor's samples of the shared streams, as an [`EventSource`].
struct StreamSource {
    streams: Arc<Streams>,
    which: Which,
    next: usize,
}

impl EventSource for StreamSource {
    fn next_event(&mut self) -> Option<Result<SensorEvent>> {
        let i = self.next;
        self.next += 1;
        let s = &self.streams;
        let event = match self.which {
            Which::Imu => s.imu.get(i).map(|x| SensorEvent::Imu(*x)),
            Which::Gnss => s.gnss.get(i).map(|x| SensorEvent::Gnss(*x)),
            Which::Mag => s.mag.get(i).map(|x| SensorEvent::Mag(*x)),
            Which::Baro => s.baro.get(i).map(|x| SensorEvent::Baro(*x)),
        };
        event.map(Ok)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vehicle_ids_from_file_names() {
        assert_eq!(
            vehicle_id_of(Path::new("/x/erle_copter_218.BIN")),
            "erle_copter_218"
        );
        assert_eq!(vehicle_id_of(Path::new("a b.c.ulg")), "a_b_c");
        assert_eq!(vehicle_id_of(Path::new(".ulg")), "_ulg");
        assert!(has_log_extension(Path::new("x.BIN")));
        assert!(has_log_extension(Path::new("x.ulg")));
        assert!(!has_log_extension(Path::new("x.mcap")));
    }
}
