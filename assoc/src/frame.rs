//! One frame's association, checked: the entry point `deform` calls every 500
//! iterations and the `assoc` stage calls once per train frame.

use serde::Serialize;

use crate::{AssocSettings, Bindings, bind_nearest, footprint_radii, lift_events};
use scene::{Camera, EventSlice};
use stagekit::Settings;

/// Per-frame figures for `report.json`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FrameStats {
    /// Frame time t0 (seconds, event clock).
    pub t0: f64,
    /// Events with |t − t0| ≤ δt.
    pub events_in_window: usize,
    /// Events lifted to 3D (the k-d tree's points).
    pub events_used: usize,
    /// Events on pixels with alpha below the threshold or without depth.
    pub events_dropped_no_depth: usize,
    /// Events outside the image after undistortion.
    pub events_dropped_outside: usize,
    pub gaussians: usize,
    pub gaussians_bound: usize,
    /// Distances of all bindings, in pixel footprints at the Gaussian's depth
    /// (distance · fx / depth): the same scale at every distance.
    pub distance_px_median: f64,
    pub distance_px_p90: f64,
    pub distance_px_max: f64,
}

/// What is wrong with the inputs of [`associate_frame`].
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FrameError {
    #[error("depth map has {got} values but the camera is {w}x{h}")]
    DepthSize { got: usize, w: u32, h: u32 },
    #[error("alpha map has {got} values but the camera is {w}x{h}")]
    AlphaSize { got: usize, w: u32, h: u32 },
    #[error("event {index} at ({x}, {y}) lies outside the {w}x{h} sensor")]
    EventOutside {
        index: usize,
        x: u16,
        y: u16,
        w: u32,
        h: u32,
    },
    #[error("the model has no Gaussians")]
    NoGaussians,
    #[error("invalid settings: {0}")]
    Settings(String),
}

/// Associates the events of `window` (already cut to |t − t0| ≤ δt) with Gaussians
/// whose centres are `centres` (deformed to t0), through `depth`/`alpha` rendered at
/// t0 with `camera` (row-major, camera size; depth is camera-space, alpha-normalised).
/// Returns the CSR bindings and the frame's figures.
pub fn associate_frame(
    camera: &Camera,
    depth: &[f32],
    alpha: &[f32],
    window: &EventSlice<'_>,
    centres: &[[f32; 3]],
    t0: f64,
    settings: &AssocSettings,
) -> Result<(Bindings, FrameStats), FrameError> {
    settings.validate().map_err(FrameError::Settings)?;
    let (w, h) = (camera.intrinsics.width, camera.intrinsics.height);
    let pixels = w as usize * h as usize;
    if depth.len() != pixels {
        return Err(FrameError::DepthSize {
            got: depth.len(),
            w,
            h,
        });
    }
    if alpha.len() != pixels {
        return Err(FrameError::AlphaSize {
            got: alpha.len(),
            w,
            h,
        });
    }
    if centres.is_empty() {
        return Err(FrameError::NoGaussians);
    }
    if let Some(i) = (0..window.len()).find(|&i| window.x[i] as u32 >= w || window.y[i] as u32 >= h)
    {
        return Err(FrameError::EventOutside {
            index: window.offset + i,
            x: window.x[i],
            y: window.y[i],
            w,
            h,
        });
    }
    let lifted = lift_events(camera, depth, alpha, settings.min_alpha, window);
    let radii = footprint_radii(camera, centres, settings.radius_px);
    let (bindings, distances) = bind_nearest(
        &lifted.points,
        &lifted.event_index,
        centres,
        &radii,
        settings.k,
    );
    // Distance in pixel footprints: radius_px · d / r_g is the distance over the
    // world size of one pixel at the Gaussian's depth.
    let mut px: Vec<f64> = Vec::with_capacity(distances.len());
    for (g, &radius) in radii.iter().enumerate().take(bindings.gaussians()) {
        let r = bindings.offsets[g] as usize..bindings.offsets[g + 1] as usize;
        for &d in &distances[r] {
            px.push(d as f64 * settings.radius_px / radius as f64);
        }
    }
    px.sort_by(f64::total_cmp);
    let quantile = |q: f64| {
        if px.is_empty() {
            0.0
        } else {
            px[((px.len() - 1) as f64 * q).round() as usize]
        }
    };
    let stats = FrameStats {
        t0,
        events_in_window: window.len(),
        events_used: lifted.points.len(),
        events_dropped_no_depth: lifted.dropped_no_depth,
        events_dropped_outside: lifted.dropped_outside,
        gaussians: centres.len(),
        gaussians_bound: bindings.bound(),
        distance_px_median: quantile(0.5),
        distance_px_p90: quantile(0.9),
        distance_px_max: px.last().copied().unwrap_or(0.0),
    };
    Ok((bindings, stats))
}

/// [`associate_frame`] over the Gaussians alive at normalised time `t` only (`life`:
/// one `[from, to)` per Gaussian, empty = all alive, `Splats::life`): a Gaussian outside
/// its life is not drawn then, so no event binds to it (its extrapolated trajectory
/// would take the events of whatever it passes over). The bindings cover every centre,
/// the others with empty ranges.
#[allow(clippy::too_many_arguments)]
pub fn associate_alive(
    camera: &Camera,
    depth: &[f32],
    alpha: &[f32],
    window: &EventSlice<'_>,
    centres: &[[f32; 3]],
    life: &[[f32; 2]],
    (t, t0): (f32, f64),
    settings: &AssocSettings,
) -> Result<(Bindings, FrameStats), FrameError> {
    let alive: Vec<usize> = (0..centres.len())
        .filter(|&g| life.get(g).is_none_or(|l| gaussians::motion::alive(*l, t)))
        .collect();
    let some: Vec<[f32; 3]> = alive.iter().map(|&g| centres[g]).collect();
    let (b, stats) = associate_frame(camera, depth, alpha, window, &some, t0, settings)?;
    Ok((b.spread(&alive, centres.len()), stats))
}
