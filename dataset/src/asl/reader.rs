//! Reads an ASL/EuRoC folder: configuration and truth up front, sensor events streamed lazily.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use uavnav_core::{
    BaroSample, CameraFrame, FixType, GnssFix, GnssVelocity, ImageFormat, ImuSample, Lla,
    MagSample, SensorEvent, TruthSample, VehicleConfig,
};

use super::layout::*;
use super::sensor_yaml;
use crate::csv::{CsvReader, Monotonic};
use crate::error::{DatasetError, Result};
use crate::merge::EventSource;

/// What to do with a `cam0/data.csv` row whose image file does not exist.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MissingImages {
    /// Skip the row and count it (real EuRoC folders have such rows).
    #[default]
    Skip,
    /// Fail with [`DatasetError::Image`].
    Error,
}

/// An opened ASL folder (the `mav0` folder or its parent).
#[derive(Debug, Clone)]
pub struct AslDataset {
    mav: PathBuf,
    vehicle_id: String,
    config: VehicleConfig,
    origin: Option<Lla>,
    truth: Option<Vec<TruthSample>>,
    reference: Option<crate::Reference>,
    missing_images: MissingImages,
    /// The rotation the IMU samples are read through (`conversion.json`'s ArduPilot trim).
    vehicle_from_board: Option<nalgebra::Rotation3<f64>>,
    /// What the reader assumed (the trim it applied).
    notes: Vec<String>,
}

/// The default vehicle id of an ASL folder without `body.yaml`.
pub const DEFAULT_VEHICLE_ID: &str = "uav0";

impl AslDataset {
    /// Opens a folder: reads every `sensor.yaml`, `body.yaml` and the truth (if any).
    pub fn open(path: &Path, missing_images: MissingImages) -> Result<Self> {
        let mav = if path.join(MAV).is_dir() {
            path.join(MAV)
        } else {
            path.to_owned()
        };
        let imu_dir = mav.join(IMU);
        if !imu_dir.is_dir() {
            return Err(DatasetError::MissingFile {
                path: imu_dir,
                what: "an ASL dataset needs mav0/imu0 (is this an ASL/EuRoC folder?)".into(),
            });
        }
        let imu = sensor_yaml::read_imu(&imu_dir.join(SENSOR_YAML))?;
        let gnss = sensor_dir(&mav, GNSS)
            .map(|d| sensor_yaml::read_gnss(&d.join(SENSOR_YAML)))
            .transpose()?;
        let mut mag = sensor_dir(&mav, MAG)
            .map(|d| sensor_yaml::read_mag(&d.join(SENSOR_YAML)))
            .transpose()?;
        let vehicle_from_board = match mav.parent() {
            Some(root) => super::conversion::vehicle_from_board(root)?,
            None => None,
        };
        if let (Some(r), Some(m)) = (vehicle_from_board, mag.as_mut()) {
            uavnav_logs::trim::rotate_mag_config(&r, m);
        }
        let baro = sensor_dir(&mav, BARO)
            .map(|d| sensor_yaml::read_baro(&d.join(SENSOR_YAML)))
            .transpose()?;
        let camera = sensor_dir(&mav, CAM)
            .map(|d| sensor_yaml::read_camera(&d.join(SENSOR_YAML)))
            .transpose()?;
        let body = sensor_yaml::read_body(&mav.join(BODY_YAML))?;
        let truth_dir = mav.join(TRUTH);
        let origin = sensor_yaml::read_origin(&truth_dir.join(SENSOR_YAML))?;
        let truth_csv = truth_dir.join(DATA_CSV);
        let mut truth = truth_csv
            .exists()
            .then(|| read_truth(&truth_csv))
            .transpose()?;
        // EuRoC has one slot for a reference trajectory; a converted flight log fills it with the
        // autopilot's estimate and says so in its sensor.yaml: that is a reference, not truth.
        let reference = match sensor_yaml::read_reference_marker(&truth_dir.join(SENSOR_YAML))? {
            Some(source) => truth
                .take()
                .map(|samples| crate::Reference { source, samples }),
            None => None,
        };
        Ok(AslDataset {
            mav,
            vehicle_id: body
                .vehicle_id
                .unwrap_or_else(|| DEFAULT_VEHICLE_ID.to_owned()),
            config: VehicleConfig {
                imu,
                gnss,
                mag,
                baro,
                camera,
                terrain_elevation_m: body.terrain_elevation_m,
                profile: body.profile,
                airframe: body.airframe,
            },
            origin,
            truth,
            reference,
            missing_images,
            vehicle_from_board,
            notes: vehicle_from_board
                .map(|r| {
                    vec![uavnav_logs::trim::note(
                        &r,
                        super::conversion::CONVERSION_JSON,
                    )]
                })
                .unwrap_or_default(),
        })
    }

    /// What the reader assumed (the ArduPilot trim it read the IMU through).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// The rotation from the board frame the IMU was logged in into the vehicle frame, when the
    /// folder's `conversion.json` states an ArduPilot trim (see [`super::conversion`]): the IMU
    /// samples are read through it and the compass's `body_from_mag` includes it.
    pub fn vehicle_from_board(&self) -> Option<nalgebra::Rotation3<f64>> {
        self.vehicle_from_board
    }

    /// The `mav0` folder.
    pub fn mav_dir(&self) -> &Path {
        &self.mav
    }

    /// The vehicle id (`body.yaml` `vehicle_id`, else [`DEFAULT_VEHICLE_ID`]).
    pub fn vehicle_id(&self) -> &str {
        &self.vehicle_id
    }

    /// The vehicle configuration from the `sensor.yaml` files and `body.yaml`.
    pub fn config(&self) -> &VehicleConfig {
        &self.config
    }

    /// The origin of the truth's local NED frame.
    pub fn origin(&self) -> Option<Lla> {
        self.origin
    }

    /// The ground truth, if the folder has it.
    pub fn truth(&self) -> Option<&[TruthSample]> {
        self.truth.as_deref()
    }

    /// The reference (`state_groundtruth_estimate0` marked as not ground truth), if any.
    pub fn reference(&self) -> Option<&crate::Reference> {
        self.reference.as_ref()
    }

    /// The event sources (IMU, GNSS, magnetometer, barometer, camera), each streaming its
    /// `data.csv`.
    pub(crate) fn sources(&self, skipped: Arc<AtomicUsize>) -> Result<Vec<Box<dyn EventSource>>> {
        let mut out: Vec<Box<dyn EventSource>> = vec![Box::new(ImuSource::open(
            &self.mav.join(IMU).join(DATA_CSV),
            self.vehicle_from_board,
        )?)];
        if self.config.gnss.is_some() {
            out.push(Box::new(RowSource::open(
                &self.mav.join(GNSS).join(DATA_CSV),
                GNSS_COLUMNS,
                parse_gnss,
            )?));
        }
        if self.config.mag.is_some() {
            out.push(Box::new(RowSource::open(
                &self.mav.join(MAG).join(DATA_CSV),
                MAG_COLUMNS,
                parse_mag,
            )?));
        }
        if self.config.baro.is_some() {
            out.push(Box::new(RowSource::open(
                &self.mav.join(BARO).join(DATA_CSV),
                BARO_COLUMNS,
                parse_baro,
            )?));
        }
        if self.config.camera.is_some() {
            let dir = self.mav.join(CAM);
            out.push(Box::new(CameraSource::open(
                &dir,
                self.missing_images,
                skipped,
            )?));
        }
        Ok(out)
    }
}

/// A sensor folder that exists (its `sensor.yaml` is then required).
fn sensor_dir(mav: &Path, name: &str) -> Option<PathBuf> {
    let d = mav.join(name);
    d.is_dir().then_some(d)
}

/// Reads the whole truth file (small: 17 numbers per row).
pub fn read_truth(path: &Path) -> Result<Vec<TruthSample>> {
    let mut csv = CsvReader::open(path, TRUTH_COLUMNS)?;
    let mut order = Monotonic::default();
    let mut out = Vec::new();
    while let Some(row) = csv.next_row() {
        let row = row?;
        let t_ns = row.i64(0)?;
        order.check(path, row.line(), t_ns)?;
        let p: [f64; 3] = row.f64s(1)?;
        let q: [f64; 4] = row.f64s(4)?;
        let v: [f64; 3] = row.f64s(8)?;
        let bw: [f64; 3] = row.f64s(11)?;
        let ba: [f64; 3] = row.f64s(14)?;
        out.push(TruthSample {
            t_ns,
            pos_ned_m: Vector3::from(p),
            nav_from_body: unit_quaternion(path, row.line(), q)?,
            vel_ned_mps: Vector3::from(v),
            gyro_bias_radps: Vector3::from(bw),
            accel_bias_mps2: Vector3::from(ba),
        });
    }
    Ok(out)
}

/// A quaternion from a CSV row: kept bit-exact when already unit (round trips), else normalised.
fn unit_quaternion(path: &Path, line: usize, q: [f64; 4]) -> Result<UnitQuaternion<f64>> {
    let raw = Quaternion::new(q[0], q[1], q[2], q[3]);
    let norm = raw.norm();
    if (norm - 1.0).abs() > 1e-2 {
        return Err(DatasetError::parse(
            path,
            line,
            format!("quaternion norm {norm} is not 1"),
        ));
    }
    Ok(if (norm - 1.0).abs() <= 4.0 * f64::EPSILON {
        UnitQuaternion::new_unchecked(raw)
    } else {
        UnitQuaternion::from_quaternion(raw)
    })
}

struct ImuSource {
    csv: CsvReader,
    order: Monotonic,
    /// Applied to every sample (see [`AslDataset::vehicle_from_board`]).
    rotation: Option<nalgebra::Rotation3<f64>>,
}

impl ImuSource {
    fn open(path: &Path, rotation: Option<nalgebra::Rotation3<f64>>) -> Result<Self> {
        Ok(ImuSource {
            csv: CsvReader::open(path, IMU_COLUMNS)?,
            order: Monotonic::default(),
            rotation,
        })
    }
}

impl EventSource for ImuSource {
    fn next_event(&mut self) -> Option<Result<SensorEvent>> {
        let row = match self.csv.next_row()? {
            Ok(r) => r,
            Err(e) => return Some(Err(e)),
        };
        let parse = || -> Result<SensorEvent> {
            let t_ns = row.i64(0)?;
            let w: [f64; 3] = row.f64s(1)?;
            let a: [f64; 3] = row.f64s(4)?;
            let s = ImuSample {
                t_ns,
                gyro_radps: Vector3::from(w),
                accel_mps2: Vector3::from(a),
            };
            Ok(SensorEvent::Imu(match &self.rotation {
                Some(r) => uavnav_logs::trim::rotate_imu(r, &s),
                None => s,
            }))
        };
        let line = row.line();
        let ev = parse();
        Some(ev.and_then(|ev| {
            self.order
                .check(self.csv.path(), line, ev.t_ns())
                .map(|()| ev)
        }))
    }
}

fn parse_gnss(row: &crate::csv::Row<'_>) -> Result<SensorEvent> {
    let t_ns = row.i64(0)?;
    let pos: [f64; 3] = row.f64s(1)?;
    let (vn, ve, vd) = (row.opt_f64(4)?, row.opt_f64(5)?, row.opt_f64(6)?);
    let (sigma_h_m, sigma_v_m) = (row.f64(7)?, row.f64(8)?);
    let sigma_vel = row.opt_f64(9)?;
    // Velocity is optional as a whole (north, east and sigma_velocity all present or all empty);
    // the vertical component is optional on its own.
    let velocity = match (vn, ve, sigma_vel) {
        (Some(north_mps), Some(east_mps), Some(sigma_mps)) => Some(GnssVelocity {
            north_mps,
            east_mps,
            down_mps: vd,
            sigma_mps,
        }),
        (None, None, None) if vd.is_none() => None,
        _ => {
            return Err(row.invalid(
                "v_north, v_east and sigma_velocity must be all given or all empty \
                 (v_down may be empty on its own)",
            ));
        }
    };
    // ASL rows carry no fix type or satellite count: a row is a 3-D fix.
    Ok(SensorEvent::Gnss(GnssFix {
        t_ns,
        lat_deg: pos[0],
        lon_deg: pos[1],
        alt_m: pos[2],
        velocity,
        sigma_h_m,
        sigma_v_m,
        fix_type: FixType::Fix3d,
        num_sats: 0,
    }))
}

fn parse_mag(row: &crate::csv::Row<'_>) -> Result<SensorEvent> {
    Ok(SensorEvent::Mag(MagSample {
        t_ns: row.i64(0)?,
        field_t: Vector3::from(row.f64s::<3>(1)?),
    }))
}

fn parse_baro(row: &crate::csv::Row<'_>) -> Result<SensorEvent> {
    Ok(SensorEvent::Baro(BaroSample {
        t_ns: row.i64(0)?,
        pressure_pa: row.f64(1)?,
        temperature_degc: row.opt_f64(2)?,
    }))
}

/// A sensor whose rows each parse to one event on their own (GNSS, magnetometer, barometer).
struct RowSource {
    csv: CsvReader,
    order: Monotonic,
    parse: fn(&crate::csv::Row<'_>) -> Result<SensorEvent>,
}

impl RowSource {
    fn open(
        path: &Path,
        columns: &[&'static str],
        parse: fn(&crate::csv::Row<'_>) -> Result<SensorEvent>,
    ) -> Result<Self> {
        Ok(RowSource {
            csv: CsvReader::open(path, columns)?,
            order: Monotonic::default(),
            parse,
        })
    }
}

impl EventSource for RowSource {
    fn next_event(&mut self) -> Option<Result<SensorEvent>> {
        let row = match self.csv.next_row()? {
            Ok(r) => r,
            Err(e) => return Some(Err(e)),
        };
        let line = row.line();
        let ev = (self.parse)(&row);
        Some(ev.and_then(|ev| {
            self.order
                .check(self.csv.path(), line, ev.t_ns())
                .map(|()| ev)
        }))
    }
}

struct CameraSource {
    csv: CsvReader,
    images: PathBuf,
    order: Monotonic,
    missing: MissingImages,
    skipped: Arc<AtomicUsize>,
}

impl CameraSource {
    fn open(dir: &Path, missing: MissingImages, skipped: Arc<AtomicUsize>) -> Result<Self> {
        Ok(CameraSource {
            csv: CsvReader::open(&dir.join(DATA_CSV), CAM_COLUMNS)?,
            images: dir.join(IMAGE_DIR),
            order: Monotonic::default(),
            missing,
            skipped,
        })
    }

    /// The next row's frame; `Ok(None)` when its image is missing and skipped.
    fn next_frame(&mut self) -> Option<Result<Option<CameraFrame>>> {
        let row = match self.csv.next_row()? {
            Ok(r) => r,
            Err(e) => return Some(Err(e)),
        };
        let line = row.line();
        let t_ns = match row.i64(0) {
            Ok(t) => t,
            Err(e) => return Some(Err(e)),
        };
        let image = self.images.join(row.str(1));
        if let Err(e) = self.order.check(self.csv.path(), line, t_ns) {
            return Some(Err(e));
        }
        let image_error = |reason: String| DatasetError::Image {
            path: image.clone(),
            csv: self.csv.path().to_owned(),
            line,
            reason,
        };
        if !image.is_file() && self.missing == MissingImages::Skip {
            self.skipped.fetch_add(1, Ordering::Relaxed);
            return Some(Ok(None));
        }
        let data = match std::fs::read(&image) {
            Ok(d) => d,
            Err(e) => return Some(Err(image_error(e.to_string()))),
        };
        let Some(format) = ImageFormat::sniff(&data) else {
            return Some(Err(image_error("not a JPEG or PNG file".into())));
        };
        Some(Ok(Some(CameraFrame {
            t_ns,
            camera_id: 0,
            format,
            data: Arc::from(data),
        })))
    }
}

impl EventSource for CameraSource {
    fn next_event(&mut self) -> Option<Result<SensorEvent>> {
        loop {
            match self.next_frame()? {
                Ok(Some(f)) => return Some(Ok(SensorEvent::Camera(f))),
                Ok(None) => continue,
                Err(e) => return Some(Err(e)),
            }
        }
    }
}
