//! Which pixels of a novel view some train view saw (the co-visibility mask of the
//! masked PSNR of "Monocular Dynamic View Synthesis: A Reality Check", Gao et al.,
//! NeurIPS 2022), from the analytic world: the surface point a novel pixel shows at
//! time `t` is a material point of its object; it was seen when, at some train time,
//! that material point (where the object's motion has taken it) projects inside the
//! train camera's image and is the first surface there. A pixel that hits no surface
//! shows the constant background, which every view sees.

use crate::world::SynthWorld;
use glam::DVec2;
use rayon::prelude::*;

/// Per pixel (row-major) of the novel view at `t`: whether a train view at one of
/// `train_times` saw it. The train views nearest in time are tried first.
pub fn novel_covisible(world: &SynthWorld, t: f64, train_times: &[f64]) -> Vec<bool> {
    let cfg = world.config();
    let (w, h) = (cfg.width as usize, cfg.height as usize);
    let mut order: Vec<f64> = train_times.to_vec();
    order.sort_by(|a, b| (a - t).abs().total_cmp(&(b - t).abs()));
    let cameras: Vec<_> = order.iter().map(|&s| (s, world.camera_at(s))).collect();
    let mut out = vec![false; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, seen) in row.iter_mut().enumerate() {
            let Some(hit) = world.cast_novel(t, DVec2::new(x as f64, y as f64)) else {
                *seen = true;
                continue;
            };
            *seen = cameras.iter().any(|(s, cam)| {
                let p = world.material_to_world(hit.object, hit.local, *s);
                let Some((px, depth)) = cam.project_world(p) else {
                    return false;
                };
                if !cam.intrinsics.contains(px) || depth <= 0.0 {
                    return false;
                }
                world.cast(*s, px).is_some_and(|first| {
                    first.object == hit.object
                        && (first.world - p).length() <= 1e-6 * depth.max(1.0)
                })
            });
        }
    });
    out
}
