//! Grid-spread Shi–Tomasi corners and pyramidal Lucas–Kanade (paper IV-A, eq. 12) with
//! zero-mean patches (robust to exposure changes) and an externally supplied initial guess
//! (the IMU/terrain prediction).

use crate::pyramid::{GrayF32, Pyramid};

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

/// Scratch buffers for one tracker (allocated once).
#[derive(Debug, Default)]
pub struct KltScratch {
    template: Vec<f32>,
    gx: Vec<f32>,
    gy: Vec<f32>,
    patch: Vec<f32>,
}

/// Local affine map of the predicted motion: a window offset `x` in `prev` appears at `A x`
/// in `next` (row-major `[a00, a01, a10, a11]`). `None` = identity (fast path).
pub type Affine = Option<[f32; 4]>;

/// Tracks a point from `prev` into `next`.
///
/// With `affine`, the window in `next` is sampled on the predicted warped grid, so large
/// predicted rotations (IMU aid) do not break the translation-only window model.
///
/// `p0` is the point in `prev` (level-0 px), `guess` its predicted position in `next`; the
/// search starts at `top_level` (≤ pyramid depth − 1) from the guess. Returns the tracked
/// position or `None` (left the image, flat window, or singular system).
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
    let top = top_level.min(prev.levels.len().min(next.levels.len()) - 1);
    let scale = 1.0 / (1u32 << top) as f32;
    let mut flow = [(guess[0] - p0[0]) * scale, (guess[1] - p0[1]) * scale];
    for level in (0..=top).rev() {
        let sc = 1.0 / (1u32 << level) as f32;
        let pl = [p0[0] * sc, p0[1] * sc];
        match track_level(
            &prev.levels[level],
            &next.levels[level],
            pl,
            flow,
            affine,
            params,
            s,
        ) {
            Some(f) => flow = f,
            // Coarse levels may clip at the border: keep the guess and refine finer.
            None if level > 0 => {}
            None => return None,
        }
        if level > 0 {
            flow = [flow[0] * 2.0, flow[1] * 2.0];
        }
    }
    Some([p0[0] + flow[0], p0[1] + flow[1]])
}

/// One level of Lucas–Kanade: finds `flow` with `next(p + flow + x) ≈ prev(p + x)` over the
/// window, linearized with the template gradient (so the 2×2 system is built once).
fn track_level(
    prev: &GrayF32,
    next: &GrayF32,
    p: [f32; 2],
    mut flow: [f32; 2],
    affine: Affine,
    params: &KltParams,
    s: &mut KltScratch,
) -> Option<[f32; 2]> {
    let r = params.half_window;
    let side = 2 * r + 1;
    let n = side * side;
    if !prev.window_inside(p[0], p[1], r) {
        return None;
    }
    let ext = side + 2;
    s.template.resize(ext * ext, 0.0);
    s.gx.resize(n, 0.0);
    s.gy.resize(n, 0.0);
    s.patch.resize(n, 0.0);
    prev.sample_patch(
        p[0] - r as f32 - 1.0,
        p[1] - r as f32 - 1.0,
        ext,
        &mut s.template,
    );
    let (mut gxx, mut gxy, mut gyy, mut tsum) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
    for y in 0..side {
        for x in 0..side {
            let c = (y + 1) * ext + x + 1;
            let gx = 0.5 * (s.template[c + 1] - s.template[c - 1]);
            let gy = 0.5 * (s.template[c + ext] - s.template[c - ext]);
            let i = y * side + x;
            s.gx[i] = gx;
            s.gy[i] = gy;
            gxx += gx * gx;
            gxy += gx * gy;
            gyy += gy * gy;
            tsum += s.template[c];
        }
    }
    let nf = n as f32;
    let det = gxx * gyy - gxy * gxy;
    let tr = gxx + gyy;
    let min_eig = 0.5 * (tr - ((gxx - gyy).powi(2) + 4.0 * gxy * gxy).sqrt()) / nf;
    if min_eig < params.min_eigen || det <= 0.0 {
        return None;
    }
    let tmean = tsum / nf;
    // Keep the centred template row-compact in `patch`'s companion: reuse the first n entries.
    for y in 0..side {
        for x in 0..side {
            s.template[y * side + x] = s.template[(y + 1) * ext + x + 1] - tmean;
        }
    }
    let inv = 1.0 / det;
    for _ in 0..params.max_iterations {
        let (qx, qy) = (p[0] + flow[0], p[1] + flow[1]);
        match affine {
            None => {
                if !next.window_inside(qx, qy, r) {
                    return None;
                }
                next.sample_patch(qx - r as f32, qy - r as f32, side, &mut s.patch);
            }
            Some(a) => {
                let reach = (a[0].abs() + a[1].abs()).max(a[2].abs() + a[3].abs());
                if !next.window_inside(qx, qy, (r as f32 * reach).ceil() as usize) {
                    return None;
                }
                sample_warped(next, [qx, qy], &a, r, &mut s.patch);
            }
        }
        let jmean = s.patch[..n].iter().sum::<f32>() / nf;
        let (mut bx, mut by) = (0.0f32, 0.0f32);
        for (((t, j), gx), gy) in s.template[..n]
            .iter()
            .zip(&s.patch[..n])
            .zip(&s.gx[..n])
            .zip(&s.gy[..n])
        {
            let e = t - (j - jmean);
            bx += e * gx;
            by += e * gy;
        }
        // the update is in template coordinates; in `next` it is A·δ
        let (ux, uy) = (inv * (gyy * bx - gxy * by), inv * (gxx * by - gxy * bx));
        let (dx, dy) = match affine {
            None => (ux, uy),
            Some(a) => (a[0] * ux + a[1] * uy, a[2] * ux + a[3] * uy),
        };
        flow[0] += dx;
        flow[1] += dy;
        if dx * dx + dy * dy < params.epsilon_px * params.epsilon_px {
            break;
        }
    }
    Some(flow)
}

/// Samples the window `q + A x`, `x ∈ [−r, r]²`, by per-pixel bilinear interpolation.
fn sample_warped(img: &GrayF32, q: [f32; 2], a: &[f32; 4], r: usize, out: &mut [f32]) {
    let side = 2 * r + 1;
    let w = img.width;
    for yy in 0..side {
        let y = yy as f32 - r as f32;
        for xx in 0..side {
            let x = xx as f32 - r as f32;
            let (sx, sy) = (q[0] + a[0] * x + a[1] * y, q[1] + a[2] * x + a[3] * y);
            let (fx, fy) = (sx.floor(), sy.floor());
            let (ax, ay) = (sx - fx, sy - fy);
            let i = fy as usize * w + fx as usize;
            let d = &img.data;
            out[yy * side + xx] = (1.0 - ay) * ((1.0 - ax) * d[i] + ax * d[i + 1])
                + ay * ((1.0 - ax) * d[i + w] + ax * d[i + w + 1]);
        }
    }
}

/// Shi–Tomasi score (mean minimum eigenvalue of the 5×5 structure tensor) at an integer pixel.
/// The caller keeps `(x, y)` at least 3 px inside the image.
#[inline]
pub fn shi_tomasi(img: &GrayF32, x: usize, y: usize) -> f32 {
    let w = img.width;
    let (mut a, mut b, mut c) = (0.0f32, 0.0f32, 0.0f32);
    for yy in y - 2..=y + 2 {
        let row = &img.data[yy * w..];
        let up = &img.data[(yy - 1) * w..];
        let dn = &img.data[(yy + 1) * w..];
        for xx in x - 2..=x + 2 {
            let gx = 0.5 * (row[xx + 1] - row[xx - 1]);
            let gy = 0.5 * (dn[xx] - up[xx]);
            a += gx * gx;
            b += gx * gy;
            c += gy * gy;
        }
    }
    0.5 * (a + c - ((a - c) * (a - c) + 4.0 * b * b).sqrt()) / 25.0
}

/// Best corner inside `[x0, x1) × [y0, y1)` sampled every `step` px; `None` below `min_score`.
pub fn best_corner_in(
    img: &GrayF32,
    (x0, x1, y0, y1): (usize, usize, usize, usize),
    step: usize,
    min_score: f32,
) -> Option<([f32; 2], f32)> {
    let m = 4;
    let (x0, y0) = (x0.max(m), y0.max(m));
    let (x1, y1) = (
        x1.min(img.width.saturating_sub(m)),
        y1.min(img.height.saturating_sub(m)),
    );
    let mut best: Option<([f32; 2], f32)> = None;
    for y in (y0..y1).step_by(step.max(1)) {
        for x in (x0..x1).step_by(step.max(1)) {
            let sc = shi_tomasi(img, x, y);
            if sc >= min_score && best.is_none_or(|(_, b)| sc > b) {
                best = Some(([x as f32, y as f32], sc));
            }
        }
    }
    best
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
                let Some((p, _)) = best_corner_in(&pa.levels[0], cell, 2, 2.0) else {
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
