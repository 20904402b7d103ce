//! Flow evaluation (issue 4 item 8, `docs/DESIGN.md` §5 "Metrics"): end-point error and
//! outliers against ground truth where it exists, the flow-warp loss always, and the
//! shared real ECD slice (`shared/data/ecd_shapes_rotation/`) as a scored test case.
//!
//! **Units.** [`flow_metrics`] compares flows in the same unit; the 3 px outlier
//! threshold assumes *pixel displacement over the window* (the network's unit, the
//! Middlebury `.flo` unit and the unit of the ECD `flow.npy`). Per-event flows in px/s
//! are multiplied by the window length first ([`scale`]).
//! [`flow_warp_loss`] takes the flow in px/s and event times in seconds (as
//! [`crate::cm`]); with times normalised to `[0, 1]` over the window it takes px per
//! window.

use crate::cm::{CmConfig, CmEvents, cm_loss, event_pixel, iwe, variance};
use crate::net::{FlowNet, tensor4, to_f64};
use glam::DVec2;
use scene::error::{Error, IoContext, Result};
use scene::events::EventStream;
use scene::{Distortion, Intrinsics};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// Outlier threshold of [`flow_metrics`], px.
pub(crate) const OUTLIER_PX: f64 = 3.0;

/// End-point error statistics of a flow against ground truth.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FlowMetrics {
    /// Mean end-point error `|pred − gt|₂` over the valid entries.
    pub epe: f64,
    /// Percentage (0–100) of valid entries with end-point error > [`OUTLIER_PX`].
    pub outliers_pct: f64,
    /// Mean magnitude of the ground truth over the same entries (EPE of zero flow).
    pub gt_magnitude: f64,
    /// Number of entries scored.
    pub count: usize,
}

/// EPE and % outliers of `pred` against `gt` (u and v columns of equal length: dense
/// pixels, row-major, or one entry per event). An entry counts when `mask` (if given)
/// is true and the ground truth is finite; a non-finite prediction there scores as an
/// outlier with infinite error, so `epe` becomes infinite (never silently dropped).
/// With nothing to score, all figures are 0 and `count` is 0.
pub fn flow_metrics(
    pred: (&[f64], &[f64]),
    gt: (&[f64], &[f64]),
    mask: Option<&[bool]>,
) -> std::result::Result<FlowMetrics, String> {
    let n = gt.0.len();
    if gt.1.len() != n || pred.0.len() != n || pred.1.len() != n {
        return Err(format!(
            "flow sizes differ: pred {}+{}, gt {}+{}",
            pred.0.len(),
            pred.1.len(),
            gt.0.len(),
            gt.1.len()
        ));
    }
    if let Some(m) = mask
        && m.len() != n
    {
        return Err(format!("mask has {} entries, flow has {n}", m.len()));
    }
    let (mut sum, mut mag, mut out, mut count) = (0.0, 0.0, 0usize, 0usize);
    for i in 0..n {
        if mask.is_some_and(|m| !m[i]) || !(gt.0[i].is_finite() && gt.1[i].is_finite()) {
            continue;
        }
        let e = (pred.0[i] - gt.0[i]).hypot(pred.1[i] - gt.1[i]);
        let e = if e.is_nan() { f64::INFINITY } else { e };
        sum += e;
        mag += gt.0[i].hypot(gt.1[i]);
        out += usize::from(e > OUTLIER_PX);
        count += 1;
    }
    if count == 0 {
        return Ok(FlowMetrics::default());
    }
    let c = count as f64;
    Ok(FlowMetrics {
        epe: sum / c,
        outliers_pct: 100.0 * out as f64 / c,
        gt_magnitude: mag / c,
        count,
    })
}

/// `values · factor` (e.g. px/s × window length → px per window).
pub fn scale(values: &[f64], factor: f64) -> Vec<f64> {
    values.iter().map(|v| v * factor).collect()
}

/// A dense flow `(u, v)` (row-major `w·h`) sampled at the nearest pixel of each event.
pub(crate) fn sample_at_events(
    u: &[f64],
    v: &[f64],
    (w, h): (usize, usize),
    ev: &CmEvents,
) -> (Vec<f64>, Vec<f64>) {
    (0..ev.len())
        .map(|k| {
            let p = event_pixel(ev.x[k], ev.y[k], w, h);
            (u[p], v[p])
        })
        .unzip()
}

/// Pixels that received at least one event (nearest pixel, inside the sensor).
pub(crate) fn event_mask(ev: &CmEvents, (w, h): (usize, usize)) -> Vec<bool> {
    let mut m = vec![false; w * h];
    for k in 0..ev.len() {
        let (x, y) = (ev.x[k].round(), ev.y[k].round());
        if x >= 0.0 && y >= 0.0 && (x as usize) < w && (y as usize) < h {
            m[y as usize * w + x as usize] = true;
        }
    }
    m
}

/// Flow-warp loss (Stoffregen et al.): variance of the image of events warped to
/// `t_ref` with the flow, divided by the variance without warping. Above 1 = the flow
/// sharpens the events.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FlowWarpLoss {
    pub var_warped: f64,
    pub var_unwarped: f64,
    /// `var_warped / var_unwarped` (0 when there are no events).
    pub ratio: f64,
}

/// [`FlowWarpLoss`] of a dense flow (px/s, row-major `w·h`) at reference time `t_ref`.
pub fn flow_warp_loss(
    ev: &CmEvents,
    u: &[f64],
    v: &[f64],
    (w, h): (usize, usize),
    t_ref: f64,
) -> FlowWarpLoss {
    let zero = vec![0.0; w * h];
    let var_unwarped = variance(&iwe(ev, &zero, &zero, t_ref, w, h));
    let var_warped = variance(&iwe(ev, u, v, t_ref, w, h));
    let ratio = if var_unwarped > 0.0 {
        var_warped / var_unwarped
    } else {
        0.0
    };
    FlowWarpLoss {
        var_warped,
        var_unwarped,
        ratio,
    }
}

/// Value of the CM loss ([`crate::cm::cm_loss`], lower = sharper) of a dense flow in
/// px/s over the window `(t_a, t_b)`.
pub fn cm_objective(
    ev: &CmEvents,
    u: &[f64],
    v: &[f64],
    size: (usize, usize),
    window: (f64, f64),
    cfg: &CmConfig,
) -> f64 {
    cm_loss(ev, u, v, size, window, cfg).loss
}

/// A real event slice with dense ground-truth flow: the layout of
/// `shared/data/ecd_shapes_rotation/` (`events.txt`, `calib.txt`, `flow.npy`).
#[derive(Clone, Debug)]
pub struct EcdSlice {
    pub width: usize,
    pub height: usize,
    /// Camera with the distortion of `calib.txt`.
    pub intrinsics: Intrinsics,
    /// The raw events (distorted sensor grid).
    pub events: EventStream,
    /// Undistorted positions (ideal grid of the same K), times in seconds.
    pub cm: CmEvents,
    /// First and last event time: the window of the ground truth.
    pub t_a: f64,
    pub t_b: f64,
    /// Ground-truth displacement over `[t_a, t_b]` (px), row-major `width·height`.
    pub gt_u: Vec<f64>,
    pub gt_v: Vec<f64>,
}

/// Read an ECD `calib.txt` with all nine numbers `fx fy cx cy k1 k2 p1 p2 k3`.
fn read_calib9(path: &Path, (w, h): (usize, usize)) -> Result<Intrinsics> {
    let text = std::fs::read_to_string(path).at(path)?;
    let vals = text
        .split_whitespace()
        .map(|s| {
            s.parse::<f64>()
                .map_err(|_| Error::invalid(path, format!("'{s}' is not a number")))
        })
        .collect::<Result<Vec<f64>>>()?;
    if vals.len() != 9 || vals.iter().any(|v| !v.is_finite()) || vals[0] <= 0.0 || vals[1] <= 0.0 {
        return Err(Error::invalid(
            path,
            format!(
                "expected 9 finite numbers fx fy cx cy k1 k2 p1 p2 k3 (fx, fy > 0), got {}",
                vals.len()
            ),
        ));
    }
    Ok(Intrinsics {
        width: w as u32,
        height: h as u32,
        fx: vals[0],
        fy: vals[1],
        cx: vals[2],
        cy: vals[3],
        distortion: Some(Distortion {
            k1: vals[4],
            k2: vals[5],
            p1: vals[6],
            p2: vals[7],
            k3: vals[8],
        }),
    })
}

/// Read a `1×2×H×W` float64 (or float32) `.npy` flow: `(w, h, u, v)`.
pub fn read_flow_npy(path: &Path) -> Result<(usize, usize, Vec<f64>, Vec<f64>)> {
    let bytes = std::fs::read(path).at(path)?;
    let npy = npyz::NpyFile::new(&bytes[..])
        .map_err(|e| Error::invalid(path, format!("not a .npy file: {e}")))?;
    let shape = npy.shape().to_vec();
    let (h, w) = match shape.as_slice() {
        [1, 2, h, w] | [2, h, w] => (*h as usize, *w as usize),
        _ => {
            return Err(Error::invalid(
                path,
                format!("shape {shape:?}, expected 1×2×H×W"),
            ));
        }
    };
    if w == 0 || h == 0 || w > 1 << 15 || h > 1 << 15 {
        return Err(Error::invalid(
            path,
            format!("flow size {w}×{h} is empty or too large"),
        ));
    }
    let is_f32 = format!("{:?}", npy.dtype()).contains("f4");
    let flat: Vec<f64> = if is_f32 {
        let v: Vec<f32> = npy
            .into_vec()
            .map_err(|e| Error::invalid(path, format!("bad data: {e}")))?;
        v.into_iter().map(f64::from).collect()
    } else {
        npy.into_vec().map_err(|e| {
            Error::invalid(path, format!("bad data (float64 or float32 expected): {e}"))
        })?
    };
    if flat.len() != 2 * w * h {
        return Err(Error::invalid(
            path,
            format!("{} values, expected {}", flat.len(), 2 * w * h),
        ));
    }
    if flat.iter().any(|x| !x.is_finite()) {
        return Err(Error::invalid(path, "flow has non-finite values"));
    }
    let v = flat[w * h..].to_vec();
    let mut u = flat;
    u.truncate(w * h);
    Ok((w, h, u, v))
}

impl EcdSlice {
    /// Read the slice in `dir` (see the type doc); the sensor size comes from `flow.npy`.
    pub fn read(dir: &Path) -> Result<EcdSlice> {
        let (width, height, gt_u, gt_v) = read_flow_npy(&dir.join("flow.npy"))?;
        let intrinsics = read_calib9(&dir.join("calib.txt"), (width, height))?;
        let events_path = dir.join("events.txt");
        let opts = scene::ReadOptions {
            sensor: Some((width as u32, height as u32)),
            coord_scale: None,
        };
        let events = scene::read_events(&events_path, &opts)?;
        let (t_a, t_b) = match (events.t.first(), events.t.last()) {
            (Some(&a), Some(&b)) if b > a => (a, b),
            _ => {
                return Err(Error::invalid(
                    &events_path,
                    "needs at least two distinct event times",
                ));
            }
        };
        let mut cm = CmEvents::default();
        for i in 0..events.len() {
            let p = intrinsics.undistort_pixel(DVec2::new(events.x[i] as f64, events.y[i] as f64));
            cm.x.push(p.x);
            cm.y.push(p.y);
            cm.t.push(events.t[i]);
        }
        Ok(EcdSlice {
            width,
            height,
            intrinsics,
            events,
            cm,
            t_a,
            t_b,
            gt_u,
            gt_v,
        })
    }

    pub fn duration(&self) -> f64 {
        self.t_b - self.t_a
    }

    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Normalised voxel grid (`bins × H × W`) of the undistorted events (rounded to the
    /// nearest pixel; those falling outside the sensor do not vote).
    pub fn voxel(&self, bins: usize) -> Vec<f32> {
        let (w, h) = (self.width as u32, self.height as u32);
        let mut ev = EventStream::with_capacity(w, h, self.cm.len());
        for k in 0..self.cm.len() {
            let (x, y) = (self.cm.x[k].round(), self.cm.y[k].round());
            if x >= 0.0 && y >= 0.0 && (x as u32) < w && (y as u32) < h {
                ev.push(self.cm.t[k], x as u16, y as u16, self.events.p[k]);
            }
        }
        crate::voxel::voxel_grid(&ev.as_slice(), self.t_a, self.t_b, bins, w, h)
    }

    /// Score a dense displacement (px over the slice, row-major) against `flow.npy`:
    /// at pixels with events (the usual protocol), per event, and the flow-warp loss.
    pub fn score(&self, u: &[f64], v: &[f64]) -> Result<EcdScore> {
        let size = self.size();
        let mask = event_mask(&self.cm, size);
        let bad = |e: String| Error::Other(format!("ECD score: {e}"));
        let masked = flow_metrics((u, v), (&self.gt_u, &self.gt_v), Some(&mask)).map_err(bad)?;
        let dense = flow_metrics((u, v), (&self.gt_u, &self.gt_v), None).map_err(bad)?;
        let (pu, pv) = sample_at_events(u, v, size, &self.cm);
        let (gu, gv) = sample_at_events(&self.gt_u, &self.gt_v, size, &self.cm);
        let per_event = flow_metrics((&pu, &pv), (&gu, &gv), None).map_err(bad)?;
        let inv = 1.0 / self.duration();
        let fwl = flow_warp_loss(
            &self.cm,
            &scale(u, inv),
            &scale(v, inv),
            size,
            0.5 * (self.t_a + self.t_b),
        );
        Ok(EcdScore {
            masked,
            dense,
            per_event,
            flow_warp: fwl,
            forward_s: 0.0,
        })
    }

    /// Run `net` (inference device) on the whole slice and score its flow.
    pub fn score_net(&self, net: &FlowNet) -> Result<EcdScore> {
        let bins = net.config.bins;
        let start = Instant::now();
        let x = tensor4(
            self.voxel(bins),
            [1, bins, self.height, self.width],
            &net.device,
            net.dtype,
        );
        let flow = to_f64(net.forward(x));
        let forward_s = start.elapsed().as_secs_f64();
        let n = self.width * self.height;
        let mut s = self.score(&flow[..n], &flow[n..])?;
        s.forward_s = forward_s;
        Ok(s)
    }
}

/// Scores of a flow on an [`EcdSlice`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EcdScore {
    /// At pixels with at least one event (the usual protocol).
    pub masked: FlowMetrics,
    /// Over every pixel.
    pub dense: FlowMetrics,
    /// One entry per event (flow at its undistorted pixel).
    pub per_event: FlowMetrics,
    /// Flow-warp loss at the slice centre.
    pub flow_warp: FlowWarpLoss,
    /// Wall time of the network's forward pass, seconds (0 when not from a network).
    pub forward_s: f64,
}
