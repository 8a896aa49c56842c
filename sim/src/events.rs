//! Camera frames of a [`Flight`] and its merged, time-ordered sensor stream.

use std::collections::VecDeque;
use std::sync::Arc;

use image::GrayImage;
use nalgebra::Vector3;
use rayon::prelude::*;
use uavnav_core::{CameraFrame, ImageFormat, SensorEvent};

use crate::flight::{Flight, SimError};
use crate::render::{PixelNoise, RayTable, encode_jpeg, render_gray};

/// Frames rendered per batch of the event stream, per worker thread.
const FRAMES_PER_THREAD: usize = 4;

impl Flight {
    fn ray_table(&self) -> &RayTable {
        self.rays
            .get_or_init(|| Arc::new(RayTable::new(&self.camera_model())))
    }

    /// The noise-free-or-noisy gray image of camera frame `index` (before JPEG).
    pub fn render_gray_frame(&self, index: usize, with_noise: bool) -> Result<GrayImage, SimError> {
        let len = self.camera_truth_index.len();
        let truth = self
            .camera_truth(index)
            .ok_or(SimError::FrameIndex { index, len })?;
        let mount = self.body_from_cam();
        let pos = truth.pos_ned_m
            + truth
                .nav_from_body
                .transform_vector(&mount.translation.vector);
        let nav_from_cam = truth.nav_from_body * mount.rotation;
        let noise = PixelNoise {
            sigma_gray: self.scenario.camera.noise_sigma,
            seed: self.image_seed ^ (index as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15),
        };
        let noise = with_noise.then_some(&noise);
        Ok(render_gray(
            &self.terrain,
            self.ray_table(),
            &self.frame,
            &pos,
            &nav_from_cam,
            noise,
        ))
    }

    /// Camera frame `index`, rendered and JPEG-encoded at the scenario quality.
    pub fn render_frame(&self, index: usize) -> Result<CameraFrame, SimError> {
        let img = self.render_gray_frame(index, true)?;
        let data = encode_jpeg(&img, self.scenario.camera.jpeg_quality)
            .map_err(|e| SimError::Encode(e.to_string()))?;
        Ok(CameraFrame {
            t_ns: self.camera_times_ns[index],
            camera_id: 0,
            format: ImageFormat::Jpeg,
            data: data.into(),
        })
    }

    /// Every sensor event in time order, ties broken by [`SensorEvent::rank`] (IMU, GNSS,
    /// magnetometer, barometer, camera). Frames are rendered in parallel batches of a few per core,
    /// so memory stays bounded.
    pub fn events(&self) -> impl Iterator<Item = Result<SensorEvent, SimError>> + '_ {
        Events {
            flight: self,
            imu: 0,
            gnss: 0,
            mag: 0,
            baro: 0,
            cam: 0,
            frames: VecDeque::new(),
        }
    }

    /// Camera position in the local frame at frame `index` (body position + mounted offset), m.
    pub fn camera_position_ned(&self, index: usize) -> Option<Vector3<f64>> {
        let t = self.camera_truth(index)?;
        Some(
            t.pos_ned_m
                + t.nav_from_body
                    .transform_vector(&self.body_from_cam().translation.vector),
        )
    }
}

/// The merged stream of [`Flight::events`].
struct Events<'a> {
    flight: &'a Flight,
    imu: usize,
    gnss: usize,
    mag: usize,
    baro: usize,
    cam: usize,
    /// Rendered frames `cam, cam + 1, …` not yet handed out.
    frames: VecDeque<Result<SensorEvent, SimError>>,
}

impl Events<'_> {
    fn next_camera(&mut self) -> Option<Result<SensorEvent, SimError>> {
        if self.frames.is_empty() {
            let n = self.flight.camera_times_ns.len();
            let batch = FRAMES_PER_THREAD * rayon::current_num_threads().max(1);
            let end = (self.cam + batch).min(n);
            let rendered: Vec<_> = (self.cam..end)
                .into_par_iter()
                .map(|i| self.flight.render_frame(i).map(SensorEvent::Camera))
                .collect();
            self.frames.extend(rendered);
        }
        self.cam += 1;
        self.frames.pop_front()
    }
}

impl Iterator for Events<'_> {
    type Item = Result<SensorEvent, SimError>;

    fn next(&mut self) -> Option<Self::Item> {
        let f = self.flight;
        let t_imu = f.imu().get(self.imu).map(|s| s.t_ns);
        let t_gnss = f.gnss().get(self.gnss).map(|g| g.t_ns);
        let t_mag = f.mag().get(self.mag).map(|m| m.t_ns);
        let t_baro = f.baro().get(self.baro).map(|b| b.t_ns);
        let t_cam = f.camera_times_ns.get(self.cam).copied();
        let earliest = [t_imu, t_gnss, t_mag, t_baro, t_cam]
            .into_iter()
            .flatten()
            .min()?;
        // Checked in `SensorEvent::rank` order, so equal times leave in that order.
        if t_imu == Some(earliest) {
            self.imu += 1;
            return Some(Ok(SensorEvent::Imu(f.imu()[self.imu - 1])));
        }
        if t_gnss == Some(earliest) {
            self.gnss += 1;
            return Some(Ok(SensorEvent::Gnss(f.gnss()[self.gnss - 1])));
        }
        if t_mag == Some(earliest) {
            self.mag += 1;
            return Some(Ok(SensorEvent::Mag(f.mag()[self.mag - 1])));
        }
        if t_baro == Some(earliest) {
            self.baro += 1;
            return Some(Ok(SensorEvent::Baro(f.baro()[self.baro - 1])));
        }
        self.next_camera()
    }
}
