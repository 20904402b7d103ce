//! The prior on every blended depth (`tracks.depth_samples`, `raster::Anchor`) through
//! the warm-up's training step (its gradient against finite differences is in
//! `raster_grad.rs`): two layers on one ray whose blend lands on the prior's depth cost
//! `L_depth` nothing, so only this term brings them together. It acts on the moving
//! Gaussians only (a part's members, those with a trajectory).

use gaussians::raster::TileRasterizer;
use gaussians::tracks::depth::Aligned;
use gaussians::tracks::prior_loss::PriorTerm;
use gaussians::train::{Trainer, View};
use gaussians::{Gaussian, Splats};
use glam::DVec3;

mod train_common;
use train_common::{H, W, cameras, fixed_gaussians};

/// A front and a back layer of one colour on the view's central ray, 1.2 apart, the
/// image and the prior both rendered from them (so the photometric loss and `L_depth`
/// start at their minimum): with the term, and the layers moving (a trajectory each), they
/// close to within a third of their gap; without the term, or still, they stay apart.
#[test]
fn the_prior_on_every_depth_brings_two_layers_together() {
    let cam = cameras(1)[0];
    let eye = cam.cam_to_world.translation;
    let forward = (DVec3::ZERO - eye).normalize();
    let at = |d: f64| (eye + forward * d).as_vec3().to_array();
    let layer = |d: f64, logit: f32| Gaussian {
        dynamic: false,
        ..Gaussian::isotropic(at(d), 0.25f32.ln(), logit, [0.8, 0.2, -0.4])
    };
    let mut s = Splats::with_capacity(2);
    s.push(layer(3.0, 0.0)); // opacity ½
    s.push(layer(4.2, 2.0));
    let (image, _) = TileRasterizer.render_full(&s, &cam, 0, [0.0; 3]);
    let prior: Vec<f32> = (image.depth.iter().zip(&image.alpha))
        .map(|(d, a)| if *a > 0.05 { d / a } else { 0.0 })
        .collect();
    let view = View {
        camera: cam,
        time: 0.0,
        rgb: image.rgb.clone(),
    };
    // Where the view (time 0) sees Gaussian i: its centre moved along its trajectory.
    let depth = |s: &Splats, i: usize| {
        let d = gaussians::motion::shift(s, i, 0.0);
        let x = DVec3::from(std::array::from_fn(|k| f64::from(s.means[i][k] + d[k])));
        (x - eye).dot(forward)
    };
    for (weight, moving) in [(0.0, true), (0.5, true), (0.5, false)] {
        let mut settings = fixed_gaussians(300);
        settings.position_lr_init = 0.01;
        settings.position_lr_final = 0.001;
        settings.tracks.depth_samples = weight;
        let mut s = s.clone();
        if moving {
            // A trajectory too slow to matter: v = 10⁻⁶ along x.
            s.motion = vec![[1e-6, 0.0, 0.0, 0.0, 0.0, 0.0]; 2];
        }
        let mut t = Trainer::new(settings, s, 1.0);
        t.tracks.priors = PriorTerm::new(vec![Some(Aligned {
            width: W,
            height: H,
            z: prior.clone(),
            median_rel_error: 0.0,
            points: 0,
        })]);
        for _ in 0..300 {
            t.step(&TileRasterizer, std::slice::from_ref(&view));
        }
        let gap = depth(&t.splats, 1) - depth(&t.splats, 0);
        eprintln!("depth_samples {weight}, moving {moving}: {gap:.3} apart (1.2 at the start)");
        if weight > 0.0 && moving {
            assert!(gap < 0.4, "the layers are still {gap:.3} apart");
        } else {
            assert!(gap > 1.0, "the layers closed to {gap:.3} without the term");
        }
    }
}
