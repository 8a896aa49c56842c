//! Camera rendering by ray casting the terrain ellipsoid, then JPEG encoding.
//!
//! Each pixel's ray is the undistorted normalized ray through the (distorted) pixel centre
//! ([`CameraModel::pixel_to_normalized`], precomputed once per camera in a [`RayTable`]). It is
//! intersected in ECEF with the ellipsoid of semi-axes (a + h, b + h), h = terrain elevation
//! (within millimetres of the true constant-height surface at these ranges). The hit point's
//! texture coordinates and the pixel footprint (range, incidence, focal length) feed
//! [`Terrain::radiance`]. A light distance haze blends towards the sky value; rays that miss the
//! ground return the sky value. Optional white pixel noise comes from per-row seeded streams, so
//! the output is identical whatever the thread count (approximately Gaussian: Irwin–Hall of four
//! uniforms, see `approx_gaussian`).

use image::GrayImage;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use rayon::prelude::*;
use uavnav_core::geodesy::{lla_to_ecef, ned_from_ecef};
use uavnav_core::rng::Rng;
use uavnav_core::{CameraModel, LocalFrame};

use crate::terrain::Terrain;

/// Gray level of the sky (and of rays that miss the ground).
pub const SKY_GRAY: f32 = 235.0;
/// Haze e-folding distance, m.
const HAZE_M: f64 = 20_000.0;
/// Smallest cosine of incidence used for the footprint (grazing rays get very blurry, not aliased).
const MIN_COS_INCIDENCE: f64 = 0.02;

/// The normalized undistorted ray (x/z, y/z) of every pixel of one camera.
#[derive(Debug, Clone)]
pub struct RayTable {
    camera: CameraModel,
    rays: Vec<[f64; 2]>,
}

impl RayTable {
    /// Undistorts every pixel centre of `camera` (in parallel).
    pub fn new(camera: &CameraModel) -> Self {
        let w = camera.width as usize;
        let rays = (0..camera.height as usize)
            .into_par_iter()
            .flat_map_iter(|row| {
                (0..w).map(move |col| {
                    let n =
                        camera.pixel_to_normalized(&nalgebra::Point2::new(col as f64, row as f64));
                    [n.x, n.y]
                })
            })
            .collect();
        Self {
            camera: *camera,
            rays,
        }
    }

    /// The camera.
    pub fn camera(&self) -> &CameraModel {
        &self.camera
    }
}

/// White Gaussian pixel noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelNoise {
    /// 1-σ, gray levels (0–255 scale).
    pub sigma_gray: f64,
    /// Seed of this image's noise (each row derives its own stream from it).
    pub seed: u64,
}

/// Per-frame constants of the ray cast.
struct Cast {
    /// Scaled (unit-sphere) ECEF camera centre.
    c_s: Vector3<f64>,
    /// c_s·c_s − 1 (negative when the camera is under the terrain).
    c_term: f64,
    /// Camera ray → scaled ECEF direction.
    scaled_from_cam: Matrix3<f64>,
    /// Camera ray → texture-frame direction.
    tex_from_cam: Matrix3<f64>,
    /// Camera centre in the texture frame.
    cam_tex: Vector3<f64>,
    /// Mean focal length, px.
    f_px: f64,
}

/// Renders the terrain as seen by a camera at `pos_ned_m` (in `frame`) with attitude
/// `nav_from_cam` (camera → NED of `frame`), 8-bit gray.
pub fn render_gray(
    terrain: &Terrain,
    rays: &RayTable,
    frame: &LocalFrame,
    pos_ned_m: &Vector3<f64>,
    nav_from_cam: &UnitQuaternion<f64>,
    noise: Option<&PixelNoise>,
) -> GrayImage {
    let cam = rays.camera;
    let cast = setup(terrain, frame, pos_ned_m, nav_from_cam, &cam);
    let w = cam.width as usize;
    let mut buf = vec![0u8; w * cam.height as usize];
    buf.par_chunks_mut(w).enumerate().for_each(|(row, out)| {
        let mut rng = noise.filter(|n| n.sigma_gray > 0.0).map(|n| {
            (
                Rng::new(n.seed ^ (row as u64 + 1).wrapping_mul(0xD1B5_4A32_D192_ED03)),
                n.sigma_gray as f32,
            )
        });
        for (col, px) in out.iter_mut().enumerate() {
            let [x, y] = rays.rays[row * w + col];
            let mut g = shade(terrain, &cast, &Vector3::new(x, y, 1.0));
            if let Some((r, sigma)) = rng.as_mut() {
                g += *sigma * approx_gaussian(r.next_u64());
            }
            *px = g.round().clamp(0.0, 255.0) as u8;
        }
    });
    // The buffer length is exactly width × height by construction.
    GrayImage::from_raw(cam.width, cam.height, buf)
        .unwrap_or_else(|| GrayImage::new(cam.width, cam.height))
}

/// An approximately standard-normal draw from 64 random bits: the sum of four 16-bit uniforms
/// (Irwin–Hall), centred and scaled to unit variance. Four times cheaper than Box–Muller, and
/// pixel noise does not need Gaussian tails.
#[inline]
fn approx_gaussian(bits: u64) -> f32 {
    let s = (bits & 0xFFFF) + ((bits >> 16) & 0xFFFF) + ((bits >> 32) & 0xFFFF) + (bits >> 48);
    // Sum of 4 U(0,1): mean 2, variance 4/12.
    (s as f32 * (1.0 / 65_536.0) - 2.0) * 3f32.sqrt()
}

fn setup(
    terrain: &Terrain,
    frame: &LocalFrame,
    pos_ned_m: &Vector3<f64>,
    nav_from_cam: &UnitQuaternion<f64>,
    cam: &CameraModel,
) -> Cast {
    let o = frame.origin();
    let ecef_from_cam = ned_from_ecef(o.lat_rad, o.lon_rad).transpose()
        * nav_from_cam.to_rotation_matrix().matrix();
    let cam_ecef = lla_to_ecef(&frame.ned_to_lla(pos_ned_m));
    let (a, b) = terrain.semi_axes_m();
    let scale = Matrix3::from_diagonal(&Vector3::new(1.0 / a, 1.0 / a, 1.0 / b));
    let c_s = scale * cam_ecef;
    let (anchor, tex_from_ecef) = terrain.texture_frame();
    Cast {
        c_s,
        c_term: c_s.norm_squared() - 1.0,
        scaled_from_cam: scale * ecef_from_cam,
        tex_from_cam: tex_from_ecef * ecef_from_cam,
        cam_tex: tex_from_ecef * (cam_ecef - anchor),
        f_px: 0.5 * (cam.fx + cam.fy),
    }
}

/// Gray level (0–255, before noise) along one camera ray (x, y, 1).
#[inline]
fn shade(terrain: &Terrain, c: &Cast, ray: &Vector3<f64>) -> f32 {
    if c.c_term <= 0.0 {
        return SKY_GRAY;
    }
    let d = c.scaled_from_cam * ray;
    let qa = d.norm_squared();
    let qb = c.c_s.dot(&d);
    let disc = qb * qb - qa * c.c_term;
    if disc < 0.0 {
        return SKY_GRAY;
    }
    // Nearest root; with the camera outside, both roots share a sign.
    let t = (-qb - disc.sqrt()) / qa;
    if t <= 0.0 {
        return SKY_GRAY;
    }
    let dt = c.tex_from_cam * ray;
    let hit = c.cam_tex + dt * t;
    let ray_len = ray.norm();
    let range_m = t * ray_len;
    let cos_inc = (dt.z.abs() / ray_len).max(MIN_COS_INCIDENCE);
    // Pixel angular size ≈ cos²(off-axis angle)/f; ground footprint = range × that / cos(incidence).
    let footprint_m = t / (c.f_px * ray_len * cos_inc);
    let l = terrain.radiance(hit.x, hit.y, footprint_m);
    let haze = (-(range_m / HAZE_M) as f32).exp();
    255.0 * l * haze + SKY_GRAY * (1.0 - haze)
}

/// Encodes an 8-bit gray image as baseline JPEG at `quality` (1–100).
pub fn encode_jpeg(img: &GrayImage, quality: u8) -> Result<Vec<u8>, image::ImageError> {
    let mut out = Vec::with_capacity(img.as_raw().len() / 4);
    let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality.clamp(1, 100));
    img.write_with_encoder(enc)?;
    Ok(out)
}
