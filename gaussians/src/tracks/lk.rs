//! Pyramidal Lucas–Kanade (Bouguet's formulation): the displacement of a small window
//! between two grey images, coarse to fine, Gauss–Newton on the window's brightness
//! constancy at each level.

use glam::Vec2;

/// One grey image, row-major, pixel centres at `(x + ½, y + ½)`.
pub struct Grey {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl Grey {
    /// Luma (Rec. 601 weights) of a planar RGB image (all red, then green, then blue,
    /// as the train views hold it).
    pub(crate) fn from_planar(rgb: &[f32], width: usize, height: usize) -> Grey {
        let n = width * height;
        let data = (0..n)
            .map(|p| 0.299 * rgb[p] + 0.587 * rgb[n + p] + 0.114 * rgb[2 * n + p])
            .collect();
        Grey {
            width,
            height,
            data,
        }
    }

    /// Bilinear sample at continuous pixel coordinates (clamped to the border).
    pub fn at(&self, x: f32, y: f32) -> f32 {
        let x = (x - 0.5).clamp(0.0, (self.width - 1) as f32);
        let y = (y - 0.5).clamp(0.0, (self.height - 1) as f32);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let g = |a: usize, b: usize| self.data[b * self.width + a];
        (1.0 - fy) * ((1.0 - fx) * g(x0, y0) + fx * g(x1, y0))
            + fy * ((1.0 - fx) * g(x0, y1) + fx * g(x1, y1))
    }

    /// Half resolution by 2×2 box averaging.
    fn half(&self) -> Grey {
        let (w, h) = ((self.width / 2).max(1), (self.height / 2).max(1));
        let s = |x: usize, y: usize| {
            self.data[y.min(self.height - 1) * self.width + x.min(self.width - 1)]
        };
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = (2 * (i % w), 2 * (i / w));
                0.25 * (s(x, y) + s(x + 1, y) + s(x, y + 1) + s(x + 1, y + 1))
            })
            .collect();
        Grey {
            width: w,
            height: h,
            data,
        }
    }
}

/// A grey image and its halvings, finest first.
pub struct Pyramid(pub Vec<Grey>);

impl Pyramid {
    pub fn new(base: Grey, levels: usize) -> Pyramid {
        let mut v = vec![base];
        while v.len() < levels.max(1) && v.last().is_some_and(|g| g.width >= 16 && g.height >= 16) {
            let next = v.last().map(Grey::half).expect("non-empty");
            v.push(next);
        }
        Pyramid(v)
    }
}

/// Where the window around `p` in `a` lies in `b`; `None` when the window has no
/// texture in two directions (its structure tensor's smaller eigenvalue per pixel is
/// below `min_eig`), so the displacement is not defined.
pub fn track(a: &Pyramid, b: &Pyramid, p: Vec2, radius: i32, min_eig: f32) -> Option<Vec2> {
    track_from(a, b, p, Vec2::ZERO, radius, min_eig)
}

/// [`track`] started at the displacement `guess` (pixels of the finest level) instead of
/// none.
pub fn track_from(
    a: &Pyramid,
    b: &Pyramid,
    p: Vec2,
    guess: Vec2,
    radius: i32,
    min_eig: f32,
) -> Option<Vec2> {
    let n = ((2 * radius + 1) * (2 * radius + 1)) as f32;
    let top = a.0.len().min(b.0.len()).max(1) - 1;
    let mut d = guess / (1 << top) as f32;
    for l in (0..a.0.len().min(b.0.len())).rev() {
        let (ga, gb) = (&a.0[l], &b.0[l]);
        let c = p / (1 << l) as f32;
        // Window gradients (central differences) and the structure tensor.
        let mut grads = [(0.0f32, 0.0f32, 0.0f32); 33 * 33];
        let (mut gxx, mut gxy, mut gyy) = (0.0, 0.0, 0.0);
        let mut m = 0;
        for j in -radius..=radius {
            for i in -radius..=radius {
                let (x, y) = (c.x + i as f32, c.y + j as f32);
                let ix = 0.5 * (ga.at(x + 1.0, y) - ga.at(x - 1.0, y));
                let iy = 0.5 * (ga.at(x, y + 1.0) - ga.at(x, y - 1.0));
                grads[m] = (ix, iy, ga.at(x, y));
                m += 1;
                gxx += ix * ix;
                gxy += ix * iy;
                gyy += iy * iy;
            }
        }
        let min_e = 0.5 * (gxx + gyy - ((gxx - gyy).powi(2) + 4.0 * gxy * gxy).sqrt()) / n;
        let det = gxx * gyy - gxy * gxy;
        if l == 0 && min_e < min_eig {
            return None;
        }
        if det.abs() > 1e-12 {
            for _ in 0..20 {
                let (mut bx, mut by) = (0.0, 0.0);
                let mut m = 0;
                for j in -radius..=radius {
                    for i in -radius..=radius {
                        let (ix, iy, va) = grads[m];
                        m += 1;
                        let it = gb.at(c.x + i as f32 + d.x, c.y + j as f32 + d.y) - va;
                        bx -= ix * it;
                        by -= iy * it;
                    }
                }
                let step = Vec2::new(gyy * bx - gxy * by, gxx * by - gxy * bx) / det;
                d += step;
                if step.length_squared() < 1e-4 {
                    break;
                }
            }
        }
        if l > 0 {
            d *= 2.0;
        }
    }
    d.is_finite().then_some(p + d)
}
