//! The shape term (`tracks.rigidity`, `gaussians::tracks::rigid`) through the warm-up's
//! training step (its gradient against finite differences is in the module's tests).

use gaussians::Splats;
use gaussians::raster::TileRasterizer;
use gaussians::train::init::random_splats;
use gaussians::train::{TrainSettings, Trainer, View};
use glam::DVec3;

mod train_common;
use train_common::{H, W, cameras, fixed_gaussians};

/// The shape term (`tracks.rigidity`) through the training step: two faint tracked
/// Gaussians (no photometric pull to speak of) whose trajectories scale their distance
/// about the origin over time, as a copy of an object drifting along the rays would,
/// end up at one distance at every time; without the term they keep breathing.
#[test]
fn the_shape_term_holds_tracked_gaussians_at_one_distance_over_time() {
    let cams = cameras(5);
    let views: Vec<View> = (cams.iter().enumerate())
        .map(|(k, c)| View {
            camera: *c,
            time: k as f32 / 4.0,
            rgb: vec![0.0; 3 * W * H],
        })
        .collect();
    let at = |s: &Splats, i: usize, t: f32| {
        let d = gaussians::motion::shift(s, i, t);
        DVec3::from(std::array::from_fn(|k| f64::from(s.means[i][k] + d[k])))
    };
    let dist = |s: &Splats, t: f32| (at(s, 0, t) - at(s, 1, t)).length();
    for weight in [0.0, 1.0] {
        let mut s = random_splats(2, DVec3::ZERO, 0.1, 3);
        s.opacity_logits = vec![-12.0; 2];
        s.means = vec![[0.1, 0.0, 0.0], [0.3, 0.05, 0.0]];
        // x(τ) = (1 + τ)·x: v = x, the distance 0.5× at t = 0 and 1.5× at t = 1.
        s.motion = (s.means.iter())
            .map(|m| [m[0], m[1], m[2], 0.0, 0.0, 0.0])
            .collect();
        let mut settings = TrainSettings {
            position_lr_init: 0.01,
            position_lr_final: 0.001,
            ..fixed_gaussians(400)
        };
        settings.tracks.rigidity = weight;
        let mut t = Trainer::new(settings, s.clone(), 1.0);
        let before = (dist(&t.splats, 1.0) - dist(&t.splats, 0.0)) / dist(&t.splats, 0.5);
        for _ in 0..400 {
            t.step(&TileRasterizer, &views);
        }
        let after = (dist(&t.splats, 1.0) - dist(&t.splats, 0.0)).abs() / dist(&t.splats, 0.5);
        assert!(
            (before - 1.0).abs() < 1e-5,
            "the start breathes by {before}"
        );
        if weight > 0.0 {
            assert!(after < 0.05, "still breathing by {after} of its size");
            assert!(t.tracks.last_shape >= 0.0);
        } else {
            assert!(after > 0.9, "breathing fell to {after} without the term");
        }
    }
}
