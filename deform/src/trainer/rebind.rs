//! Rebinding during the joint training (§3.3): events bound anew to the Gaussians as
//! they are now, by the `assoc` library with the settings' association parameters.

use super::JointTrainer;
use crate::inputs::Inputs;
use gaussians::{Rasterizer, TileRasterizer};
use std::time::Instant;

impl JointTrainer {
    /// Bind events to the current Gaussians at every train frame (§3.3, the `assoc`
    /// library with the settings' association parameters).
    pub fn rebind(&mut self, r: &TileRasterizer, d: &Inputs) {
        let clock = Instant::now();
        let s = &self.settings.assoc;
        let mut out = Vec::with_capacity(d.views.len());
        for (i, v) in d.views.iter().enumerate() {
            let (splats, _) = self.inner.deformed(v.time);
            let (image, _) = r.render(
                &splats,
                &v.camera,
                self.inner.sh_degree(),
                self.inner.settings.background,
            );
            let depth = image.normalised_depth();
            let alpha: Vec<f32> = depth.iter().map(|&z| f32::from(z > 0.0)).collect();
            let t0 = d.times[i];
            let window = d.events.window(t0 - s.delta_t, (t0 + s.delta_t).next_up());
            // Events at hot pixels or in bursts are not bound (their indices mapped back).
            let kept = d.rate_outliers.kept_events(&window);
            let events = kept.as_ref().map_or(window, |(k, _)| k.as_slice());
            let life = &self.inner.splats.life;
            let b = assoc::associate_alive(
                &v.camera,
                &depth,
                &alpha,
                &events,
                &splats.means,
                life,
                (v.time, t0),
                s,
            )
            .map(|(mut b, _)| {
                if let Some((_, index)) = &kept {
                    b.events.iter_mut().for_each(|e| *e = index[*e as usize]);
                }
                b
            })
            .unwrap_or_else(|e| match e {
                // Every Gaussian outside its life at this frame: nothing to bind, counted.
                assoc::FrameError::NoGaussians => {
                    self.fallbacks.rebind_frames_unbound += 1;
                    assoc::Bindings {
                        offsets: vec![0; splats.len() + 1],
                        ..Default::default()
                    }
                }
                // The trainer renders at the camera's size with validated settings and
                // events checked against the sensor when read: a bug, not a recording's.
                e => panic!("rebinding train frame {i} (t0 = {t0} s): {e}"),
            });
            out.push(b);
        }
        self.bindings = out;
        self.rebinds += 1;
        self.timings.rebind += clock.elapsed().as_secs_f64();
    }
}
