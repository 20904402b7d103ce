//! Pretraining data: the randomised synthetic scenes, their simulated events and
//! ground-truth flow, and training samples (voxel grid + target flow) cut from them.

use super::PretrainSettings;
use crate::cm::CmEvents;
use crate::synthesize::simulate_scene;
use glam::DVec3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scene::error::{Error, Result};
use scene::events::EventStream;
use scene::synth::gt::NOISE_ID;
use scene::synth::{Pattern, SynthConfig, SynthWorld};

/// The synthetic world of `(preset, seed)`: the preset at `resolution`², randomised by
/// `seed` (see the module doc). Different seeds give different textures.
pub fn scene_config(preset: &str, seed: u64, s: &PretrainSettings) -> Result<SynthConfig> {
    let mut cfg = SynthConfig::preset(preset)
        .ok_or_else(|| Error::Other(format!("unknown synthetic preset '{preset}'")))?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ 0x5eed);
    cfg.width = s.resolution;
    cfg.height = s.resolution;
    cfg.duration = s.scene_duration;
    cfg.render_rate_hz = s.render_rate_hz;
    cfg.supersample = 1;
    cfg.seed = seed;
    cfg.contrast_threshold = rng.random_range(0.1..0.25);
    cfg.threshold_sigma = rng.random_range(0.0..0.03);
    cfg.shot_noise_hz = rng.random_range(0.0..0.3);
    cfg.fov_x_deg = rng.random_range(45.0..75.0);
    let g = rng.random_range(0.05..0.5);
    cfg.background = [g, g, g];
    let speed = rng.random_range(s.speed_min..=s.speed_max);
    let cam = &mut cfg.camera;
    cam.eye += DVec3::new(
        rng.random_range(-0.5..0.5),
        rng.random_range(-0.2..0.3),
        rng.random_range(-0.4..0.4),
    );
    cam.target += DVec3::new(
        rng.random_range(-0.3..0.3),
        rng.random_range(-0.1..0.1),
        0.0,
    );
    cam.sway *= rng.random_range(0.3..1.5);
    cam.yaw_deg = rng.random_range(0.0..10.0);
    cam.pitch_deg = rng.random_range(0.0..5.0);
    cam.sway_hz *= speed;
    cam.turn_hz *= speed;
    let patterns = [Pattern::Checker, Pattern::Stripes, Pattern::Blobs];
    for (k, o) in cfg.objects.iter_mut().enumerate() {
        let t = &mut o.texture;
        t.pattern = patterns[rng.random_range(0..3)];
        t.cell *= rng.random_range(0.5..1.8);
        let bright: f64 = rng.random_range(0.5..0.95);
        let dark: f64 = rng.random_range(0.02..0.3);
        t.colour_a = [0; 3].map(|_| (bright * rng.random_range(0.6..1.0)).min(1.0));
        t.colour_b = [0; 3].map(|_| dark * rng.random_range(0.5..1.0));
        t.detail = rng.random_range(0.0..0.3);
        t.seed = rng.random();
        let m = &mut o.motion;
        if k >= 2 {
            // The props (not the floor and wall): placement, spin axis, direction.
            m.position += DVec3::new(
                rng.random_range(-0.2..0.2),
                rng.random_range(-0.1..0.1),
                rng.random_range(-0.2..0.2),
            );
            let axis = DVec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            if axis.length() > 0.1 {
                m.spin_axis = axis;
            }
            let sign = if rng.random_bool(0.5) { -1.0 } else { 1.0 };
            m.spin_deg_per_s *= sign * rng.random_range(0.5..1.5);
            m.velocity *= sign;
        }
        m.velocity *= speed;
        m.oscillation_hz *= speed;
        m.spin_deg_per_s *= speed;
        o.deform.hz *= speed;
        o.deform.wave_hz *= speed;
    }
    cfg.validate()
        .map_err(|e| Error::Other(format!("synthetic scene {preset}/{seed}: {e}")))?;
    Ok(cfg)
}

/// Events of one synthetic scene with the ground-truth flow (px/s) of each event;
/// `noise[i]` marks noise events (no valid flow).
pub struct SceneData {
    pub name: String,
    pub events: EventStream,
    pub u: Vec<f32>,
    pub v: Vec<f32>,
    pub noise: Vec<bool>,
    pub duration: f64,
}

/// Simulate the scene of `(preset, seed)`.
pub fn make_scene(preset: &str, seed: u64, s: &PretrainSettings) -> Result<SceneData> {
    let cfg = scene_config(preset, seed, s)?;
    let world = SynthWorld::new(&cfg)
        .map_err(|e| Error::Other(format!("synthetic scene {preset}/{seed}: {e}")))?;
    let (events, gt) = simulate_scene(&world)?;
    let n = events.len();
    let (mut u, mut v, mut noise) = (vec![0f32; n], vec![0f32; n], vec![true; n]);
    for k in 0..gt.len() {
        let i = gt.index[k] as usize;
        if i < n {
            u[i] = gt.u[k];
            v[i] = gt.v[k];
            noise[i] = gt.object[k] == NOISE_ID;
        }
    }
    Ok(SceneData {
        name: format!("{preset}/{seed}"),
        events,
        u,
        v,
        noise,
        duration: cfg.duration,
    })
}

/// One training or evaluation window: input voxel grid, target displacement (px per
/// window; u then v, row-major) and the mask of pixels with non-noise events.
pub struct Sample {
    pub voxel: Vec<f32>,
    pub target: Vec<f32>,
    pub mask: Vec<f32>,
    /// The window's non-noise events, times normalised to `[0, 1]` (for CM / flow-warp).
    pub cm: CmEvents,
}

/// The sample of window `[t_a, t_b]` of `d`, flipped as asked.
pub fn sample(d: &SceneData, (t_a, t_b): (f64, f64), bins: usize, flip: (bool, bool)) -> Sample {
    let (w, h) = (d.events.width as usize, d.events.height as usize);
    let range = d.events.window_range(t_a, t_b);
    let len = t_b - t_a;
    let slice = d.events.as_slice().sub(range.clone());
    let mut voxel = crate::voxel::voxel_grid(&slice, t_a, t_b, bins, w as u32, h as u32);
    let mut sum = vec![0f64; 2 * w * h];
    let mut count = vec![0u32; w * h];
    let mut cm = CmEvents::default();
    for i in range {
        if d.noise[i] {
            continue;
        }
        let (x, y) = (d.events.x[i] as usize, d.events.y[i] as usize);
        let p = y * w + x;
        sum[p] += d.u[i] as f64 * len;
        sum[w * h + p] += d.v[i] as f64 * len;
        count[p] += 1;
        cm.x.push(x as f64);
        cm.y.push(y as f64);
        cm.t.push((d.events.t[i] - t_a) / len);
    }
    let mut target = vec![0f32; 2 * w * h];
    let mut mask = vec![0f32; w * h];
    for p in 0..w * h {
        if count[p] > 0 {
            target[p] = (sum[p] / count[p] as f64) as f32;
            target[w * h + p] = (sum[w * h + p] / count[p] as f64) as f32;
            mask[p] = 1.0;
        }
    }
    let (fx, fy) = flip;
    if fx || fy {
        let map = |x: usize, y: usize| {
            let xs = if fx { w - 1 - x } else { x };
            let ys = if fy { h - 1 - y } else { y };
            ys * w + xs
        };
        let remap = |plane: &[f32], sign: f32| -> Vec<f32> {
            let mut out = vec![0f32; w * h];
            for y in 0..h {
                for x in 0..w {
                    out[y * w + x] = sign * plane[map(x, y)];
                }
            }
            out
        };
        voxel = voxel.chunks(w * h).flat_map(|c| remap(c, 1.0)).collect();
        let su = if fx { -1.0 } else { 1.0 };
        let sv = if fy { -1.0 } else { 1.0 };
        let mut t = remap(&target[..w * h], su);
        t.extend(remap(&target[w * h..], sv));
        target = t;
        mask = remap(&mask, 1.0);
        for k in 0..cm.len() {
            if fx {
                cm.x[k] = (w - 1) as f64 - cm.x[k];
            }
            if fy {
                cm.y[k] = (h - 1) as f64 - cm.y[k];
            }
        }
    }
    Sample {
        voxel,
        target,
        mask,
        cm,
    }
}

/// Build the training and held-out scenes.
pub fn make_scenes(s: &PretrainSettings) -> Result<(Vec<SceneData>, Vec<SceneData>)> {
    let mut train = Vec::new();
    for p in &s.presets {
        for &seed in &s.train_seeds {
            train.push(make_scene(p, seed, s)?);
        }
    }
    let mut held = Vec::new();
    for p in &s.eval_presets {
        for &seed in &s.eval_seeds {
            held.push(make_scene(p, seed, s)?);
        }
    }
    Ok((train, held))
}
