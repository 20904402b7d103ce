//! Lifting events to 3D through a rendered depth map.

use glam::DVec2;
use scene::{Camera, EventSlice};

/// Events lifted to world space; `event_index` indexes the source stream.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LiftedEvents {
    pub points: Vec<[f32; 3]>,
    pub event_index: Vec<u64>,
    /// Events dropped because their pixel had alpha below the threshold or no depth.
    pub dropped_no_depth: usize,
    /// Events dropped because they fall outside the image after undistortion.
    pub dropped_outside: usize,
}

/// Lifts every event of `events` through `depth` (camera-space depth, row-major
/// `width × height`, 0 where nothing was rendered) and `alpha`, with the camera at the
/// frame time. Event coordinates are undistorted first when the camera has distortion
/// (the depth map lives on the ideal pinhole grid); the depth is read at the nearest
/// pixel, so a lifted point lies on the rendered surface.
///
/// `depth` and `alpha` must have `width × height` entries (checked by the caller, see
/// [`crate::bind`] users); panics otherwise.
pub fn lift_events(
    camera: &Camera,
    depth: &[f32],
    alpha: &[f32],
    min_alpha: f32,
    events: &EventSlice<'_>,
) -> LiftedEvents {
    let k = &camera.intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    assert_eq!(depth.len(), w * h, "depth map size");
    assert_eq!(alpha.len(), w * h, "alpha map size");
    let distorted = k.distortion.is_some_and(|d| !d.is_zero());
    let mut out = LiftedEvents {
        points: Vec::with_capacity(events.len()),
        event_index: Vec::with_capacity(events.len()),
        ..Default::default()
    };
    for i in 0..events.len() {
        let raw = DVec2::new(events.x[i] as f64, events.y[i] as f64);
        let px = if distorted {
            k.undistort_pixel(raw)
        } else {
            raw
        };
        let (u, v) = (px.x.round(), px.y.round());
        if !(u >= 0.0 && v >= 0.0 && u < w as f64 && v < h as f64) {
            out.dropped_outside += 1;
            continue;
        }
        let at = v as usize * w + u as usize;
        let d = depth[at];
        if !(alpha[at] >= min_alpha && d > 0.0 && d.is_finite()) {
            out.dropped_no_depth += 1;
            continue;
        }
        let p = camera.unproject_world(px, d as f64);
        out.points.push([p.x as f32, p.y as f32, p.z as f32]);
        out.event_index.push((events.offset + i) as u64);
    }
    out
}
