//! The event term on part of the image: one of `k × k` equal tiles of the sensor,
//! picked at random each step, rendered by a camera cropped to it (the same rays as
//! the whole camera's pixels there) and compared with the same window of the pseudo
//! image. Every pixel is in exactly one tile, so over the steps each is compared as
//! often as any other; a step costs the rasterizer `1/k²` of the pixels.

use crate::event_image::PseudoImage;
use scene::{Camera, real::Real};

/// A window of the sensor: columns `x0..x0 + width`, rows `y0..y0 + height`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    pub x0: usize,
    pub y0: usize,
    pub width: usize,
    pub height: usize,
}

impl Crop {
    /// Tile `index` (row-major, `0..k²`) of a `width × height` sensor cut into `k × k`
    /// tiles; the cuts fall at `⌊i·width/k⌋`, so the tiles cover every pixel once.
    pub fn tile(width: usize, height: usize, k: usize, index: usize) -> Crop {
        let k = k.max(1);
        let (i, j) = (index % k, (index / k) % k);
        let cut = |n: usize, m: usize| m * n / k;
        Crop {
            x0: cut(width, i),
            y0: cut(height, j),
            width: cut(width, i + 1) - cut(width, i),
            height: cut(height, j + 1) - cut(height, j),
        }
    }

    /// The camera of this window: same pose and focal lengths, the principal point
    /// moved by the window's corner (pixel `(x, y)` of the crop is pixel
    /// `(x0 + x, y0 + y)` of `camera`).
    pub fn camera(&self, camera: &Camera) -> Camera {
        let mut c = *camera;
        c.intrinsics.width = self.width as u32;
        c.intrinsics.height = self.height as u32;
        c.intrinsics.cx -= self.x0 as f64;
        c.intrinsics.cy -= self.y0 as f64;
        c
    }

    /// This window of each plane of `full` into `out` (its buffers reused).
    pub fn pseudo<R: Real>(&self, full: &PseudoImage<R>, out: &mut PseudoImage<R>) {
        let (w, plane) = (full.width, full.width * full.height);
        assert!(
            self.x0 + self.width <= w && self.y0 + self.height <= full.height,
            "crop outside the pseudo image"
        );
        out.begin_like(full, self.width, self.height);
        for c in 0..full.channels {
            for y in self.y0..self.y0 + self.height {
                let a = c * plane + y * w + self.x0;
                let b = a + self.width;
                out.data.extend_from_slice(&full.data[a..b]);
                out.valid.extend_from_slice(&full.valid[a..b]);
                out.n_eff.extend_from_slice(&full.n_eff[a..b]);
            }
        }
    }
}
