//! k-nearest binding of Gaussians to lifted events (kiddo k-d tree).

use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use scene::Camera;

/// Bindings in CSR form: Gaussian `g` binds to `events[offsets[g]..offsets[g+1]]` with
/// the matching `weights` (normalised inverse distances, summing to 1 for every bound
/// Gaussian; an empty range means "bound to none").
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bindings {
    pub offsets: Vec<u32>,
    pub events: Vec<u64>,
    pub weights: Vec<f32>,
}

impl Bindings {
    /// Number of Gaussians (bound or not).
    pub fn gaussians(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }
    /// Number of Gaussians bound to at least one event.
    pub fn bound(&self) -> usize {
        self.offsets.windows(2).filter(|w| w[1] > w[0]).count()
    }
    /// The events and weights of Gaussian `g`.
    pub fn of(&self, g: usize) -> (&[u64], &[f32]) {
        let r = self.offsets[g] as usize..self.offsets[g + 1] as usize;
        (&self.events[r.clone()], &self.weights[r])
    }

    /// These bindings of some of `n` Gaussians (the `j`-th is Gaussian `ids[j]`, `ids`
    /// increasing) as bindings of all `n`, the others bound to none. The events keep
    /// their order, so only the offsets change.
    pub fn spread(self, ids: &[usize], n: usize) -> Bindings {
        assert_eq!(
            ids.len(),
            self.gaussians(),
            "spread: one id per Gaussian bound"
        );
        assert!(ids.windows(2).all(|w| w[0] < w[1]) && ids.last().is_none_or(|&i| i < n));
        let mut counts = vec![0u32; n];
        for (j, &i) in ids.iter().enumerate() {
            counts[i] = self.offsets[j + 1] - self.offsets[j];
        }
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0);
        for c in counts {
            offsets.push(offsets.last().copied().unwrap_or(0) + c);
        }
        Bindings { offsets, ..self }
    }
}

/// Per-Gaussian search radius in world units: `radius_px` pixels at the Gaussian's depth
/// (`radius_px · depth / fx`). Gaussians behind the camera get radius 0 (bind to none).
pub fn footprint_radii(camera: &Camera, centres: &[[f32; 3]], radius_px: f64) -> Vec<f32> {
    let fx = camera.intrinsics.fx;
    centres
        .par_iter()
        .map(|c| {
            let p = camera.cam_to_world.to_camera(glam::DVec3::new(
                c[0] as f64,
                c[1] as f64,
                c[2] as f64,
            ));
            let depth = -p.z;
            if depth > 0.0 {
                (radius_px * depth / fx) as f32
            } else {
                0.0
            }
        })
        .collect()
}

/// Weight floor on distances so an event exactly at a centre does not get infinite
/// weight (world units): weights are `w_i = (1/max(d_i, MIN_DISTANCE)) / Σ_j (…)`.
pub const MIN_DISTANCE: f32 = 1e-6;

/// Binds every centre to its `k` nearest `points` within its own `radii[g]`
/// (inclusive), weights ∝ 1/distance normalised to sum 1. `point_ids[i]` is what is
/// stored for point `i` (the event index). Which of several points at exactly the same
/// distance is kept is up to the tree (deterministic for the same input). Also returns the distance (world units)
/// of every binding, parallel to `Bindings::events`, for reports.
pub fn bind_nearest(
    points: &[[f32; 3]],
    point_ids: &[u64],
    centres: &[[f32; 3]],
    radii: &[f32],
    k: usize,
) -> (Bindings, Vec<f32>) {
    assert_eq!(points.len(), point_ids.len());
    assert_eq!(centres.len(), radii.len());
    let n = centres.len();
    let mut offsets = Vec::with_capacity(n + 1);
    offsets.push(0u32);
    let k_nz = match NonZeroUsize::new(k) {
        Some(k_nz) if !points.is_empty() => k_nz,
        _ => {
            // k = 0 or nothing to bind to: every Gaussian binds to none.
            offsets.resize(n + 1, 0);
            let none = Bindings {
                offsets,
                ..Default::default()
            };
            return (none, Vec::new());
        }
    };
    let tree: ImmutableKdTree<f32, 3> =
        ImmutableKdTree::new_from_slice(points).expect("finite points build a tree");
    // One query per Gaussian (radii differ), in parallel chunks; results kept in order.
    let per: Vec<Vec<(f32, u32)>> = centres
        .par_iter()
        .zip(radii.par_iter())
        .map(|(c, &r)| {
            if r.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
                || !c.iter().all(|v| v.is_finite())
            {
                return Vec::new();
            }
            let found = tree
                .query(c)
                .nearest_n::<SquaredEuclidean<f32>>(k_nz)
                .within(r * r)
                .execute();
            let mut v: Vec<(f32, u32)> = found.into_iter().map(|q| (q.distance, q.item)).collect();
            v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            v.truncate(k);
            v
        })
        .collect();
    let total: usize = per.iter().map(Vec::len).sum();
    let mut events = Vec::with_capacity(total);
    let mut weights = Vec::with_capacity(total);
    let mut distances = Vec::with_capacity(total);
    for list in &per {
        let inv: Vec<f32> = list
            .iter()
            .map(|&(d2, _)| 1.0 / d2.sqrt().max(MIN_DISTANCE))
            .collect();
        let sum: f32 = inv.iter().sum();
        for (&(d2, i), w) in list.iter().zip(&inv) {
            events.push(point_ids[i as usize]);
            weights.push(w / sum);
            distances.push(d2.sqrt());
        }
        offsets.push(events.len() as u32);
    }
    (
        Bindings {
            offsets,
            events,
            weights,
        },
        distances,
    )
}
