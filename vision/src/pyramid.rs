//! Float gray images, the image pyramid (buffers reused across frames) and frame statistics
//! used to reject black, saturated, textureless and blurred frames.

/// A row-major single-channel `f32` image.
#[derive(Debug, Clone, Default)]
pub struct GrayF32 {
    /// Width, px.
    pub width: usize,
    /// Height, px.
    pub height: usize,
    /// Pixels, row-major, intensity 0..255.
    pub data: Vec<f32>,
}

impl GrayF32 {
    /// Resizes in place (reusing the allocation when it is large enough).
    pub fn resize(&mut self, width: usize, height: usize) {
        self.width = width;
        self.height = height;
        self.data.resize(width * height, 0.0);
    }

    /// Pixel at integer coordinates (no bounds check beyond the slice's).
    #[inline]
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x]
    }

    /// Whether a `(2r+1)²` window around `(x, y)` (plus one pixel for bilinear interpolation and
    /// one for central differences) lies inside the image.
    #[inline]
    pub fn window_inside(&self, x: f32, y: f32, r: usize) -> bool {
        let m = r as f32 + 2.0;
        x >= m && y >= m && x < self.width as f32 - m - 1.0 && y < self.height as f32 - m - 1.0
    }

    /// Samples a `side × side` patch whose top-left sample is at `(x0, y0)` (sub-pixel) by
    /// bilinear interpolation into `out`. The caller guarantees the patch is inside.
    /// The sub-pixel weights are the same for the whole patch, so each row is a short
    /// vectorizable loop.
    #[inline]
    pub fn sample_patch(&self, x0: f32, y0: f32, side: usize, out: &mut [f32]) {
        self.sample_patch_rect(x0, y0, side, side, out);
    }

    /// [`Self::sample_patch`] for a `cols × rows` patch.
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
                *d = w00 * a0 + w01 * a1 + w10 * b0 + w11 * b1;
            }
        }
    }
}

/// A Gaussian-like image pyramid: level 0 is the frame, each next level halves the size with a
/// 2×2 box average (cheap, and what KLT needs from coarse levels is only a good initial guess).
#[derive(Debug, Clone, Default)]
pub struct Pyramid {
    /// Levels, finest first.
    pub levels: Vec<GrayF32>,
}

impl Pyramid {
    /// Rebuilds from an 8-bit luma plane, reusing buffers.
    pub fn build(&mut self, luma: &[u8], width: usize, height: usize, n_levels: usize) {
        self.levels.resize_with(n_levels.max(1), GrayF32::default);
        let l0 = &mut self.levels[0];
        l0.resize(width, height);
        for (d, s) in l0.data.iter_mut().zip(luma) {
            *d = f32::from(*s);
        }
        for l in 1..self.levels.len() {
            let (lo, hi) = self.levels.split_at_mut(l);
            downsample(&lo[l - 1], &mut hi[0]);
        }
    }
}

fn downsample(src: &GrayF32, dst: &mut GrayF32) {
    let (w, h) = (src.width / 2, src.height / 2);
    dst.resize(w, h);
    for y in 0..h {
        let r0 = &src.data[2 * y * src.width..][..2 * w];
        let r1 = &src.data[(2 * y + 1) * src.width..][..2 * w];
        let d = &mut dst.data[y * w..][..w];
        for x in 0..w {
            d[x] = 0.25 * (r0[2 * x] + r0[2 * x + 1] + r1[2 * x] + r1[2 * x + 1]);
        }
    }
}

/// Cheap whole-frame statistics for rejecting unusable frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameStats {
    /// Mean intensity (0..255).
    pub mean: f32,
    /// Standard deviation of intensity.
    pub std: f32,
    /// Fraction of pixels at ≥ 250.
    pub saturated_fraction: f32,
    /// Mean |∂x| + |∂y| at level 0 divided by the intensity std, 1/px: the inverse of the
    /// typical scale of the image structure. Blur lowers it; compared with the previous frame's
    /// value it detects motion or focus blur whatever the scene's own texture scale.
    pub sharpness: f32,
}

/// Computes [`FrameStats`] (sub-sampled rows: only coarse figures are needed).
pub fn frame_stats(p: &Pyramid) -> FrameStats {
    let l0 = &p.levels[0];
    // intensity statistics on the half-resolution level (the box average keeps mean and
    // saturation; the std loses only pixel-scale noise)
    let ls = p.levels.get(1).unwrap_or(l0);
    let (mut n, mut s, mut s2, mut sat) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for row in ls.data.chunks_exact(ls.width.max(1)) {
        let (mut a, mut a2, mut c) = (0.0f32, 0.0f32, 0u32);
        for &v in row {
            a += v;
            a2 += v * v;
            c += u32::from(v >= 250.0);
        }
        n += row.len() as f64;
        s += f64::from(a);
        s2 += f64::from(a2);
        sat += f64::from(c);
    }
    let mean = s / n.max(1.0);
    let std = (s2 / n.max(1.0) - mean * mean).max(0.0).sqrt();
    let g0 = mean_abs_diff(l0, 4);
    let sharpness = if std > 1e-3 { g0 / std as f32 } else { 0.0 };
    FrameStats {
        mean: mean as f32,
        std: std as f32,
        saturated_fraction: (sat / n.max(1.0)) as f32,
        sharpness,
    }
}

/// Mean of |∂x| + |∂y| (forward differences) over every `step`-th row.
fn mean_abs_diff(img: &GrayF32, step: usize) -> f32 {
    let (mut acc, mut n) = (0.0f64, 0usize);
    let w = img.width;
    for y in (0..img.height.saturating_sub(1)).step_by(step) {
        let r0 = &img.data[y * w..][..w];
        let r1 = &img.data[(y + 1) * w..][..w];
        let mut a = 0.0f32;
        for x in 0..w - 1 {
            a += (r0[x + 1] - r0[x]).abs() + (r1[x] - r0[x]).abs();
        }
        acc += f64::from(a);
        n += w - 1;
    }
    (acc / n.max(1) as f64) as f32
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
        assert_eq!((p.levels[2].width, p.levels[2].height), (16, 12));
        // linear ramp: bilinear sampling is exact
        let mut out = [0.0f32; 9];
        p.levels[0].sample_patch(10.25, 20.5, 3, &mut out);
        assert!((out[0] - (10.25 * 2.0 + 20.5)).abs() < 1e-4);
        assert!((out[8] - (12.25 * 2.0 + 22.5)).abs() < 1e-4);
    }
}
