//! The image of warped events (IWE): each event k is warped to a reference time with the
//! flow of its own pixel, `x'_k = x_k − (t_k − t_ref)·v(x_k)` (flow in px/s), and
//! splatted bilinearly (paper Eq. 4–5). Plain Rust, f64.

/// Events prepared for contrast maximisation: sub-pixel positions (e.g. undistorted),
/// times in seconds. Struct of arrays.
#[derive(Clone, Debug, Default)]
pub struct CmEvents {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub t: Vec<f64>,
}

impl CmEvents {
    pub fn len(&self) -> usize {
        self.t.len()
    }
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
}

/// Pixel whose flow an event uses (nearest pixel, clamped to the sensor).
#[inline]
pub fn event_pixel(x: f64, y: f64, width: usize, height: usize) -> usize {
    let xi = (x.round().max(0.0) as usize).min(width - 1);
    let yi = (y.round().max(0.0) as usize).min(height - 1);
    yi * width + xi
}

/// Bilinear splat of the events warped to `t_ref` (unit weight per event).
// Eq. 4 (warp) and Eq. 5 (IWE)
pub fn iwe(ev: &CmEvents, u: &[f64], v: &[f64], t_ref: f64, w: usize, h: usize) -> Vec<f64> {
    let mut img = vec![0.0; w * h];
    if w == 0 || h == 0 {
        return img;
    }
    for k in 0..ev.len() {
        let p = event_pixel(ev.x[k], ev.y[k], w, h);
        let dt = ev.t[k] - t_ref;
        let wx = ev.x[k] - dt * u[p];
        let wy = ev.y[k] - dt * v[p];
        splat(&mut img, w, h, wx, wy);
    }
    img
}

#[inline]
pub(super) fn corners(wx: f64, wy: f64) -> (i64, i64, f64, f64) {
    let x0 = wx.floor();
    let y0 = wy.floor();
    (x0 as i64, y0 as i64, wx - x0, wy - y0)
}

#[inline]
fn splat(img: &mut [f64], w: usize, h: usize, wx: f64, wy: f64) {
    if !wx.is_finite() || !wy.is_finite() {
        return;
    }
    let (x0, y0, fx, fy) = corners(wx, wy);
    for (dx, dy, wt) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (1, 0, fx * (1.0 - fy)),
        (0, 1, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        let (xx, yy) = (x0 + dx, y0 + dy);
        if xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h {
            img[yy as usize * w + xx as usize] += wt;
        }
    }
}

/// Value of the image at integer (x, y), 0 outside.
#[inline]
pub(super) fn at(img: &[f64], w: usize, h: usize, x: i64, y: i64) -> f64 {
    if x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h {
        img[y as usize * w + x as usize]
    } else {
        0.0
    }
}

/// Variance of an image (the classic CM objective; used by `eval` as flow-warp loss).
pub fn variance(img: &[f64]) -> f64 {
    if img.is_empty() {
        return 0.0;
    }
    let n = img.len() as f64;
    let mean = img.iter().sum::<f64>() / n;
    img.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n
}
