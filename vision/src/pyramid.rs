//! Gray images (the 8-bit frame at full resolution, `f32` coarser levels), the image pyramid
//! (buffers reused across frames) and frame statistics used to reject black, saturated,
//! textureless and blurred frames.

/// A pixel type the trackers sample (8-bit full-resolution luma or `f32` coarse levels).
pub trait Pixel: Copy + Default + std::fmt::Debug + 'static {
    /// Intensity 0..255 as `f32`.
    fn value(self) -> f32;
}

impl Pixel for u8 {
    #[inline(always)]
    fn value(self) -> f32 {
        f32::from(self)
    }
}

impl Pixel for f32 {
    #[inline(always)]
    fn value(self) -> f32 {
        self
    }
}

/// A row-major single-channel image.
#[derive(Debug, Clone, Default)]
pub struct Image<T> {
    /// Width, px.
    pub width: usize,
    /// Height, px.
    pub height: usize,
    /// Pixels, row-major, intensity 0..255.
    pub data: Vec<T>,
}

/// The full-resolution frame as decoded (8-bit luma).
pub type Gray8 = Image<u8>;
/// A coarse pyramid level (box averages keep fractions).
pub type GrayF32 = Image<f32>;

impl<T: Pixel> Image<T> {
    /// Resizes in place (reusing the allocation when it is large enough).
    pub fn resize(&mut self, width: usize, height: usize) {
        self.width = width;
        self.height = height;
        self.data.resize(width * height, T::default());
    }

    /// Pixel at integer coordinates (no bounds check beyond the slice's).
    #[inline]
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x].value()
    }

    /// Samples a `side × side` patch whose top-left sample is at `(x0, y0)` (sub-pixel) by
    /// bilinear interpolation into `out`. The caller guarantees the patch is inside.
    #[inline]
    pub fn sample_patch(&self, x0: f32, y0: f32, side: usize, out: &mut [f32]) {
        self.sample_patch_rect(x0, y0, side, side, out);
    }

    /// [`Self::sample_patch`] for a `cols × rows` patch. The sub-pixel weights are the same for
    /// the whole patch, so each row is a short vectorizable loop.
    #[inline]
    pub fn sample_patch_rect(&self, x0: f32, y0: f32, cols: usize, rows: usize, out: &mut [f32]) {
        // inside the image, so non-negative: truncation is the floor (and no libm call)
        let (xi, yi) = (x0 as usize, y0 as usize);
        let (ax, ay) = (x0 - xi as f32, y0 - yi as f32);
        let (w00, w01, w10, w11) = (
            (1.0 - ax) * (1.0 - ay),
            ax * (1.0 - ay),
            (1.0 - ax) * ay,
            ax * ay,
        );
        let w = self.width;
        for (r, dst) in out.chunks_exact_mut(cols).take(rows).enumerate() {
            let base = (yi + r) * w + xi;
            let r0 = &self.data[base..base + cols + 1];
            let r1 = &self.data[base + w..base + w + cols + 1];
            // zipped shifted slices: no bounds checks, vectorizes
            let (a0, a1, b0, b1) = (&r0[..cols], &r0[1..], &r1[..cols], &r1[1..]);
            for ((((d, a0), a1), b0), b1) in dst.iter_mut().zip(a0).zip(a1).zip(b0).zip(b1) {
                *d = w00 * a0.value() + w01 * a1.value() + w10 * b0.value() + w11 * b1.value();
            }
        }
    }
}

/// An image pyramid: level 0 is the 8-bit frame, each next level halves the size with a 2×2
/// box average (cheap, and what KLT needs from coarse levels is only a good initial guess).
/// The frame statistics are gathered while the first coarse level is built.
#[derive(Debug, Clone, Default)]
pub struct Pyramid {
    /// Level 0: the frame.
    pub base: Gray8,
    /// Levels 1, 2, …: `coarse[k]` is level `k + 1`.
    pub coarse: Vec<GrayF32>,
    /// Statistics of the frame, from the last build.
    pub stats: FrameStats,
    /// Row of 2×2 box sums (scratch).
    box_row: Vec<u16>,
}

impl Pyramid {
    /// Rebuilds from an 8-bit luma plane, reusing buffers.
    pub fn build(&mut self, luma: &[u8], width: usize, height: usize, n_levels: usize) {
        self.base.resize(width, height);
        self.base.data.copy_from_slice(&luma[..width * height]);
        self.rebuild(n_levels);
    }

    /// Rebuilds the coarse levels and the statistics from `base`, which the caller filled (the
    /// decoder writes straight into it).
    pub fn rebuild(&mut self, n_levels: usize) {
        self.coarse
            .resize_with(n_levels.max(1) - 1, GrayF32::default);
        let sums = match self.coarse.first_mut() {
            Some(l1) => downsample_base(&self.base, l1, &mut self.box_row),
            None => box_sums_full(&self.base, &mut self.box_row),
        };
        for l in 1..self.coarse.len() {
            let (lo, hi) = self.coarse.split_at_mut(l);
            downsample(&lo[l - 1], &mut hi[0]);
        }
        self.stats = sums.stats(mean_abs_diff(&self.base, 4));
    }

    /// Number of levels.
    pub fn depth(&self) -> usize {
        1 + self.coarse.len()
    }
}

/// Sums over the 2×2 box sums `q` of the frame (exact integers: associative, so the loops
/// vectorize, and the same on every machine).
#[derive(Debug, Clone, Copy, Default)]
struct BoxSums {
    n: u64,
    sum: u64,
    sum_sq: u64,
    /// Boxes averaging ≥ 250 (`q ≥ 1000`).
    saturated: u64,
}

impl BoxSums {
    fn add_row(&mut self, row: &[u16]) {
        // i32 lanes vectorize; q ≤ 1020, so Σ q² over 2048 boxes stays below 2³¹
        for part in row.chunks(2048) {
            let (mut s, mut s2, mut sat) = (0i32, 0i32, 0i32);
            for &q in part {
                let q = i32::from(q);
                s += q;
                s2 += q * q;
                sat += i32::from(q >= 1000);
            }
            self.n += part.len() as u64;
            self.sum += s as u64;
            self.sum_sq += s2 as u64;
            self.saturated += sat as u64;
        }
    }

    /// Statistics of the box averages `q / 4` (what the first coarse level holds).
    fn stats(&self, mean_abs_diff: f32) -> FrameStats {
        let n = self.n.max(1) as f64;
        let mean = self.sum as f64 / (4.0 * n);
        let std = (self.sum_sq as f64 / (16.0 * n) - mean * mean)
            .max(0.0)
            .sqrt();
        FrameStats {
            mean: mean as f32,
            std: std as f32,
            saturated_fraction: (self.saturated as f64 / n) as f32,
            sharpness: if std > 1e-3 {
                mean_abs_diff / std as f32
            } else {
                0.0
            },
        }
    }
}

/// Level 1 from the 8-bit frame, and the statistics of its pixels.
fn downsample_base(src: &Gray8, dst: &mut GrayF32, q: &mut Vec<u16>) -> BoxSums {
    let (w, h) = (src.width / 2, src.height / 2);
    dst.resize(w, h);
    let mut sums = BoxSums::default();
    q.resize(w, 0);
    for y in 0..h {
        let r0 = &src.data[2 * y * src.width..][..2 * w];
        let r1 = &src.data[(2 * y + 1) * src.width..][..2 * w];
        box_sums_row(r0, r1, q);
        for (d, &q) in dst.data[y * w..][..w].iter_mut().zip(q.iter()) {
            *d = 0.25 * f32::from(q);
        }
        sums.add_row(q);
    }
    sums
}

/// `q[x] = r0[2x] + r0[2x+1] + r1[2x] + r1[2x+1]`. Eight pixels at a time as one `u64`
/// (four 16-bit lanes of pair sums: SIMD within a register, no byte shuffles needed).
fn box_sums_row(r0: &[u8], r1: &[u8], q: &mut [u16]) {
    const LO: u64 = 0x00ff_00ff_00ff_00ff;
    let word = |c: &[u8]| {
        let mut b = [0u8; 8];
        b.copy_from_slice(c);
        u64::from_le_bytes(b)
    };
    let mut qs = q.chunks_exact_mut(4);
    let (mut a8, mut b8) = (r0.chunks_exact(8), r1.chunks_exact(8));
    for ((qc, a), b) in (&mut qs).zip(&mut a8).zip(&mut b8) {
        let (a, b) = (word(a), word(b));
        let s = (a & LO) + ((a >> 8) & LO) + (b & LO) + ((b >> 8) & LO);
        for (k, v) in qc.iter_mut().enumerate() {
            *v = (s >> (16 * k)) as u16;
        }
    }
    let tail = qs.into_remainder();
    let (ra, rb) = (a8.remainder(), b8.remainder());
    for (k, v) in tail.iter_mut().enumerate() {
        let sum = [ra[2 * k], ra[2 * k + 1], rb[2 * k], rb[2 * k + 1]];
        *v = sum.iter().map(|&p| u16::from(p)).sum();
    }
}

/// [`BoxSums`] of a frame without coarse levels (each pixel stands for a box of four).
fn box_sums_full(src: &Gray8, q: &mut Vec<u16>) -> BoxSums {
    let mut sums = BoxSums::default();
    q.resize(src.width, 0);
    for row in src.data.chunks_exact(src.width.max(1)) {
        for (q, &v) in q.iter_mut().zip(row) {
            *q = 4 * u16::from(v);
        }
        sums.add_row(q);
    }
    sums
}

fn downsample(src: &GrayF32, dst: &mut GrayF32) {
    let (w, h) = (src.width / 2, src.height / 2);
    dst.resize(w, h);
    for y in 0..h {
        let r0 = &src.data[2 * y * src.width..][..2 * w];
        let r1 = &src.data[(2 * y + 1) * src.width..][..2 * w];
        let d = &mut dst.data[y * w..][..w];
        for ((d, a), b) in d.iter_mut().zip(r0.chunks_exact(2)).zip(r1.chunks_exact(2)) {
            *d = 0.25 * (a[0] + a[1] + b[0] + b[1]);
        }
    }
}

/// Cheap whole-frame statistics for rejecting unusable frames.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameStats {
    /// Mean intensity (0..255).
    pub mean: f32,
    /// Standard deviation of intensity (of the 2×2 box averages: without pixel-scale noise).
    pub std: f32,
    /// Fraction of 2×2 boxes averaging ≥ 250.
    pub saturated_fraction: f32,
    /// Mean |∂x| + |∂y| at level 0 divided by the intensity std, 1/px: the inverse of the
    /// typical scale of the image structure. Blur lowers it; compared with the previous frame's
    /// value it detects motion or focus blur whatever the scene's own texture scale.
    pub sharpness: f32,
}

/// The statistics of the pyramid's frame (computed when it was built).
pub fn frame_stats(p: &Pyramid) -> FrameStats {
    p.stats
}

/// Mean of |∂x| + |∂y| (forward differences) over every `step`-th row, in exact integers.
fn mean_abs_diff(img: &Gray8, step: usize) -> f32 {
    let (mut acc, mut n) = (0u64, 0u64);
    let w = img.width;
    for y in (0..img.height.saturating_sub(1)).step_by(step) {
        let r0 = &img.data[y * w..][..w];
        let r1 = &img.data[(y + 1) * w..][..w];
        let mut a = 0u32;
        for ((p, q), d) in r0.iter().zip(&r0[1..]).zip(r1) {
            a += u32::from(p.abs_diff(*q)) + u32::from(p.abs_diff(*d));
        }
        acc += u64::from(a);
        n += w.saturating_sub(1) as u64;
    }
    (acc as f64 / n.max(1) as f64) as f32
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn pyramid_and_sampling() {
        let (w, h) = (64, 48);
        let luma: Vec<u8> = (0..w * h).map(|i| ((i % w) * 2 + (i / w)) as u8).collect();
        let mut p = Pyramid::default();
        p.build(&luma, w, h, 3);
        assert_eq!((p.coarse[1].width, p.coarse[1].height), (16, 12));
        // linear ramp: bilinear sampling is exact
        let mut out = [0.0f32; 9];
        p.base.sample_patch(10.25, 20.5, 3, &mut out);
        assert!((out[0] - (10.25 * 2.0 + 20.5)).abs() < 1e-4);
        assert!((out[8] - (12.25 * 2.0 + 22.5)).abs() < 1e-4);
    }

    /// Level 1 and the statistics against a direct computation, on an odd-sized frame (tail
    /// of the eight-pixel loop) with saturated and black patches.
    #[test]
    fn box_average_and_stats() {
        let (w, h) = (45, 23);
        let mut luma: Vec<u8> = (0..w * h)
            .map(|i| ((i * 7919 + (i / w) * 31) % 256) as u8)
            .collect();
        for y in 0..8 {
            for x in 0..10 {
                luma[y * w + x] = 255;
                luma[(h - 1 - y) * w + w - 1 - x] = 0;
            }
        }
        let mut p = Pyramid::default();
        p.build(&luma, w, h, 2);
        let l1 = &p.coarse[0];
        assert_eq!((l1.width, l1.height), (22, 11));
        let (mut n, mut s, mut s2, mut sat) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for y in 0..11 {
            for x in 0..22 {
                let v = [(0, 0), (1, 0), (0, 1), (1, 1)]
                    .iter()
                    .map(|&(dx, dy)| f64::from(luma[(2 * y + dy) * w + 2 * x + dx]))
                    .sum::<f64>()
                    / 4.0;
                assert!((f64::from(l1.at(x, y)) - v).abs() < 1e-6, "({x}, {y})");
                n += 1.0;
                s += v;
                s2 += v * v;
                sat += f64::from(u8::from(v >= 250.0));
            }
        }
        let mean = s / n;
        let std = (s2 / n - mean * mean).sqrt();
        let st = p.stats;
        assert!((f64::from(st.mean) - mean).abs() < 1e-3);
        assert!((f64::from(st.std) - std).abs() < 1e-3);
        assert!((f64::from(st.saturated_fraction) - sat / n).abs() < 1e-6);
        assert!(sat > 0.0 && st.sharpness > 0.0);
    }
}
