//! Writes an ASL/EuRoC folder event by event (used by `uavnav simulate` and the converters).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use uavnav_core::{
    BaroSample, CameraFrame, GnssFix, ImuSample, Lla, MagSample, SensorEvent, TruthSample,
    VehicleConfig,
};

use super::layout::*;
use super::sensor_yaml;
use crate::error::{DatasetError, Result};

/// An ASL folder being written. Call [`AslWriter::finish`] to flush; dropping without it may lose
/// buffered rows.
#[derive(Debug)]
pub struct AslWriter {
    mav: PathBuf,
    imu: Csv,
    gnss: Option<Csv>,
    mag: Option<Csv>,
    baro: Option<Csv>,
    cam: Option<Csv>,
    truth: Option<Csv>,
    origin: Option<Lla>,
}

/// One `data.csv` being written, with its own time-order check.
#[derive(Debug)]
struct Csv {
    path: PathBuf,
    out: BufWriter<File>,
    rows: usize,
    last_t_ns: Option<i64>,
}

impl Csv {
    fn create(dir: &Path, header: &str) -> Result<Self> {
        std::fs::create_dir_all(dir).map_err(|e| DatasetError::io(dir, e))?;
        let path = dir.join(DATA_CSV);
        let file = File::create(&path).map_err(|e| DatasetError::io(&path, e))?;
        let mut csv = Csv {
            path,
            out: BufWriter::new(file),
            rows: 0,
            last_t_ns: None,
        };
        csv.line(header)?;
        Ok(csv)
    }

    fn line(&mut self, text: &str) -> Result<()> {
        writeln!(self.out, "{text}").map_err(|e| DatasetError::io(&self.path, e))
    }

    /// Writes a row; `t_ns` must be after the previous row's.
    fn row(&mut self, t_ns: i64, cells: &[f64]) -> Result<()> {
        self.opt_row(t_ns, cells.iter().map(|&v| Some(v)))
    }

    /// Writes a row whose `None` cells are left empty; `t_ns` must be after the previous row's.
    fn opt_row(&mut self, t_ns: i64, cells: impl IntoIterator<Item = Option<f64>>) -> Result<()> {
        self.check_time(t_ns)?;
        let mut s = t_ns.to_string();
        for v in cells {
            s.push(',');
            if let Some(v) = v {
                s.push_str(&fmt_f64(v));
            }
        }
        self.line(&s)
    }

    fn check_time(&mut self, t_ns: i64) -> Result<()> {
        if let Some(prev) = self.last_t_ns.filter(|&p| t_ns <= p) {
            // +2: the header is line 1 and the new row would be the next line.
            return Err(DatasetError::TimeBackwards {
                path: self.path.clone(),
                line: self.rows + 2,
                t_ns,
                prev_t_ns: prev,
            });
        }
        self.last_t_ns = Some(t_ns);
        self.rows += 1;
        Ok(())
    }

    fn finish(mut self) -> Result<()> {
        self.out
            .flush()
            .map_err(|e| DatasetError::io(&self.path, e))
    }
}

fn write_file(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).map_err(|e| DatasetError::io(path, e))
}

impl AslWriter {
    /// Creates `<dir>/mav0/...` with the `sensor.yaml` files of `config`, and `body.yaml` with the
    /// vehicle id, terrain and profile. Sensor folders exist only for fitted sensors. `origin` is the
    /// truth's NED origin (written with the truth).
    pub fn create(
        dir: &Path,
        vehicle_id: &str,
        config: &VehicleConfig,
        origin: Option<Lla>,
    ) -> Result<Self> {
        let mav = dir.join(MAV);
        std::fs::create_dir_all(&mav).map_err(|e| DatasetError::io(&mav, e))?;
        write_file(
            &mav.join(BODY_YAML),
            &sensor_yaml::write_body(
                vehicle_id,
                config.terrain_elevation_m,
                config.profile,
                config.airframe,
            ),
        )?;
        let imu = Csv::create(&mav.join(IMU), IMU_HEADER)?;
        write_file(
            &mav.join(IMU).join(SENSOR_YAML),
            &sensor_yaml::write_imu(&config.imu),
        )?;
        let gnss = match &config.gnss {
            Some(g) => {
                let csv = Csv::create(&mav.join(GNSS), GNSS_HEADER)?;
                write_file(
                    &mav.join(GNSS).join(SENSOR_YAML),
                    &sensor_yaml::write_gnss(g),
                )?;
                Some(csv)
            }
            None => None,
        };
        let mag = match &config.mag {
            Some(m) => {
                let csv = Csv::create(&mav.join(MAG), MAG_HEADER)?;
                write_file(&mav.join(MAG).join(SENSOR_YAML), &sensor_yaml::write_mag(m))?;
                Some(csv)
            }
            None => None,
        };
        let baro = match &config.baro {
            Some(b) => {
                let csv = Csv::create(&mav.join(BARO), BARO_HEADER)?;
                write_file(
                    &mav.join(BARO).join(SENSOR_YAML),
                    &sensor_yaml::write_baro(b),
                )?;
                Some(csv)
            }
            None => None,
        };
        let cam = match &config.camera {
            Some(c) => {
                let csv = Csv::create(&mav.join(CAM), CAM_HEADER)?;
                let images = mav.join(CAM).join(IMAGE_DIR);
                std::fs::create_dir_all(&images).map_err(|e| DatasetError::io(&images, e))?;
                write_file(
                    &mav.join(CAM).join(SENSOR_YAML),
                    &sensor_yaml::write_camera(c),
                )?;
                Some(csv)
            }
            None => None,
        };
        if origin.is_some() {
            // Written now so an origin without truth samples survives a round trip.
            let dir = mav.join(TRUTH);
            std::fs::create_dir_all(&dir).map_err(|e| DatasetError::io(&dir, e))?;
            write_file(
                &dir.join(SENSOR_YAML),
                &sensor_yaml::write_truth(origin.as_ref()),
            )?;
        }
        Ok(AslWriter {
            mav,
            imu,
            gnss,
            mag,
            baro,
            cam,
            truth: None,
            origin,
        })
    }

    /// The `mav0` folder being written.
    pub fn mav_dir(&self) -> &Path {
        &self.mav
    }

    /// Appends one event to its sensor's `data.csv` (and writes the image file for a frame).
    /// Each sensor's times must strictly increase.
    pub fn write_event(&mut self, event: &SensorEvent) -> Result<()> {
        match event {
            SensorEvent::Imu(s) => self.write_imu(s),
            SensorEvent::Gnss(f) => self.write_gnss(f),
            SensorEvent::Mag(m) => self.write_mag(m),
            SensorEvent::Baro(b) => self.write_baro(b),
            SensorEvent::Camera(c) => self.write_frame(c),
        }
    }

    /// Appends an IMU sample.
    pub fn write_imu(&mut self, s: &ImuSample) -> Result<()> {
        let (w, a) = (s.gyro_radps, s.accel_mps2);
        self.imu.row(s.t_ns, &[w.x, w.y, w.z, a.x, a.y, a.z])
    }

    /// Appends a GNSS fix (fix type and satellite count are not part of the ASL format).
    pub fn write_gnss(&mut self, f: &GnssFix) -> Result<()> {
        let csv = self
            .gnss
            .as_mut()
            .ok_or_else(|| DatasetError::Unsupported {
                path: self.mav.join(GNSS),
                message: "GNSS fix for a vehicle configured without GNSS".into(),
            })?;
        let v = f.velocity;
        csv.opt_row(
            f.t_ns,
            [
                Some(f.lat_deg),
                Some(f.lon_deg),
                Some(f.alt_m),
                v.map(|v| v.north_mps),
                v.map(|v| v.east_mps),
                v.and_then(|v| v.down_mps),
                Some(f.sigma_h_m),
                Some(f.sigma_v_m),
                v.map(|v| v.sigma_mps),
            ],
        )
    }

    /// Appends a magnetometer sample.
    pub fn write_mag(&mut self, m: &MagSample) -> Result<()> {
        let csv = self.mag.as_mut().ok_or_else(|| DatasetError::Unsupported {
            path: self.mav.join(MAG),
            message: "magnetometer sample for a vehicle configured without one".into(),
        })?;
        let b = m.field_t;
        csv.row(m.t_ns, &[b.x, b.y, b.z])
    }

    /// Appends a barometer sample (an unknown temperature is an empty cell).
    pub fn write_baro(&mut self, b: &BaroSample) -> Result<()> {
        let csv = self
            .baro
            .as_mut()
            .ok_or_else(|| DatasetError::Unsupported {
                path: self.mav.join(BARO),
                message: "barometer sample for a vehicle configured without one".into(),
            })?;
        csv.opt_row(b.t_ns, [Some(b.pressure_pa), b.temperature_degc])
    }

    /// Writes a frame's image as `cam0/data/<t_ns>.jpg|.png` and appends its row.
    pub fn write_frame(&mut self, c: &CameraFrame) -> Result<()> {
        let dir = self.mav.join(CAM);
        let csv = self.cam.as_mut().ok_or_else(|| DatasetError::Unsupported {
            path: dir.clone(),
            message: "camera frame for a vehicle configured without a camera".into(),
        })?;
        if c.camera_id != 0 {
            return Err(DatasetError::Unsupported {
                path: dir,
                message: format!(
                    "camera {} (the ASL writer holds camera 0 only)",
                    c.camera_id
                ),
            });
        }
        csv.check_time(c.t_ns)?;
        let ext = match c.format {
            uavnav_core::ImageFormat::Jpeg => "jpg",
            uavnav_core::ImageFormat::Png => "png",
        };
        let name = format!("{}.{ext}", c.t_ns);
        let image = dir.join(IMAGE_DIR).join(&name);
        std::fs::write(&image, &c.data[..]).map_err(|e| DatasetError::io(&image, e))?;
        csv.line(&format!("{},{name}", c.t_ns))
    }

    /// Appends a truth sample (creates the truth folder on first use).
    pub fn write_truth(&mut self, s: &TruthSample) -> Result<()> {
        if self.truth.is_none() {
            self.start_truth(&sensor_yaml::write_truth(self.origin.as_ref()))?;
        }
        self.truth_row(s)
    }

    /// Appends a reference sample (another estimator's output, e.g. an autopilot's EKF) to
    /// `state_groundtruth_estimate0`, whose `sensor.yaml` then says it is not ground truth (the
    /// layout of the shared real-flight conversions). A folder holds truth or a reference, not
    /// both: do not mix with [`Self::write_truth`].
    pub fn write_reference(&mut self, s: &TruthSample, source: Option<&str>) -> Result<()> {
        if self.truth.is_none() {
            self.start_truth(&sensor_yaml::write_reference(self.origin.as_ref(), source))?;
        }
        self.truth_row(s)
    }

    fn start_truth(&mut self, yaml: &str) -> Result<()> {
        let dir = self.mav.join(TRUTH);
        let csv = Csv::create(&dir, TRUTH_HEADER)?;
        write_file(&dir.join(SENSOR_YAML), yaml)?;
        self.truth = Some(csv);
        Ok(())
    }

    fn truth_row(&mut self, s: &TruthSample) -> Result<()> {
        let Some(csv) = self.truth.as_mut() else {
            return Ok(());
        };
        let (p, q, v, bw, ba) = (
            s.pos_ned_m,
            s.nav_from_body,
            s.vel_ned_mps,
            s.gyro_bias_radps,
            s.accel_bias_mps2,
        );
        csv.row(
            s.t_ns,
            &[
                p.x, p.y, p.z, q.w, q.i, q.j, q.k, v.x, v.y, v.z, bw.x, bw.y, bw.z, ba.x, ba.y,
                ba.z,
            ],
        )
    }

    /// Flushes every file.
    pub fn finish(self) -> Result<()> {
        self.imu.finish()?;
        for csv in [self.gnss, self.mag, self.baro, self.cam, self.truth]
            .into_iter()
            .flatten()
        {
            csv.finish()?;
        }
        Ok(())
    }
}
