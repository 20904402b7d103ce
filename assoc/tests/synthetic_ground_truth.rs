//! Association on a synthetic scene with ground truth (issue: assoc "Must show"):
//! Gaussians are placed on the true surfaces at a frame time t0 (each knows its object),
//! their depth is rendered by our rasterizer, the simulator's events around t0 are lifted
//! through that depth and bound. Lifted events must lie on the true surfaces (median
//! distance below one pixel footprint) and ≥ 95 % of bindings must tie an event to a
//! Gaussian on the object that caused it.

use assoc::{AssocSettings, associate_frame, lift_events};
use gaussians::raster::TileRasterizer;
use gaussians::{Gaussian, Splats};
use glam::{DVec2, DVec3};
use synth::gt::NOISE_ID;
use synth::{Hit, SynthConfig, SynthWorld};

/// Gaussians on a 2-px grid of the surfaces seen at `t0`, with their object ids.
fn surface_gaussians(world: &SynthWorld, t0: f64) -> (Splats, Vec<u16>) {
    let cfg = world.config();
    let fx = world.intrinsics().fx;
    let mut s = Splats::default();
    let mut ids = Vec::new();
    for v in (0..cfg.height).step_by(2) {
        for u in (0..cfg.width).step_by(2) {
            let Some(hit) = world.cast(t0, DVec2::new(u as f64, v as f64)) else {
                continue;
            };
            let p = hit.world;
            let mean = [p.x as f32, p.y as f32, p.z as f32];
            // σ ≈ 1 px at the hit's depth: neighbours (2 px apart) overlap smoothly.
            let sigma = (1.0 * hit.depth / fx).ln() as f32;
            s.push(Gaussian::isotropic(mean, sigma, 3.0, [0.5; 3]));
            ids.push(hit.object as u16 + 1);
        }
    }
    (s, ids)
}

/// Distance from `q` to the true surface through pixel `px` at `t0`: along the
/// local normal (from two neighbouring rays on the same object), or to the hit point
/// where the neighbourhood crosses an object border.
fn surface_distance(world: &SynthWorld, t0: f64, px: DVec2, hit: &Hit, q: DVec3) -> f64 {
    let a = world.cast(t0, px + DVec2::new(0.25, 0.0));
    let b = world.cast(t0, px + DVec2::new(0.0, 0.25));
    match (a, b) {
        (Some(a), Some(b)) if a.object == hit.object && b.object == hit.object => {
            let n = (a.world - hit.world).cross(b.world - hit.world);
            if n.length() > 0.0 {
                return (q - hit.world).dot(n.normalize()).abs();
            }
            q.distance(hit.world)
        }
        _ => q.distance(hit.world),
    }
}

#[test]
fn lifted_events_lie_on_true_surfaces_and_bind_to_their_own_object() {
    let mut cfg = SynthConfig::preset("rigid").unwrap();
    cfg.width = 96;
    cfg.height = 96;
    cfg.duration = 0.5;
    cfg.render_rate_hz = 500.0;
    cfg.supersample = 1;
    let world = SynthWorld::new(&cfg).unwrap();
    let (events, gt) = synth::simulate_scene(&world).unwrap();
    assert_eq!(gt.len(), events.len());
    let t0 = cfg.train_times()[2];
    let camera = world.camera_at(t0);
    let fx = camera.intrinsics.fx;

    let (splats, ids) = surface_gaussians(&world, t0);
    let (frame, _) = TileRasterizer::new().render_full(&splats, &camera, 0, [0.0; 3]);
    let depth: Vec<f32> = frame
        .depth
        .iter()
        .zip(&frame.alpha)
        .map(|(&d, &a)| if a > 0.0 { d / a } else { 0.0 })
        .collect();

    let settings = AssocSettings::default();
    let window = events.window(t0 - settings.delta_t, t0 + settings.delta_t);
    assert!(window.len() > 1000, "too few events: {}", window.len());

    // (a) lifted points against the true surface at t0, in pixel footprints.
    let lifted = lift_events(&camera, &depth, &frame.alpha, settings.min_alpha, &window);
    assert!(lifted.points.len() > window.len() / 2);
    let mut err_px: Vec<f64> = Vec::new();
    for (p, &e) in lifted.points.iter().zip(&lifted.event_index) {
        let e = e as usize;
        let px = DVec2::new(events.x[e] as f64, events.y[e] as f64);
        let Some(hit) = world.cast(t0, px) else {
            continue;
        };
        let q = glam::DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
        err_px.push(surface_distance(&world, t0, px, &hit, q) * fx / hit.depth);
    }
    err_px.sort_by(f64::total_cmp);
    let median = err_px[err_px.len() / 2];
    assert!(
        median < 1.0,
        "median distance to the true surface {median:.3} px"
    );

    // (b) bindings tie events to Gaussians of the same object.
    let (bindings, stats) = associate_frame(
        &camera,
        &depth,
        &frame.alpha,
        &window,
        &splats.means,
        t0,
        &settings,
    )
    .unwrap();
    assert!(stats.gaussians_bound > 100, "{stats:?}");
    let (mut same, mut total) = (0usize, 0usize);
    for (g, &id) in ids.iter().enumerate().take(bindings.gaussians()) {
        let (evs, w) = bindings.of(g);
        let sum: f32 = w.iter().sum();
        assert!(evs.is_empty() || (sum - 1.0).abs() < 1e-5);
        for &e in evs {
            let object = gt.object[e as usize];
            if object == NOISE_ID {
                continue;
            }
            total += 1;
            same += usize::from(object == id);
        }
    }
    let fraction = same as f64 / total as f64;
    eprintln!(
        "events {} lifted {} median {median:.3} px, bindings {total}, same object {:.2}%",
        window.len(),
        lifted.points.len(),
        100.0 * fraction
    );
    assert!(
        fraction >= 0.95,
        "same-object bindings {:.2}%",
        100.0 * fraction
    );
}
