//! The prior on every blended depth (`tracks.depth_samples`, `raster::Anchor`) through
//! the warm-up's training step (its gradient against finite differences is in
//! `raster_grad.rs`): two layers on one ray whose blend lands on the prior's depth cost
//! `L_depth` nothing, so only this term brings them together.

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
/// start at their minimum): with the term the layers close to within a third of their
/// gap; without it they stay apart.
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
    let depth = |s: &Splats, i: usize| (DVec3::from(s.means[i].map(f64::from)) - eye).dot(forward);
    for weight in [0.0, 0.5] {
        let mut settings = fixed_gaussians(300);
        settings.position_lr_init = 0.01;
        settings.position_lr_final = 0.001;
        settings.tracks.depth_samples = weight;
        let mut t = Trainer::new(settings, s.clone(), 1.0);
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
        eprintln!("depth_samples {weight}: the layers {gap:.3} apart (1.2 at the start)");
        if weight > 0.0 {
            assert!(gap < 0.4, "the layers are still {gap:.3} apart");
        } else {
            assert!(gap > 1.0, "the layers closed to {gap:.3} without the term");
        }
    }
}
