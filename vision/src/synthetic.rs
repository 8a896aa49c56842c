//! Small deterministic synthetic images for unit tests and benchmarks: a band-limited
//! procedural texture, its affine warps, and views of a textured ground plane from an arbitrary
//! camera pose (a stand-in until the simulator's renderer is used).

use nalgebra::{Isometry3, Point2, Vector3};
use uavnav_core::CameraModel;

/// A seeded multi-octave value-noise texture on the plane, intensity 0..255.
#[derive(Debug, Clone)]
pub struct Texture {
    seed: u64,
}

fn hash2(seed: u64, x: i64, y: i64) -> f64 {
    let mut h = seed
        ^ (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    h ^= h >> 33;
    h = h.wrapping_mul(0xFF51_AFD7_ED55_8CCD);
    h ^= h >> 33;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

fn smooth(t: f64) -> f64 {
    t * t * (3.0 - 2.0 * t)
}

fn value_noise(seed: u64, x: f64, y: f64) -> f64 {
    let (xf, yf) = (x.floor(), y.floor());
    let (xi, yi) = (xf as i64, yf as i64);
    let (tx, ty) = (smooth(x - xf), smooth(y - yf));
    let a = hash2(seed, xi, yi);
    let b = hash2(seed, xi + 1, yi);
    let c = hash2(seed, xi, yi + 1);
    let d = hash2(seed, xi + 1, yi + 1);
    let top = a + (b - a) * tx;
    let bot = c + (d - c) * tx;
    top + (bot - top) * ty
}

impl Texture {
    /// A texture with the given seed.
    pub fn new(seed: u64) -> Self {
        Self { seed }
    }

    /// Intensity at texture coordinates (units: the finest noise cell is ~3 units).
    pub fn sample(&self, u: f64, v: f64) -> f64 {
        let mut acc = 0.0;
        let mut amp = 1.0;
        let mut norm = 0.0;
        let mut f = 1.0 / 48.0;
        for o in 0..5u64 {
            acc += amp * value_noise(self.seed.wrapping_add(o * 7919), u * f, v * f);
            norm += amp;
            amp *= 0.75;
            f *= 2.0;
        }
        let x = acc / norm;
        // stretch contrast: value noise concentrates around 0.5
        (128.0 + (x - 0.5) * 3.0 * 255.0).clamp(0.0, 255.0)
    }
}

/// Renders `w × h` pixels where the pixel `p` shows the texture at `M⁻¹ (p − off)`, i.e. a
/// texture point at `q` appears at `M q + off`.
pub fn render_affine(
    tex: &Texture,
    w: usize,
    h: usize,
    m: [[f64; 2]; 2],
    off: [f64; 2],
) -> Vec<u8> {
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    let inv = [
        [m[1][1] / det, -m[0][1] / det],
        [-m[1][0] / det, m[0][0] / det],
    ];
    let mut out = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let (dx, dy) = (x as f64 - off[0], y as f64 - off[1]);
            let u = inv[0][0] * dx + inv[0][1] * dy;
            let v = inv[1][0] * dx + inv[1][1] * dy;
            out[y * w + x] = tex.sample(u, v).round() as u8;
        }
    }
    out
}

/// Renders a textured ground plane `z_world = 0` (world "down" is +z, so the camera sits at
/// negative z) seen by `camera` at pose `world_from_cam`. `texels_per_m` scales the texture.
/// Pixels whose ray misses the plane are mid-grey.
pub fn render_ground(
    tex: &Texture,
    camera: &CameraModel,
    world_from_cam: &Isometry3<f64>,
    texels_per_m: f64,
) -> Vec<u8> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let mut out = vec![128u8; w * h];
    let c = world_from_cam.translation.vector;
    for y in 0..h {
        for x in 0..w {
            let ray = camera.ray(&Point2::new(x as f64, y as f64));
            let d: Vector3<f64> = world_from_cam.rotation * ray;
            if d.z <= 1e-9 {
                continue;
            }
            let s = -c.z / d.z;
            if s <= 0.0 {
                continue;
            }
            let p = c + d * s;
            out[y * w + x] = tex.sample(p.x * texels_per_m, p.y * texels_per_m).round() as u8;
        }
    }
    out
}
