//! Bound Gaussians whose events' flow disagrees with their neighbours' (issue #18,
//! item 3): a Gaussian's mean event flow is compared with the median of the mean flows
//! of the other bound Gaussians within `radius_px` of it in the image; it is dropped
//! from `L_motion` when it lies farther from that median than `tolerance_px` over the
//! span *and* than three robust deviations (1.4826·MAD) of the neighbours around it.
//! Fewer than `min_neighbours` neighbours: kept (nothing to compare with). Apparent
//! motion is smooth over most of the image, so one Gaussian bound to events of another
//! object (or to events with a wrong flow) stands out from the Gaussians around it;
//! a region whose flow genuinely varies has a large spread and keeps its Gaussians.

use serde::{Deserialize, Serialize};

/// Settings of the neighbour check (serde, every field optional in files).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NeighbourSettings {
    /// Neighbourhood radius in the image, px; 0 turns the check off.
    pub radius_px: f64,
    /// Fewest neighbours a comparison needs.
    pub min_neighbours: usize,
    /// Smallest disagreement (px over the motion span) that can drop a Gaussian.
    pub tolerance_px: f64,
}

impl Default for NeighbourSettings {
    fn default() -> Self {
        NeighbourSettings {
            radius_px: 4.0,
            min_neighbours: 4,
            tolerance_px: 2.0,
        }
    }
}

fn median(v: &mut [f32]) -> f32 {
    let m = v.len() / 2;
    *v.select_nth_unstable_by(m, f32::total_cmp).1
}

/// For each Gaussian (pixel `px`, mean flow over the span `flow` in px, `None` without
/// one), whether it disagrees with its neighbours (module docs). Cost: a grid of
/// `radius_px` cells, each Gaussian compared with the 3×3 cells around it.
pub(crate) fn disagreeing(
    px: &[[f32; 2]],
    flow: &[Option<[f32; 2]>],
    s: &NeighbourSettings,
) -> Vec<bool> {
    assert_eq!(px.len(), flow.len(), "disagreeing: one flow per Gaussian");
    let mut out = vec![false; px.len()];
    let r = s.radius_px as f32;
    if !(r > 0.0 && r.is_finite()) {
        return out;
    }
    let cell = |p: [f32; 2]| ((p[0] / r).floor() as i64, (p[1] / r).floor() as i64);
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> = Default::default();
    for (i, (p, f)) in px.iter().zip(flow).enumerate() {
        if f.is_some() && p[0].is_finite() && p[1].is_finite() {
            grid.entry(cell(*p)).or_default().push(i);
        }
    }
    // Scratch buffers reused for every Gaussian (this runs at every motion step).
    let (mut near, mut nu, mut nv, mut dev) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (i, (p, f)) in px.iter().zip(flow).enumerate() {
        let Some(f) = *f else { continue };
        if !(p[0].is_finite() && p[1].is_finite()) {
            continue;
        }
        let (cx, cy) = cell(*p);
        near.clear();
        for (dx, dy) in (-1..=1).flat_map(|a| (-1..=1).map(move |b| (a, b))) {
            for &j in grid.get(&(cx + dx, cy + dy)).into_iter().flatten() {
                let q = px[j];
                let d2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
                if j != i && d2 <= r * r {
                    let g: [f32; 2] = flow[j].expect("gridded Gaussians have a flow");
                    near.push(g);
                }
            }
        }
        if near.len() < s.min_neighbours.max(1) {
            continue;
        }
        nu.clear();
        nv.clear();
        nu.extend(near.iter().map(|g| g[0]));
        nv.extend(near.iter().map(|g| g[1]));
        let m = [median(&mut nu), median(&mut nv)];
        dev.clear();
        dev.extend(near.iter().map(|g| (g[0] - m[0]).hypot(g[1] - m[1])));
        let spread = 3.0 * 1.4826 * median(&mut dev);
        let d = (f[0] - m[0]).hypot(f[1] - m[1]);
        out[i] = d > (s.tolerance_px as f32).max(spread);
    }
    out
}
