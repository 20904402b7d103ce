//! `gaussians::trajectory` against the analytic world of a synthetic scene: Gaussians
//! placed on the moving objects' surfaces (and some behind them, and some on still
//! objects) by casting rays in the world itself; a model without a field moves none of
//! them, so its error is the objects' whole true motion.

use gaussians::model::{Model, ModelInfo};
use gaussians::trajectory::trajectory_error;
use glam::{DVec2, DVec3};

#[test]
fn a_still_model_misses_all_of_the_true_motion() {
    let mut cfg = synth::SynthConfig::preset("rigid").unwrap();
    cfg.width = 32;
    cfg.height = 32;
    cfg.duration = 0.5;
    cfg.train_fps = 4.0;
    cfg.test_frames = 2;
    let d = tempfile::tempdir().unwrap();
    let dir = d.path().join("scene");
    synth::write_synthetic_scene(&cfg, &dir).unwrap();
    let scene = scene::manifest::Scene::open(&dir).unwrap();
    let world = synth::SynthWorld::new(&cfg).unwrap();
    let t0 = scene.train.frames[0].timestamp;
    let eye = world.camera_at(t0).cam_to_world.centre();
    let mut splats = gaussians::Splats::default();
    let push = |s: &mut gaussians::Splats, p: DVec3| {
        s.means.push(p.as_vec3().to_array());
        s.log_scales.push([-4.0; 3]);
        s.rotations.push([1.0, 0.0, 0.0, 0.0]);
        s.opacity_logits.push(4.0);
        s.sh_dc.push([0.0; 3]);
        s.sh_rest.push([0.0; 45]);
    };
    // (material point, object, world point at t₀) of each Gaussian on a moving surface
    let mut on = Vec::new();
    let mut off = 0usize;
    for y in 0..32 {
        for x in 0..32 {
            let px = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
            let Some(hit) = world.cast(t0, px) else {
                continue;
            };
            if !cfg.objects[hit.object].moves() {
                push(&mut splats, hit.world); // a still object: not counted
                continue;
            }
            push(&mut splats, hit.world);
            on.push((hit.local, hit.object, hit.world));
            if (x + y) % 3 == 0 {
                // The same pixel at 1.5 × the depth: seen on the object, off its surface.
                push(&mut splats, eye + 1.5 * (hit.world - eye));
                off += 1;
            }
        }
    }
    assert!(on.len() > 10 && off > 3, "{} on, {off} off", on.len());
    let model = Model {
        info: ModelInfo {
            gaussians: splats.len(),
            sh_degree: 0,
            ..ModelInfo::default()
        },
        splats,
        field: None,
    };
    let t = trajectory_error(&model, &scene).expect("a synthetic scene with moving objects");
    assert_eq!(t.gaussians, on.len());
    assert_eq!(t.times, scene.test.frames.len());
    let frac = on.len() as f64 / (on.len() + off) as f64;
    assert!(
        (t.on_surface_fraction - frac).abs() < 1e-12,
        "{t:?} vs {frac}"
    );
    assert_eq!((t.model_motion_mean, t.seen_motion_mean), (0.0, 0.0));
    // The true motion, from the world directly.
    let mut sum = 0.0;
    for f in &scene.test.frames {
        for &(local, object, start) in &on {
            sum += (world.material_to_world(object, local, f.timestamp) - start).length();
        }
    }
    let truth = sum / (on.len() * scene.test.frames.len()) as f64;
    assert!(truth > 0.01, "the objects move: {truth}");
    assert!(
        (t.true_motion_mean - truth).abs() < 1e-6 * truth,
        "{t:?} vs {truth}"
    );
    assert!((t.motion_error_mean - truth).abs() < 1e-6 * truth);
    assert!((t.relative_error - 1.0).abs() < 1e-6);

    // With lives: the Gaussians on moving surfaces at odd rows live only until the
    // middle of the first and second test times; at the second test time only the
    // others count.
    let times: Vec<f64> = scene.test.frames.iter().map(|f| f.time).collect();
    let cut = (0.5 * (times[0] + times[1])) as f32;
    let mut lived = model;
    let n = lived.splats.len();
    lived.splats.motion = Vec::new();
    lived.splats.life = vec![gaussians::splats::ALWAYS; n];
    // Each `on` Gaussian's index: the order in which they were pushed.
    let mut short = std::collections::HashSet::new();
    let (mut g, mut k) = (0usize, 0usize);
    for y in 0..32 {
        for x in 0..32 {
            let px = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
            let Some(hit) = world.cast(t0, px) else {
                continue;
            };
            let moving = cfg.objects[hit.object].moves();
            if moving && y % 2 == 1 {
                lived.splats.life[g] = [f32::MIN, cut];
                short.insert(k);
            }
            g += 1 + usize::from(moving && (x + y) % 3 == 0);
            k += usize::from(moving);
        }
    }
    assert_eq!(g, n);
    let t2 = trajectory_error(&lived, &scene).unwrap();
    let (mut sum, mut count) = (0.0, 0usize);
    for (j, f) in scene.test.frames.iter().enumerate() {
        for (k, &(local, object, start)) in on.iter().enumerate() {
            if j == 1 && short.contains(&k) {
                continue;
            }
            sum += (world.material_to_world(object, local, f.timestamp) - start).length();
            count += 1;
        }
    }
    assert!(!short.is_empty() && count < 2 * on.len());
    let want = sum / count as f64;
    assert!(
        (t2.true_motion_mean - want).abs() < 1e-6 * want,
        "{t2:?} vs {want}"
    );
}
