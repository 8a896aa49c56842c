//! ASL ↔ MCAP conversion, one call each (the `uavnav convert` subcommand wraps [`convert`]); a
//! flight log converts to either (read only).
//!
//! Lossless for everything the ASL format holds: ASL → MCAP → ASL reproduces every `data.csv`
//! byte for byte (for folders written by [`AslWriter`]) and every image file. GNSS fix type and
//! satellite count exist only in MCAP (ASL rows read back as 3-D fixes).

use std::path::Path;

use uavnav_core::SensorEvent;

use crate::error::{DatasetError, Result};
use crate::{AslWriter, Dataset, Format, McapOptions, McapWriter, ReadOptions};

/// What a conversion wrote.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ConvertSummary {
    /// IMU samples.
    pub imu: usize,
    /// GNSS fixes.
    pub gnss: usize,
    /// Magnetometer samples.
    pub mag: usize,
    /// Barometer samples.
    pub baro: usize,
    /// Camera frames.
    pub frames: usize,
    /// Truth samples.
    pub truth: usize,
    /// Reference samples (not truth: e.g. the autopilot's estimate of a flight log).
    pub reference: usize,
    /// Source camera rows skipped because their image was missing.
    pub skipped_images: usize,
}

impl ConvertSummary {
    fn count(&mut self, e: &SensorEvent) {
        match e {
            SensorEvent::Imu(_) => self.imu += 1,
            SensorEvent::Gnss(_) => self.gnss += 1,
            SensorEvent::Mag(_) => self.mag += 1,
            SensorEvent::Baro(_) => self.baro += 1,
            SensorEvent::Camera(_) => self.frames += 1,
        }
    }
}

/// Converts `src` to `dst`, each an ASL folder or an `.mcap` file (chosen by extension), with
/// default options. Any direction works, including ASL → ASL (a normalising copy); `src` may also
/// be a flight log.
pub fn convert(src: &Path, dst: &Path) -> Result<ConvertSummary> {
    convert_with(src, dst, &ReadOptions::default())
}

/// [`convert`] with read options (a flight log's GNSS delay, damage handling, ...).
pub fn convert_with(src: &Path, dst: &Path, options: &ReadOptions) -> Result<ConvertSummary> {
    match Format::of_path(dst) {
        Format::Mcap => write_mcap(
            &Dataset::open_with(src, options)?,
            dst,
            &McapOptions::default(),
        ),
        Format::Asl => write_asl(&Dataset::open_with(src, options)?, dst),
        Format::Log => Err(DatasetError::Unsupported {
            path: dst.to_owned(),
            message: "flight logs are read, not written: give an ASL folder or an .mcap file"
                .into(),
        }),
    }
}

/// ASL folder → MCAP recording.
pub fn asl_to_mcap(src: &Path, dst: &Path, options: &McapOptions) -> Result<ConvertSummary> {
    write_mcap(&Dataset::open(src)?, dst, options)
}

/// MCAP recording → ASL folder (`vehicle` selects one of several vehicles).
pub fn mcap_to_asl(src: &Path, dst: &Path, vehicle: Option<&str>) -> Result<ConvertSummary> {
    let options = ReadOptions {
        vehicle: vehicle.map(str::to_owned),
        ..ReadOptions::default()
    };
    write_asl(&Dataset::open_with(src, &options)?, dst)
}

/// Writes any opened dataset as an MCAP recording. Log time = publish time = sensor time (no
/// receive time exists for recorded data); config and info are stamped with the first event's
/// time; truth and reference are interleaved in time order.
pub fn write_mcap(ds: &Dataset, dst: &Path, options: &McapOptions) -> Result<ConvertSummary> {
    let mut out = McapWriter::create(dst, options)?;
    let vehicle = ds.vehicle_id();
    let truth = ds.truth().unwrap_or(&[]);
    let mut stream = ds.events()?;
    let first = stream.next().transpose()?;
    let first_t = first
        .as_ref()
        .map(SensorEvent::t_ns)
        .or(truth.first().map(|s| s.t_ns))
        .unwrap_or(0)
        .max(0);
    out.write_config(vehicle, ds.config(), first_t)?;
    out.write_info(vehicle, ds.origin().as_ref(), first_t)?;
    let mut summary = ConvertSummary::default();
    let (reference, source) = ds
        .reference()
        .map_or((&[][..], None), |r| (&r.samples[..], r.source.as_deref()));
    let mut next_truth = 0;
    let mut next_reference = 0;
    for event in first.into_iter().map(Ok).chain(stream.by_ref()) {
        let event = event?;
        while let Some(s) = truth.get(next_truth).filter(|s| s.t_ns <= event.t_ns()) {
            out.write_truth(vehicle, s, s.t_ns)?;
            next_truth += 1;
        }
        while let Some(s) = reference
            .get(next_reference)
            .filter(|s| s.t_ns <= event.t_ns())
        {
            out.write_reference(vehicle, s, source, s.t_ns)?;
            next_reference += 1;
        }
        out.write_event(vehicle, &event, event.t_ns())?;
        summary.count(&event);
    }
    for s in &truth[next_truth..] {
        out.write_truth(vehicle, s, s.t_ns)?;
    }
    for s in &reference[next_reference..] {
        out.write_reference(vehicle, s, source, s.t_ns)?;
    }
    summary.truth = truth.len();
    summary.reference = reference.len();
    summary.skipped_images = stream.skipped_images();
    out.finish()?;
    Ok(summary)
}

/// Writes any opened dataset as an ASL folder.
pub fn write_asl(ds: &Dataset, dst: &Path) -> Result<ConvertSummary> {
    let mut out = AslWriter::create(dst, ds.vehicle_id(), ds.config(), ds.origin())?;
    let mut summary = ConvertSummary::default();
    let mut stream = ds.events()?;
    for event in stream.by_ref() {
        let event = event?;
        out.write_event(&event)?;
        summary.count(&event);
    }
    for s in ds.truth().unwrap_or(&[]) {
        out.write_truth(s)?;
        summary.truth += 1;
    }
    // The ASL layout has one slot for a trajectory: a reference fills it only without truth (as
    // in the shared real-flight conversions), marked as not ground truth.
    if let Some(r) = ds.reference().filter(|_| summary.truth == 0) {
        for s in &r.samples {
            out.write_reference(s, r.source.as_deref())?;
            summary.reference += 1;
        }
    }
    summary.skipped_images = stream.skipped_images();
    out.finish()?;
    Ok(summary)
}
