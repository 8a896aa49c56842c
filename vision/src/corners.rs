//! Shi–Tomasi corners for the grid-spread feature detection (new features only where tracks
//! were lost): the best-scoring pixel of a grid cell.

use crate::pyramid::{Image, Pixel};

/// Shi–Tomasi score (mean minimum eigenvalue of the 5×5 structure tensor of central
/// differences) at an integer pixel. The caller keeps `(x, y)` at least 3 px inside the image.
#[inline]
pub fn shi_tomasi<T: Pixel>(img: &Image<T>, x: usize, y: usize) -> f32 {
    let w = img.width;
    let (mut a, mut b, mut c) = (0.0f32, 0.0f32, 0.0f32);
    for yy in y - 2..=y + 2 {
        let row = &img.data[yy * w..];
        let up = &img.data[(yy - 1) * w..];
        let dn = &img.data[(yy + 1) * w..];
        for xx in x - 2..=x + 2 {
            let gx = 0.5 * (row[xx + 1].value() - row[xx - 1].value());
            let gy = 0.5 * (dn[xx].value() - up[xx].value());
            a += gx * gx;
            b += gx * gy;
            c += gy * gy;
        }
    }
    min_eigen(a, b, c)
}

/// Mean minimum eigenvalue of the 5×5 structure tensor `[a b; b c]` (sums over 25 pixels).
#[inline]
fn min_eigen(a: f32, b: f32, c: f32) -> f32 {
    0.5 * (a + c - ((a - c) * (a - c) + 4.0 * b * b).sqrt()) / 25.0
}

/// Buffers of [`best_corner_with`] (reused across cells and frames).
#[derive(Debug, Default)]
pub struct CornerScratch {
    /// Gradient products over the cell's region, row-major.
    xx: Vec<f32>,
    xy: Vec<f32>,
    yy: Vec<f32>,
    /// Their 5-pixel horizontal sums at the candidate columns, per region row.
    hx: Vec<f32>,
    hxy: Vec<f32>,
    hy: Vec<f32>,
}

/// Best corner inside `[x0, x1) × [y0, y1)` sampled every `step` px; `None` below `min_score`.
/// (Allocates its buffers: the front end calls [`best_corner_with`].)
pub fn best_corner_in<T: Pixel>(
    img: &Image<T>,
    rect: (usize, usize, usize, usize),
    step: usize,
    min_score: f32,
) -> Option<([f32; 2], f32)> {
    best_corner_with(img, rect, step, min_score, &mut CornerScratch::default())
}

/// [`best_corner_in`] with reused buffers. The score of every candidate is [`shi_tomasi`]'s,
/// computed from the gradient products of the whole region, each product once, and separable
/// 5-pixel box sums (instead of 25 products per candidate and its overlapping neighbours).
pub fn best_corner_with<T: Pixel>(
    img: &Image<T>,
    (x0, x1, y0, y1): (usize, usize, usize, usize),
    step: usize,
    min_score: f32,
    s: &mut CornerScratch,
) -> Option<([f32; 2], f32)> {
    let m = 4;
    let step = step.max(1);
    let (x0, y0) = (x0.max(m), y0.max(m));
    let (x1, y1) = (
        x1.min(img.width.saturating_sub(m)),
        y1.min(img.height.saturating_sub(m)),
    );
    if x1 <= x0 || y1 <= y0 {
        return None;
    }
    // candidates x0 + i·step < x1; their windows cover [x0 − 2, last + 2]
    let (nx, ny) = ((x1 - x0).div_ceil(step), (y1 - y0).div_ceil(step));
    let (rx, ry) = (x0 - 2, y0 - 2);
    let (rw, rh) = ((nx - 1) * step + 5, (ny - 1) * step + 5);
    gradient_products(img, (rx, ry, rw, rh), s);
    // horizontal 5-sums at the candidate columns
    for v in [&mut s.hx, &mut s.hxy, &mut s.hy] {
        v.clear();
        v.resize(rh * nx, 0.0);
    }
    for r in 0..rh {
        for i in 0..nx {
            let k = r * rw + i * step;
            s.hx[r * nx + i] = s.xx[k..k + 5].iter().sum();
            s.hxy[r * nx + i] = s.xy[k..k + 5].iter().sum();
            s.hy[r * nx + i] = s.yy[k..k + 5].iter().sum();
        }
    }
    let mut best: Option<([f32; 2], f32)> = None;
    for j in 0..ny {
        for i in 0..nx {
            let col = |h: &[f32]| (0..5).map(|d| h[(j * step + d) * nx + i]).sum::<f32>();
            let sc = min_eigen(col(&s.hx), col(&s.hxy), col(&s.hy));
            if sc >= min_score && best.is_none_or(|(_, b)| sc > b) {
                best = Some(([(x0 + i * step) as f32, (y0 + j * step) as f32], sc));
            }
        }
    }
    best
}

/// Central-difference gradient products `gx², gx·gy, gy²` over the region
/// `[rx, rx + rw) × [ry, ry + rh)` (which keeps one pixel from the image border).
fn gradient_products<T: Pixel>(
    img: &Image<T>,
    (rx, ry, rw, rh): (usize, usize, usize, usize),
    s: &mut CornerScratch,
) {
    let w = img.width;
    for v in [&mut s.xx, &mut s.xy, &mut s.yy] {
        v.clear();
        v.resize(rw * rh, 0.0);
    }
    for r in 0..rh {
        let y = ry + r;
        let mid = &img.data[y * w + rx - 1..][..rw + 2];
        let up = &img.data[(y - 1) * w + rx..][..rw];
        let dn = &img.data[(y + 1) * w + rx..][..rw];
        let o = r * rw;
        for x in 0..rw {
            let gx = 0.5 * (mid[x + 2].value() - mid[x].value());
            let gy = 0.5 * (dn[x].value() - up[x].value());
            s.xx[o + x] = gx * gx;
            s.xy[o + x] = gx * gy;
            s.yy[o + x] = gy * gy;
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::pyramid::Pyramid;
    use crate::synthetic::{Texture, render_affine};

    /// The box-sum scores are the per-candidate scores (up to rounding), so the same corner wins.
    #[test]
    fn box_sums_match_direct_scores() {
        let (w, h) = (160, 120);
        let luma = render_affine(&Texture::new(5), w, h, [[1.0, 0.0], [0.0, 1.0]], [0.0, 0.0]);
        let mut p = Pyramid::default();
        p.build(&luma, w, h, 2);
        let mut s = CornerScratch::default();
        for (img_w, step) in [(160, 2), (80, 1), (80, 3)] {
            for cy in 0..3 {
                for cx in 0..4 {
                    let c = img_w / 4;
                    let rect = (cx * c, cx * c + c, cy * c, cy * c + c);
                    let (got, want) = if img_w == 160 {
                        let got = best_corner_with(&p.base, rect, step, 0.0, &mut s);
                        (got, direct(&p.base, rect, step))
                    } else {
                        let got = best_corner_with(&p.coarse[0], rect, step, 0.0, &mut s);
                        (got, direct(&p.coarse[0], rect, step))
                    };
                    let (got, want) = (got.unwrap(), want.unwrap());
                    assert!((got.1 - want.1).abs() <= 1e-4 * want.1, "{got:?} {want:?}");
                    // ties within rounding may pick a different pixel of equal score
                    assert!(
                        got.0 == want.0
                            || (shi_tomasi_at(&p, img_w, got.0) - want.1).abs() <= 1e-4 * want.1
                    );
                }
            }
        }
    }

    fn shi_tomasi_at(p: &Pyramid, img_w: usize, q: [f32; 2]) -> f32 {
        let (x, y) = (q[0] as usize, q[1] as usize);
        if img_w == 160 {
            shi_tomasi(&p.base, x, y)
        } else {
            shi_tomasi(&p.coarse[0], x, y)
        }
    }

    /// The original candidate-by-candidate search.
    fn direct<T: Pixel>(
        img: &Image<T>,
        (x0, x1, y0, y1): (usize, usize, usize, usize),
        step: usize,
    ) -> Option<([f32; 2], f32)> {
        let m = 4;
        let (x0, y0) = (x0.max(m), y0.max(m));
        let (x1, y1) = (x1.min(img.width - m), y1.min(img.height - m));
        let mut best: Option<([f32; 2], f32)> = None;
        for y in (y0..y1).step_by(step) {
            for x in (x0..x1).step_by(step) {
                let sc = shi_tomasi(img, x, y);
                if best.is_none_or(|(_, b)| sc > b) {
                    best = Some(([x as f32, y as f32], sc));
                }
            }
        }
        best
    }
}
