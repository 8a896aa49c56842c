//! Pyramidal Lucas–Kanade (paper IV-A, eq. 12) with
//! zero-mean patches (robust to exposure changes) and an externally supplied initial guess
//! (the IMU/terrain prediction).

pub use crate::corners::{CornerScratch, best_corner_in, best_corner_with, shi_tomasi};
use crate::pyramid::{Image, Pixel, Pyramid};

/// Lucas–Kanade settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KltParams {
    /// Half window: the window is `(2r+1)²` pixels. Default 5 (11×11).
    pub half_window: usize,
    /// Maximum Gauss–Newton iterations per pyramid level. Default 8.
    pub max_iterations: usize,
    /// Convergence: stop when the update is below this, px. Default 0.02.
    pub epsilon_px: f32,
    /// Minimum mean structure-tensor eigenvalue of a window (gray²/px²). Default 1.0.
    pub min_eigen: f32,
}

impl Default for KltParams {
    fn default() -> Self {
        Self {
            half_window: 5,
            max_iterations: 8,
            epsilon_px: 0.02,
            min_eigen: 1.0,
        }
    }
}

/// Largest padded window (rows of `2R+1` samples padded to whole groups of four, R ≤ 10).
const MAX_WIN: usize = 24 * 21;
/// Largest template with its one-pixel gradient border.
const MAX_EXT: usize = 26 * 23;

/// Scratch buffers for one tracker (allocated once, reused for every feature). Fixed-size
/// arrays: with the window size a compile-time constant in the kernels, every loop has a fixed
/// length and no bounds checks, so the compiler unrolls and vectorizes them.
#[derive(Debug)]
pub struct KltScratch {
    /// Template samples with a one-pixel border for the gradients.
    ext: Box<[f32; MAX_EXT]>,
    /// Template values and gradients, rows padded to whole groups of four (pad lanes zero).
    tv: Box<[f32; MAX_WIN]>,
    gx: Box<[f32; MAX_WIN]>,
    gy: Box<[f32; MAX_WIN]>,
    /// The sampled window of `next`.
    win: Box<[f32; MAX_WIN]>,
    /// Horizontally interpolated rows (separable bilinear sampling).
    hbuf: Box<[f32; MAX_EXT + 26]>,
    /// 1 in the window's lanes, 0 in the pads, for the half window `mask_r` (0: not yet set).
    mask: Box<[f32; MAX_WIN]>,
    mask_r: usize,
    /// Level-0 templates saved in this frame, and those saved in the previous one.
    saved: TemplateStore,
    loaded: TemplateStore,
}

impl KltScratch {
    /// Makes the templates saved since the last call loadable (and forgets the older ones):
    /// call once per frame, when the new frame becomes the reference.
    pub fn next_frame(&mut self) {
        std::mem::swap(&mut self.saved, &mut self.loaded);
        self.saved.meta.clear();
    }
}

/// Which template slot a level-0 kernel loads from (the previous frame's store) or saves to
/// (this frame's store); see [`track_with_templates`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    /// Neither.
    None,
    /// Use the template saved in slot `k` of the previous frame when there is one.
    Load(usize),
    /// Save the template into slot `k`.
    Save(usize),
}

/// Level-0 templates (gradients and sums), slot by slot: the backward check of frame k samples
/// the template at `p1` in frame k, exactly what the forward tracking of frame k + 1 samples at
/// `p0 = p1` — kept instead of computed twice (only for unwarped templates).
#[derive(Debug, Default)]
struct TemplateStore {
    /// Half window and gradient floats per slot the store holds.
    r: usize,
    n: usize,
    /// Per slot: `gx` then `gy`.
    grads: Vec<f32>,
    meta: Vec<Option<Template>>,
}

impl TemplateStore {
    fn invalidate(&mut self, k: usize) {
        if let Some(m) = self.meta.get_mut(k) {
            *m = None;
        }
    }

    fn put(&mut self, k: usize, r: usize, t: &Template, gx: &[f32], gy: &[f32]) {
        let n = gx.len();
        if (self.r, self.n) != (r, n) {
            (self.r, self.n) = (r, n);
            self.meta.clear();
        }
        if self.meta.len() <= k {
            self.meta.resize(k + 1, None);
        }
        if self.grads.len() < (k + 1) * 2 * n {
            self.grads.resize((k + 1) * 2 * n, 0.0);
        }
        let g = &mut self.grads[k * 2 * n..(k + 1) * 2 * n];
        g[..n].copy_from_slice(gx);
        g[n..].copy_from_slice(gy);
        self.meta[k] = Some(*t);
    }

    fn get(&self, k: usize, r: usize) -> Option<(Template, &[f32], &[f32])> {
        let t = (*self.meta.get(k)?)?;
        (self.r == r).then_some(())?;
        let n = self.n;
        let g = &self.grads[k * 2 * n..(k + 1) * 2 * n];
        Some((t, &g[..n], &g[n..]))
    }
}

impl Default for KltScratch {
    fn default() -> Self {
        Self {
            ext: Box::new([0.0; MAX_EXT]),
            tv: Box::new([0.0; MAX_WIN]),
            gx: Box::new([0.0; MAX_WIN]),
            gy: Box::new([0.0; MAX_WIN]),
            win: Box::new([0.0; MAX_WIN]),
            hbuf: Box::new([0.0; MAX_EXT + 26]),
            mask: Box::new([0.0; MAX_WIN]),
            mask_r: 0,
            saved: TemplateStore::default(),
            loaded: TemplateStore::default(),
        }
    }
}

/// Local affine map of the predicted motion: a window offset `x` in `prev` appears at `A x`
/// in `next` (row-major `[a00, a01, a10, a11]`). `None` = identity (fast path).
pub type Affine = Option<[f32; 4]>;

/// A tracked point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Track {
    /// Position in `next`, level-0 px.
    pub pos: [f32; 2],
    /// Whether the finest level converged (last update below `epsilon_px`) within
    /// `max_iterations`.
    pub converged: bool,
}

/// Tracks a point from `prev` into `next`; the position only, see [`track`].
#[allow(clippy::too_many_arguments)] // the tracker's inputs are all distinct
pub fn track_point(
    prev: &Pyramid,
    next: &Pyramid,
    p0: [f32; 2],
    guess: [f32; 2],
    affine: Affine,
    top_level: usize,
    params: &KltParams,
    s: &mut KltScratch,
) -> Option<[f32; 2]> {
    track(prev, next, p0, guess, affine, top_level, params, s).map(|t| t.pos)
}

/// Tracks a point from `prev` into `next`.
///
/// With `affine`, the template is sampled from `prev` on the grid `p + A⁻¹ x` (once per level),
/// so large predicted rotations (IMU aid) do not break the translation-only window model while
/// the iterations sample `next` on an axis-aligned grid (the fast path).
///
/// `p0` is the point in `prev` (level-0 px), `guess` its predicted position in `next`; the
/// search starts at `top_level` (≤ pyramid depth − 1) from the guess. Returns `None` when the
/// point left the image, the window is flat, or the system is singular.
#[allow(clippy::too_many_arguments)] // the tracker's inputs are all distinct
pub fn track(
    prev: &Pyramid,
    next: &Pyramid,
    p0: [f32; 2],
    guess: [f32; 2],
    affine: Affine,
    top_level: usize,
    params: &KltParams,
    s: &mut KltScratch,
) -> Option<Track> {
    track_with_templates(
        prev,
        next,
        p0,
        guess,
        affine,
        top_level,
        params,
        s,
        Slot::None,
    )
}

/// [`track`] that also loads or saves its level-0 template (`slot`): the front end saves the
/// template of each backward check and loads it when it tracks the same point out of the same
/// frame one frame later. Only unwarped templates (no `affine`) are saved or loaded.
#[allow(clippy::too_many_arguments)] // the tracker's inputs are all distinct
pub fn track_with_templates(
    prev: &Pyramid,
    next: &Pyramid,
    p0: [f32; 2],
    guess: [f32; 2],
    affine: Affine,
    top_level: usize,
    params: &KltParams,
    s: &mut KltScratch,
    slot: Slot,
) -> Option<Track> {
    let depth = prev.depth().min(next.depth());
    // the template is warped by the inverse map; a degenerate prediction is not usable
    let warp = match affine {
        Some(a) => Some(invert2(a)?),
        None => None,
    };
    let top = top_level.min(depth - 1);
    let scale = 1.0 / (1u32 << top) as f32;
    let mut flow = [(guess[0] - p0[0]) * scale, (guess[1] - p0[1]) * scale];
    let mut converged = false;
    for level in (0..=top).rev() {
        let sc = 1.0 / (1u32 << level) as f32;
        let pl = [p0[0] * sc, p0[1] * sc];
        let tracked = match level {
            0 => track_level(&prev.base, &next.base, pl, flow, warp, params, s, slot),
            l => {
                let (a, b) = (&prev.coarse[l - 1], &next.coarse[l - 1]);
                track_level(a, b, pl, flow, warp, params, s, Slot::None)
            }
        };
        match tracked {
            Some((f, c)) => {
                flow = f;
                converged = c;
            }
            // Coarse levels may clip at the border: keep the guess and refine finer.
            None if level > 0 => {}
            None => return None,
        }
        if level > 0 {
            flow = [flow[0] * 2.0, flow[1] * 2.0];
        }
    }
    Some(Track {
        pos: [p0[0] + flow[0], p0[1] + flow[1]],
        converged,
    })
}

/// Inverse of a 2×2 row-major matrix; `None` when (nearly) singular or not finite.
pub fn invert2(a: [f32; 4]) -> Option<[f32; 4]> {
    let det = a[0] * a[3] - a[1] * a[2];
    (det.abs() > 1e-6 && det.is_finite())
        .then(|| [a[3] / det, -a[1] / det, -a[2] / det, a[0] / det])
}

/// Lane-wise sums over four lanes: `f32` reductions written this way vectorize (SSE2/NEON)
/// without `unsafe` or fast-math; the order of the additions is fixed, so results are
/// deterministic.
type F4 = [f32; 4];

#[inline(always)]
fn hsum(a: F4) -> f32 {
    (a[0] + a[2]) + (a[1] + a[3])
}

/// `Σ a·b` over slices whose length is a multiple of four, four lanes at a time (one sum per
/// loop: several accumulators in one loop defeat the vectorizer).
#[inline(always)]
fn dot4(a: &[f32], b: &[f32]) -> f32 {
    let mut acc: F4 = [0.0; 4];
    for (x, y) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        for k in 0..4 {
            acc[k] += x[k] * y[k];
        }
    }
    hsum(acc)
}

/// Dispatches one pyramid level to the kernel specialised for the window size (fixed loop
/// lengths let the compiler unroll and vectorize the rows). Half windows above 10 use 10.
#[allow(clippy::too_many_arguments)] // the tracker's inputs are all distinct
fn track_level<T: Pixel>(
    prev: &Image<T>,
    next: &Image<T>,
    p: [f32; 2],
    flow: [f32; 2],
    warp: Option<[f32; 4]>,
    params: &KltParams,
    s: &mut KltScratch,
    slot: Slot,
) -> Option<([f32; 2], bool)> {
    // (R, chunks of four lanes per row of 2R+1 samples)
    match params.half_window {
        0 | 1 => level_kernel::<T, 1, 1>(prev, next, p, flow, warp, params, s, slot),
        2 => level_kernel::<T, 2, 2>(prev, next, p, flow, warp, params, s, slot),
        3 => level_kernel::<T, 3, 2>(prev, next, p, flow, warp, params, s, slot),
        4 => level_kernel::<T, 4, 3>(prev, next, p, flow, warp, params, s, slot),
        5 => level_kernel::<T, 5, 3>(prev, next, p, flow, warp, params, s, slot),
        6 => level_kernel::<T, 6, 4>(prev, next, p, flow, warp, params, s, slot),
        7 => level_kernel::<T, 7, 4>(prev, next, p, flow, warp, params, s, slot),
        8 => level_kernel::<T, 8, 5>(prev, next, p, flow, warp, params, s, slot),
        9 => level_kernel::<T, 9, 5>(prev, next, p, flow, warp, params, s, slot),
        _ => level_kernel::<T, 10, 6>(prev, next, p, flow, warp, params, s, slot),
    }
}

/// The template of one level: its structure tensor and the constant parts of the right-hand
/// side (see [`level_kernel`]).
#[derive(Debug, Clone, Copy)]
struct Template {
    gxx: f32,
    gxy: f32,
    gyy: f32,
    /// Σ t̃·∇T, t̃ the centred template.
    tg: [f32; 2],
    /// Σ ∇T.
    sg: [f32; 2],
    /// Template mean (subtracted from the samples of `next` to keep the sums small).
    mean: f32,
}

/// Integer origin and sub-pixel fractions of a region whose top-left sample is `(x0, y0)` and
/// which reads pixels `[xi, xi + cols] × [yi, yi + rows]` (bilinear needs the extra one);
/// `None` when that is not inside the image (or the position is not finite).
#[inline]
fn region<T: Pixel>(
    img: &Image<T>,
    x0: f32,
    y0: f32,
    cols: usize,
    rows: usize,
) -> Option<(usize, usize, f32, f32)> {
    if !(x0 >= 0.0 && y0 >= 0.0) {
        return None;
    }
    // non-negative: truncation is the floor
    let (xi, yi) = (x0 as usize, y0 as usize);
    (xi + cols < img.width && yi + rows < img.height).then_some((
        xi,
        yi,
        x0 - xi as f32,
        y0 - yi as f32,
    ))
}

/// Bilinear samples of `img` on a `rows × cols` grid with unit spacing starting at the
/// sub-pixel position `(xi + ax, yi + ay)` (one set of weights for the whole grid), minus
/// `offset`, into `out` (row-major, `cols` per row). Separable: each image row is interpolated
/// horizontally once into `h` (`(rows + 1) × cols`), then pairs of rows vertically. The caller
/// checked the region.
#[allow(clippy::too_many_arguments)] // a sampling kernel: the grid, the weights, the buffers
#[inline(always)]
fn sample_grid<T: Pixel>(
    img: &Image<T>,
    (xi, yi, ax, ay): (usize, usize, f32, f32),
    rows: usize,
    cols: usize,
    offset: f32,
    h: &mut [f32],
    out: &mut [f32],
) {
    let w = img.width;
    for y in 0..=rows {
        let r = &img.data[(yi + y) * w + xi..][..cols + 1];
        let hr = &mut h[y * cols..y * cols + cols];
        for x in 0..cols {
            let a = r[x].value();
            hr[x] = a + ax * (r[x + 1].value() - a);
        }
    }
    for y in 0..rows {
        let (t, b) = (
            &h[y * cols..y * cols + cols],
            &h[(y + 1) * cols..(y + 2) * cols],
        );
        let o = &mut out[y * cols..y * cols + cols];
        for x in 0..cols {
            o[x] = t[x] + ay * (b[x] - t[x]) - offset;
        }
    }
}

/// Samples the template of `prev` around `p` into `ext`: `2R+3` rows (a one-pixel border for
/// the gradients) of `ew` samples (the padded row plus the border), on the grid `p + M x`
/// when a warp `M` is given.
#[inline(always)]
fn sample_template<T: Pixel, const R: usize>(
    prev: &Image<T>,
    p: [f32; 2],
    warp: Option<[f32; 4]>,
    ew: usize,
    ext: &mut [f32],
    hbuf: &mut [f32],
) -> Option<()> {
    let rows = 2 * R + 3;
    let h = (R + 1) as f32;
    match warp {
        None => {
            let at = region(prev, p[0] - h, p[1] - h, ew, rows)?;
            sample_grid(prev, at, rows, ew, 0.0, hbuf, ext);
        }
        Some(m) => sample_warped(prev, p, &m, h, rows, ew, ext)?,
    }
    Some(())
}

/// [`sample_template`] on the warped grid `p + M (x − h, y − h)`, per-pixel bilinear.
fn sample_warped<T: Pixel>(
    prev: &Image<T>,
    p: [f32; 2],
    m: &[f32; 4],
    h: f32,
    rows: usize,
    ew: usize,
    ext: &mut [f32],
) -> Option<()> {
    // grid origin (top-left sample) in `prev`; the extreme samples are at the corners, and a
    // sample at s reads floor(s) + 1 ≤ floor(min) + floor(span) + 2
    let o = [p[0] - h * (m[0] + m[1]), p[1] - h * (m[2] + m[3])];
    let (wx, wy) = ((ew - 1) as f32, (rows - 1) as f32);
    let span = |a: f32, b: f32| {
        let c = [0.0, a * wx, b * wy, a * wx + b * wy];
        let lo = c.iter().fold(0.0f32, |u, &v| u.min(v));
        let hi = c.iter().fold(0.0f32, |u, &v| u.max(v));
        (lo, hi - lo)
    };
    let ((x_lo, x_span), (y_lo, y_span)) = (span(m[0], m[1]), span(m[2], m[3]));
    region(
        prev,
        o[0] + x_lo,
        o[1] + y_lo,
        x_span as usize + 2,
        y_span as usize + 2,
    )?;
    let w = prev.width;
    let d = &prev.data;
    for (j, row) in ext[..rows * ew].chunks_exact_mut(ew).enumerate() {
        let y = j as f32;
        for (i, out) in row.iter_mut().enumerate() {
            let x = i as f32;
            let sx = o[0] + m[0] * x + m[1] * y;
            let sy = o[1] + m[2] * x + m[3] * y;
            // inside by the check above: non-negative, truncation is the floor
            let (fx, fy) = (sx as usize, sy as usize);
            let (ax, ay) = (sx - fx as f32, sy - fy as f32);
            let k = fy * w + fx;
            let (a0, a1) = (d[k].value(), d[k + 1].value());
            let (b0, b1) = (d[k + w].value(), d[k + w + 1].value());
            let (top, bot) = (a0 + ax * (a1 - a0), b0 + ax * (b1 - b0));
            *out = top + ay * (bot - top);
        }
    }
    Some(())
}

/// Gradients (central differences) and values of the template in `s.ext`, as `2R+1` rows of
/// `4·NC` lanes (pad lanes zero), and the template's sums. `None` for a flat window (paper
/// eq. 12 needs an invertible structure tensor).
#[inline(always)]
fn prepare_template<const R: usize, const NC: usize>(
    s: &mut KltScratch,
    min_eigen: f32,
) -> Option<Template> {
    let side = 2 * R + 1;
    let pw = 4 * NC;
    let ew = pw + 2;
    let n = side * pw;
    let ext = &s.ext[..(side + 2) * ew];
    let (tv, gx, gy) = (&mut s.tv[..n], &mut s.gx[..n], &mut s.gy[..n]);
    for y in 0..side {
        let up = &ext[y * ew..y * ew + ew];
        let mid = &ext[(y + 1) * ew..(y + 1) * ew + ew];
        let dn = &ext[(y + 2) * ew..(y + 2) * ew + ew];
        let o = y * pw;
        for x in 0..pw {
            let m = if x < side { 1.0 } else { 0.0 };
            tv[o + x] = m * mid[x + 1];
            gx[o + x] = m * 0.5 * (mid[x + 2] - mid[x]);
            gy[o + x] = m * 0.5 * (dn[x + 1] - up[x + 1]);
        }
    }
    let (gx, gy, tv, m) = (&*gx, &*gy, &*tv, &s.mask[..n]);
    let (gxx, gxy, gyy) = (dot4(gx, gx), dot4(gx, gy), dot4(gy, gy));
    let nf = (side * side) as f32;
    let det = gxx * gyy - gxy * gxy;
    let min_eig = 0.5 * (gxx + gyy - ((gxx - gyy).powi(2) + 4.0 * gxy * gxy).sqrt()) / nf;
    if !(min_eig >= min_eigen && det > 0.0) {
        return None;
    }
    let mean = dot4(tv, m) / nf;
    let sg = [dot4(gx, m), dot4(gy, m)];
    // Σ t̃ g = Σ T g − mean Σ g
    let tg = [dot4(tv, gx) - mean * sg[0], dot4(tv, gy) - mean * sg[1]];
    Some(Template {
        gxx,
        gxy,
        gyy,
        tg,
        sg,
        mean,
    })
}

/// One level of Lucas–Kanade (paper eq. 12): finds `flow` with
/// `next(p + flow + x) − mean ≈ prev(p + M x) − mean` over the `(2R+1)²` window, linearized
/// with the template gradient so the 2×2 system is built once. Zero-mean residuals make it
/// robust to exposure changes. With `e = t̃ − (J − J̄)` the right-hand side
/// `Σ e ∇T = Σ t̃ ∇T − Σ J ∇T + J̄ Σ ∇T` needs three sums of the sampled window `J` per
/// iteration. Returns the flow and whether the last update was below `epsilon_px`.
#[allow(clippy::too_many_arguments)] // the tracker's inputs are all distinct
fn level_kernel<T: Pixel, const R: usize, const NC: usize>(
    prev: &Image<T>,
    next: &Image<T>,
    p: [f32; 2],
    mut flow: [f32; 2],
    warp: Option<[f32; 4]>,
    params: &KltParams,
    s: &mut KltScratch,
    slot: Slot,
) -> Option<([f32; 2], bool)> {
    let side = 2 * R + 1;
    let pw = 4 * NC;
    debug_assert!(pw >= side && pw < side + 4);
    let n = side * pw;
    if s.mask_r != R {
        for (i, m) in s.mask[..n].iter_mut().enumerate() {
            *m = if i % pw < side { 1.0 } else { 0.0 };
        }
        s.mask_r = R;
    }
    let loaded = match slot {
        Slot::Load(k) if warp.is_none() => s.loaded.get(k, R).map(|(t, gx, gy)| {
            s.gx[..n].copy_from_slice(gx);
            s.gy[..n].copy_from_slice(gy);
            t
        }),
        _ => None,
    };
    let t = match loaded {
        Some(t) => t,
        None => {
            if let Slot::Save(k) = slot {
                s.saved.invalidate(k);
            }
            sample_template::<T, R>(prev, p, warp, pw + 2, &mut s.ext[..], &mut s.hbuf[..])?;
            let t = prepare_template::<R, NC>(s, params.min_eigen)?;
            if let (Slot::Save(k), None) = (slot, warp) {
                s.saved.put(k, R, &t, &s.gx[..n], &s.gy[..n]);
            }
            t
        }
    };
    let inv = 1.0 / (t.gxx * t.gyy - t.gxy * t.gxy);
    let nf = (side * side) as f32;
    let (gx, gy, mask) = (&s.gx[..n], &s.gy[..n], &s.mask[..n]);
    let (win, hbuf) = (&mut s.win[..n], &mut s.hbuf[..]);
    let eps2 = params.epsilon_px * params.epsilon_px;
    for _ in 0..params.max_iterations {
        let q = [p[0] + flow[0] - R as f32, p[1] + flow[1] - R as f32];
        let at = region(next, q[0], q[1], pw, side)?;
        // samples shifted by the template mean (keeps the sums small)
        sample_grid(next, at, side, pw, t.mean, hbuf, win);
        // the pad lanes carry samples but zero gradients: masked in Σ J only
        let jmean = dot4(win, mask) / nf;
        let bx = t.tg[0] - dot4(win, gx) + jmean * t.sg[0];
        let by = t.tg[1] - dot4(win, gy) + jmean * t.sg[1];
        let (dx, dy) = (
            inv * (t.gyy * bx - t.gxy * by),
            inv * (t.gxx * by - t.gxy * bx),
        );
        flow[0] += dx;
        flow[1] += dy;
        if dx * dx + dy * dy < eps2 {
            return Some((flow, true));
        }
    }
    Some((flow, false))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::synthetic::{Texture, render_affine};

    fn pyr(img: &[u8], w: usize, h: usize) -> Pyramid {
        let mut p = Pyramid::default();
        p.build(img, w, h, 3);
        p
    }

    /// Tracks corners of a texture warped by a rotation `deg` about the centre plus a shift;
    /// returns the largest error, px.
    fn max_track_error(deg: f64, shift: [f64; 2]) -> f64 {
        let (w, h) = (320, 240);
        let tex = Texture::new(7);
        let a = render_affine(&tex, w, h, [[1.0, 0.0], [0.0, 1.0]], [0.0, 0.0]);
        let ang = deg.to_radians();
        let (c, s) = (ang.cos(), ang.sin());
        let m = [[c, -s], [s, c]];
        let ctr = [160.0, 120.0];
        let off = [
            ctr[0] - (m[0][0] * ctr[0] + m[0][1] * ctr[1]) + shift[0],
            ctr[1] - (m[1][0] * ctr[0] + m[1][1] * ctr[1]) + shift[1],
        ];
        // a point p in a moves to M p + off in b
        let b = render_affine(&tex, w, h, m, off);
        let (pa, pb) = (pyr(&a, w, h), pyr(&b, w, h));
        let params = KltParams {
            half_window: 7,
            ..KltParams::default()
        };
        let mut sc = KltScratch::default();
        let (mut n_ok, mut worst) = (0, 0.0f64);
        for gy in 0..5 {
            for gx in 0..7 {
                let cell = (
                    60 + gx * 30,
                    60 + gx * 30 + 30,
                    50 + gy * 30,
                    50 + gy * 30 + 30,
                );
                let Some((p, _)) = best_corner_in(&pa.base, cell, 2, 2.0) else {
                    continue;
                };
                let (px, py) = (f64::from(p[0]), f64::from(p[1]));
                let want = [
                    m[0][0] * px + m[0][1] * py + off[0],
                    m[1][0] * px + m[1][1] * py + off[1],
                ];
                let got = track_point(&pa, &pb, p, p, None, 2, &params, &mut sc).unwrap();
                let err = ((f64::from(got[0]) - want[0]).powi(2)
                    + (f64::from(got[1]) - want[1]).powi(2))
                .sqrt();
                worst = worst.max(err);
                n_ok += 1;
            }
        }
        assert!(n_ok > 25);
        worst
    }

    /// A template saved by one track and loaded by the next (same image, same point) gives
    /// exactly the result of computing it again; a slot whose last save was skipped (warped
    /// template) is not loaded.
    #[test]
    fn saved_templates_are_exact() {
        let (w, h) = (320, 240);
        let tex = Texture::new(11);
        let id = [[1.0, 0.0], [0.0, 1.0]];
        let a = pyr(&render_affine(&tex, w, h, id, [0.0, 0.0]), w, h);
        let b = pyr(&render_affine(&tex, w, h, id, [3.4, -1.7]), w, h);
        let c = pyr(&render_affine(&tex, w, h, id, [6.1, -2.9]), w, h);
        let params = KltParams::default();
        let p1 = [150.3, 101.7];
        let (mut s, mut fresh) = (KltScratch::default(), KltScratch::default());
        // "backward" b → a at p1 saves into slot 0; slot 1 is saved and then overwritten by a
        // warped template
        let guess = [p1[0] - 3.4, p1[1] + 1.7];
        let save = |k| Slot::Save(k);
        track_with_templates(&b, &a, p1, guess, None, 0, &params, &mut s, save(0)).unwrap();
        track_with_templates(&b, &a, p1, guess, None, 0, &params, &mut s, save(1)).unwrap();
        let warp = Some([1.01, 0.0, 0.0, 1.01]);
        track_with_templates(&b, &a, p1, guess, warp, 0, &params, &mut s, save(1)).unwrap();
        s.next_frame();
        let guess = [p1[0] + 2.5, p1[1] - 1.0];
        let want = track(&b, &c, p1, guess, None, 0, &params, &mut fresh).unwrap();
        for k in 0..2 {
            let got =
                track_with_templates(&b, &c, p1, guess, None, 0, &params, &mut s, Slot::Load(k))
                    .unwrap();
            assert_eq!(got, want);
        }
        // the load does happen: slot 0 used for another point gives another answer
        let q = [p1[0] + 4.0, p1[1] + 3.0];
        let gq = [q[0] + 2.5, q[1] - 1.0];
        let other = track(&b, &c, q, gq, None, 0, &params, &mut fresh);
        let misused = track_with_templates(&b, &c, q, gq, None, 0, &params, &mut s, Slot::Load(0));
        assert_ne!(other, misused);
        assert!(
            (want.pos[0] - (p1[0] + 2.7)).abs() < 0.05
                && (want.pos[1] - (p1[1] - 1.2)).abs() < 0.05
        );
    }

    #[test]
    fn tracks_shift() {
        let e = max_track_error(0.0, [7.3, -4.6]);
        assert!(e < 0.05, "max err {e}");
    }

    #[test]
    fn tracks_shift_and_rotation() {
        // a translation-only window model under a 3° rotation: small bias at the window edges
        let e = max_track_error(3.0, [7.3, -4.6]);
        assert!(e < 0.3, "max err {e}");
    }
}
