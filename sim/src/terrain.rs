//! The ground texture: procedural, seeded, with detail at every scale and filtered by construction.
//!
//! Texture coordinates are metres north/east on the tangent plane of the terrain's anchor point
//! (fixed to the ground, independent of the vehicle). The radiance is the sum of
//!
//! - 13 octaves of rotated value noise, cells from 512 m down to 0.125 m, each faded out as its
//!   cell size approaches the pixel footprint (so no octave finer than ~1.5 px is ever sampled:
//!   anti-aliasing by construction), amplitudes falling slowly (∝ cell^0.2) so that corners are
//!   trackable from 50 m to 500 m above the ground;
//! - a layer of fields: a domain-warped grid of ~120 m parcels with random albedo, box-filtered
//!   over the pixel footprint at their edges, some edges lined with dark hedges (T-junctions and
//!   corners for the feature tracker).

use nalgebra::{Matrix3, Vector3};
use uavnav_core::geodesy::{WGS84_A, WGS84_B, lla_to_ecef, ned_from_ecef};
use uavnav_core::rng::Rng;
use uavnav_core::{Lla, LocalFrame};

/// Number of value-noise octaves.
const OCTAVES: usize = 13;
/// Cell size of the coarsest octave, m.
const COARSEST_CELL_M: f64 = 512.0;
/// Amplitude exponent: octave amplitude ∝ cell^this.
const AMPLITUDE_EXPONENT: f64 = 0.2;
/// Parcel (field) size, m.
const PARCEL_M: f64 = 120.0;
/// Hedge width, m.
const HEDGE_M: f64 = 2.5;
/// Domain-warp amplitude of the parcel grid, m.
const WARP_M: f64 = 18.0;

/// One noise octave: rotation, offset and hash key.
#[derive(Debug, Clone, Copy)]
struct Octave {
    inv_cell: f64,
    cell_m: f64,
    cos: f64,
    sin: f64,
    off_x: f64,
    off_y: f64,
    key: u32,
    amp: f32,
}

/// A flat textured terrain at a fixed height above the WGS84 ellipsoid.
#[derive(Debug, Clone)]
pub struct Terrain {
    elevation_m: f64,
    /// Texture anchor: ECEF origin and the rotation into its tangent NED frame.
    anchor_ecef: Vector3<f64>,
    tex_from_ecef: Matrix3<f64>,
    octaves: [Octave; OCTAVES],
    noise_gain: f32,
    parcel_cos: f64,
    parcel_sin: f64,
    parcel_key: u32,
}

/// Multipliers spreading lattice x and y over 32 bits before mixing.
const PRIME_X: u32 = 0x8DA6_B343;
/// See [`PRIME_X`].
const PRIME_Y: u32 = 0xD816_3841;

/// Final avalanche of a 32-bit hash (two multiply–xorshift rounds).
#[inline]
fn fmix(mut h: u32) -> u32 {
    h ^= h >> 16;
    h = h.wrapping_mul(0x7FEB_352D);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846C_A68B);
    h ^ (h >> 16)
}

/// 32-bit integer hash of a lattice point.
#[inline]
fn hash2(ix: i64, iy: i64, key: u32) -> u32 {
    fmix((ix as u32).wrapping_mul(PRIME_X) ^ (iy as u32).wrapping_mul(PRIME_Y) ^ key)
}

/// Hash → [0, 1) from the high 16 bits.
#[inline]
fn unit(h: u32) -> f32 {
    (h >> 16) as f32 * (1.0 / 65_536.0)
}

/// Hash → [0, 1) from the low 16 bits (a second, independent value from the same hash).
#[inline]
fn unit_lo(h: u32) -> f32 {
    (h & 0xFFFF) as f32 * (1.0 / 65_536.0)
}

/// ⌊x⌋ without a libm call (baseline x86-64 has no rounding instruction); |x| < 2⁶³.
#[inline]
fn floor_i64(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) > x { i - 1 } else { i }
}

/// The four corner hashes and the smoothed fractions of the lattice cell holding (x, y).
#[inline]
fn cell(x: f64, y: f64, key: u32) -> ([u32; 4], f32, f32) {
    let (ix, iy) = (floor_i64(x), floor_i64(y));
    let (fx, fy) = ((x - ix as f64) as f32, (y - iy as f64) as f32);
    let hx0 = (ix as u32).wrapping_mul(PRIME_X);
    let hx1 = hx0.wrapping_add(PRIME_X);
    let hy0 = (iy as u32).wrapping_mul(PRIME_Y) ^ key;
    let hy1 = (iy as u32).wrapping_add(1).wrapping_mul(PRIME_Y) ^ key;
    let h = [
        fmix(hx0 ^ hy0),
        fmix(hx1 ^ hy0),
        fmix(hx0 ^ hy1),
        fmix(hx1 ^ hy1),
    ];
    (h, fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy))
}

#[inline]
fn bilerp(v: [f32; 4], sx: f32, sy: f32) -> f32 {
    let top = v[0] + (v[1] - v[0]) * sx;
    let bot = v[2] + (v[3] - v[2]) * sx;
    top + (bot - top) * sy
}

/// Smoothly interpolated lattice noise in [0, 1) at (x, y) in cell units.
#[inline]
fn value_noise(x: f64, y: f64, key: u32) -> f32 {
    let (h, sx, sy) = cell(x, y, key);
    bilerp(h.map(unit), sx, sy)
}

/// Two independent lattice noises in [0, 1) at (x, y), for the price of one.
#[inline]
fn value_noise2(x: f64, y: f64, key: u32) -> (f32, f32) {
    let (h, sx, sy) = cell(x, y, key);
    (bilerp(h.map(unit), sx, sy), bilerp(h.map(unit_lo), sx, sy))
}

/// Fraction of a box of width `fp` centred at distance `d` from a band's centre line covered by
/// the band of width `w` (exact box filter of a line).
#[inline]
fn band_coverage(d: f64, w: f64, fp: f64) -> f64 {
    let lo = (d - 0.5 * fp).max(-0.5 * w);
    let hi = (d + 0.5 * fp).min(0.5 * w);
    ((hi - lo) / fp).clamp(0.0, 1.0)
}

impl Terrain {
    /// A terrain `elevation_m` above the ellipsoid, textured from `seed`, its texture anchored at
    /// `anchor` (any nearby point; the scenario origin).
    pub fn new(anchor: Lla, elevation_m: f64, seed: u64) -> Self {
        let mut rng = Rng::derive(seed, "terrain");
        let mut octaves = [Octave {
            inv_cell: 1.0,
            cell_m: 1.0,
            cos: 1.0,
            sin: 0.0,
            off_x: 0.0,
            off_y: 0.0,
            key: 0,
            amp: 0.0,
        }; OCTAVES];
        let mut sum_sq = 0.0f64;
        for (i, o) in octaves.iter_mut().enumerate() {
            let cell_m = COARSEST_CELL_M / f64::from(1u32 << i);
            let angle = rng.uniform_range(0.0, std::f64::consts::TAU);
            let amp = (cell_m / COARSEST_CELL_M).powf(AMPLITUDE_EXPONENT);
            sum_sq += amp * amp;
            *o = Octave {
                inv_cell: 1.0 / cell_m,
                cell_m,
                cos: angle.cos(),
                sin: angle.sin(),
                off_x: rng.uniform_range(0.0, 1000.0),
                off_y: rng.uniform_range(0.0, 1000.0),
                key: (rng.next_u64() >> 32) as u32,
                amp: amp as f32,
            };
        }
        let parcel_angle = rng.uniform_range(0.0, std::f64::consts::TAU);
        let anchor_ground = Lla {
            alt_m: elevation_m,
            ..anchor
        };
        Self {
            elevation_m,
            anchor_ecef: lla_to_ecef(&anchor_ground),
            tex_from_ecef: ned_from_ecef(anchor.lat_rad, anchor.lon_rad),
            octaves,
            // Value noise has σ ≈ 0.2; this makes the summed octaves' σ ≈ 0.13.
            noise_gain: (0.65 / sum_sq.sqrt()) as f32,
            parcel_cos: parcel_angle.cos(),
            parcel_sin: parcel_angle.sin(),
            parcel_key: (rng.next_u64() >> 32) as u32,
        }
    }

    /// Height of the terrain above the WGS84 ellipsoid, m.
    pub fn elevation_m(&self) -> f64 {
        self.elevation_m
    }

    /// Semi-axes (equatorial, polar) of the ellipsoid the terrain lies on, m.
    pub fn semi_axes_m(&self) -> (f64, f64) {
        (WGS84_A + self.elevation_m, WGS84_B + self.elevation_m)
    }

    /// ECEF origin of the texture plane and the rotation ECEF → texture NED.
    pub(crate) fn texture_frame(&self) -> (Vector3<f64>, Matrix3<f64>) {
        (self.anchor_ecef, self.tex_from_ecef)
    }

    /// Texture coordinates (north, east, m) of a point given in a local frame, for tests and tools.
    pub fn texture_coords(&self, frame: &LocalFrame, ned_m: &Vector3<f64>) -> (f64, f64) {
        let ecef = lla_to_ecef(&frame.ned_to_lla(ned_m));
        let t = self.tex_from_ecef * (ecef - self.anchor_ecef);
        (t.x, t.y)
    }

    /// Ground reflectance in [0, 1] at texture point (north, east), box-filtered over a pixel
    /// footprint of `footprint_m` metres.
    pub fn radiance(&self, north_m: f64, east_m: f64, footprint_m: f64) -> f32 {
        let fp = footprint_m.max(1e-3);
        let mut sum = 0.0f32;
        for o in &self.octaves {
            // Full weight for cells ≥ 3 px, none below 1.5 px.
            let w = ((o.cell_m / fp - 1.5) / 1.5).clamp(0.0, 1.0) as f32;
            if w == 0.0 {
                break;
            }
            let u = (o.cos * north_m - o.sin * east_m) * o.inv_cell + o.off_x;
            let v = (o.sin * north_m + o.cos * east_m) * o.inv_cell + o.off_y;
            sum += w * o.amp * (value_noise(u, v, o.key) - 0.5);
        }
        let l = 0.5 + self.noise_gain * sum + self.parcels(north_m, east_m, fp);
        l.clamp(0.02, 0.98)
    }

    /// The field layer: albedo offset of the parcel grid, edges box-filtered, hedges darkened.
    fn parcels(&self, north_m: f64, east_m: f64, fp: f64) -> f32 {
        let mut u = self.parcel_cos * north_m - self.parcel_sin * east_m;
        let mut v = self.parcel_sin * north_m + self.parcel_cos * east_m;
        // Domain warp: the grid bends gently, so no two parcels are alike.
        let (warp_u, warp_v) = value_noise2(u / 700.0, v / 700.0, self.parcel_key ^ 0xA5A5);
        u += WARP_M * 2.0 * f64::from(warp_u - 0.5);
        v += WARP_M * 2.0 * f64::from(warp_v - 0.5);
        let (gu, gv) = ((u / PARCEL_M).floor(), (v / PARCEL_M).floor());
        let (iu, iv) = (gu as i64, gv as i64);
        let (fu, fv) = (u - gu * PARCEL_M, v - gv * PARCEL_M);
        // Nearest edge along each axis and the neighbour across it.
        let (du, su) = if fu < 0.5 * PARCEL_M {
            (fu, -1)
        } else {
            (PARCEL_M - fu, 1)
        };
        let (dv, sv) = if fv < 0.5 * PARCEL_M {
            (fv, -1)
        } else {
            (PARCEL_M - fv, 1)
        };
        let wu = (0.5 + du / fp).min(1.0);
        let wv = (0.5 + dv / fp).min(1.0);
        let albedo = |a: i64, b: i64| f64::from(unit(hash2(a, b, self.parcel_key))) - 0.5;
        let mut field = albedo(iu, iv) * wu * wv;
        if wu < 1.0 {
            field += albedo(iu + su, iv) * (1.0 - wu) * wv;
        }
        if wv < 1.0 {
            field += albedo(iu, iv + sv) * wu * (1.0 - wv);
        }
        if wu < 1.0 && wv < 1.0 {
            field += albedo(iu + su, iv + sv) * (1.0 - wu) * (1.0 - wv);
        }
        // Hedges on about half the edges, keyed by the edge's identity.
        let edge_u = if su < 0 { iu } else { iu + 1 };
        let edge_v = if sv < 0 { iv } else { iv + 1 };
        let has_u = hash2(edge_u, iv, self.parcel_key ^ 0x1234_5678) & 1 == 1;
        let has_v = hash2(iu, edge_v, self.parcel_key ^ 0x8765_4321) & 1 == 1;
        let cu = if has_u {
            band_coverage(du, HEDGE_M, fp)
        } else {
            0.0
        };
        let cv = if has_v {
            band_coverage(dv, HEDGE_M, fp)
        } else {
            0.0
        };
        (0.3 * field - 0.25 * cu.max(cv)) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_matches_std() {
        for x in [-2.5, -2.0, -0.1, 0.0, 0.3, 1.0, 7.9, -1e9 - 0.5] {
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
        }
    }

    #[test]
    fn band_coverage_is_a_box_filter() {
        assert!((band_coverage(0.0, 2.0, 0.1) - 1.0).abs() < 1e-12);
        assert!((band_coverage(0.0, 2.0, 10.0) - 0.2).abs() < 1e-12);
        assert_eq!(band_coverage(5.0, 2.0, 1.0), 0.0);
    }

    #[test]
    fn radiance_in_range_and_varies() {
        let t = Terrain::new(Lla::from_deg(41.0, 14.0, 0.0), 50.0, 1);
        let vals: Vec<f32> = (0..1000)
            .map(|i| t.radiance(i as f64 * 0.7, i as f64 * 0.3, 0.5))
            .collect();
        assert!(vals.iter().all(|v| (0.0..=1.0).contains(v)));
        let mean = vals.iter().sum::<f32>() / vals.len() as f32;
        let sd = (vals.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / vals.len() as f32).sqrt();
        assert!(sd > 0.05, "sd {sd}");
    }
}
