//! Pretraining data: the randomised synthetic scenes, their simulated events and
//! ground-truth flow, and training samples (voxel grid + target flow) cut from them.

use super::settings::PretrainSettings;
use crate::cm::CmEvents;
use glam::DVec3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scene::error::{Error, Result};
use scene::events::EventStream;
use stagekit::Settings;
use synth::gt::NOISE_ID;
use synth::{Pattern, SynthConfig, SynthWorld, simulate_scene};

/// The synthetic world of `(preset, seed)`: the preset at `size`², randomised by `seed`
/// (see the module doc). Different seeds give different textures; the world does not
/// depend on `size` (only its sampling does).
pub fn scene_config(
    preset: &str,
    seed: u64,
    size: u32,
    s: &PretrainSettings,
) -> Result<SynthConfig> {
    let mut cfg = SynthConfig::preset(preset)
        .ok_or_else(|| Error::Other(format!("unknown synthetic preset '{preset}'")))?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ 0x5eed);
    cfg.width = size;
    cfg.height = size;
    cfg.duration = s.scene_duration;
    cfg.render_rate_hz = s.render_rate_hz;
    cfg.supersample = 1;
    cfg.seed = seed;
    let c = rng.random_range(0.1..0.25);
    (cfg.events.threshold_pos, cfg.events.threshold_neg) = (c, c);
    cfg.events.threshold_sigma = rng.random_range(0.0..0.03);
    cfg.events.shot_noise_hz = rng.random_range(0.0..0.3);
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

/// Simulate the scene of `(preset, seed)` at `size`².
pub fn make_scene(preset: &str, seed: u64, size: u32, s: &PretrainSettings) -> Result<SceneData> {
    let cfg = scene_config(preset, seed, size, s)?;
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
        name: if size == s.resolution {
            format!("{preset}/{seed}")
        } else {
            format!("{preset}/{seed}@{size}")
        },
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

/// How a window is turned into a training sample. `Augment::default()` is the window as
/// recorded.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Augment {
    /// Mirror horizontally / vertically (flow u / v changes sign).
    pub flip: (bool, bool),
    /// Swap the x and y axes (square samples only; flow (u, v) becomes (v, u)).
    pub transpose: bool,
    /// Play the window backwards: event times mirrored, polarities and flow negated (the
    /// voxel grid becomes `−E[B−1−n]`, exactly what the reversed events give).
    pub reverse: bool,
    /// Keep only the `size`² block at `(x0, y0)`: `(x0, y0, size)`.
    pub crop: Option<(usize, usize, usize)>,
}

/// The sample of window `[t_a, t_b]` of `d`, augmented as asked (crop first, then
/// transpose, then flips).
pub fn sample(d: &SceneData, (t_a, t_b): (f64, f64), bins: usize, aug: Augment) -> Sample {
    let (mut w, mut h) = (d.events.width as usize, d.events.height as usize);
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
    if aug.reverse {
        // bin n of the reversed window is −(bin B−1−n)
        voxel = voxel.chunks(w * h).rev().flatten().map(|v| -v).collect();
        target.iter_mut().for_each(|v| *v = -*v);
        cm.t.iter_mut().for_each(|t| *t = 1.0 - *t);
    }
    if let Some((x0, y0, c)) = aug.crop {
        assert!(x0 + c <= w && y0 + c <= h, "crop outside the sensor");
        let cut = |planes: &[f32]| -> Vec<f32> {
            planes
                .chunks(w * h)
                .flat_map(|pl| {
                    (y0..y0 + c).flat_map(move |y| pl[y * w + x0..y * w + x0 + c].iter().copied())
                })
                .collect()
        };
        voxel = cut(&voxel);
        target = cut(&target);
        mask = cut(&mask);
        let mut kept = CmEvents::default();
        for k in 0..cm.len() {
            let (x, y) = (cm.x[k] as usize, cm.y[k] as usize);
            if (x0..x0 + c).contains(&x) && (y0..y0 + c).contains(&y) {
                kept.x.push(cm.x[k] - x0 as f64);
                kept.y.push(cm.y[k] - y0 as f64);
                kept.t.push(cm.t[k]);
            }
        }
        cm = kept;
        (w, h) = (c, c);
    }
    let (fx, fy) = aug.flip;
    let tr = aug.transpose;
    assert!(!tr || w == h, "transpose needs a square sample");
    if fx || fy || tr {
        // Output pixel (x, y) comes from source pixel `map(x, y)`.
        let map = |x: usize, y: usize| {
            let xs = if fx { w - 1 - x } else { x };
            let ys = if fy { h - 1 - y } else { y };
            if tr { xs * w + ys } else { ys * w + xs }
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
        let (pu, pv) = target.split_at(w * h);
        let (pu, pv) = if tr { (pv, pu) } else { (pu, pv) };
        let mut t = remap(pu, su);
        t.extend(remap(pv, sv));
        target = t;
        mask = remap(&mask, 1.0);
        for k in 0..cm.len() {
            if tr {
                std::mem::swap(&mut cm.x[k], &mut cm.y[k]);
            }
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
            let size = match s.train_sizes.len() {
                0 => s.resolution,
                n => s.train_sizes[train.len() % n],
            };
            train.push(make_scene(p, seed, size, s)?);
        }
    }
    Ok((train, make_held_out(s)?))
}

/// Build the held-out scenes (at `resolution`, speeds from `eval_speed` if set).
pub fn make_held_out(s: &PretrainSettings) -> Result<Vec<SceneData>> {
    let mut held = Vec::new();
    let hs = match s.eval_speed {
        Some([lo, hi]) => PretrainSettings {
            speed_min: lo,
            speed_max: hi,
            ..s.clone()
        },
        None => s.clone(),
    };
    for p in &s.eval_presets {
        for &seed in &s.eval_seeds {
            held.push(make_scene(p, seed, s.resolution, &hs)?);
        }
    }
    Ok(held)
}
