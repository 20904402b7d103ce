//! Write a complete synthetic scene directory (docs/DESIGN.md §3) with ground truth,
//! from a [`SynthConfig`]: analytic renders ([`crate::world`]) plus simulated events
//! ([`crate::sim`]).
//!
//! Layout of `out_dir` (built under a temp name and renamed at the end):
//!
//! ```text
//! transforms_train.json   train frames at k/train_fps, events entry (events.evs, C)
//! transforms_test.json    held-out frames at (k + ½)·duration/test_frames
//! images/train_XXXX.png   linear RGB, 8-bit; averaged over `blur_subframes` renders
//!                         spanning `exposure_s` when blur_subframes > 1
//! images/test_XXXX.png    sharp
//! transforms_novel.json   novel views: at the test times, from the recorded camera's
//!                         centre rotated by `novel_angle_deg` about the vertical axis
//!                         through the path's target, looking at it (absent when the
//!                         angle is 0; `SynthWorld::novel_camera_at`)
//! images/novel_XXXX.png   sharp
//! events.evs              events simulated from renders at render_rate_hz
//! synth.json              the SynthConfig used
//! report.json             the Summary (counts, timings)
//! gt/train/depth_XXXX.exr depth (EXR `Z`, −z_cam, 0 on background) at the train times
//! gt/train/flow_XXXX.exr  analytic optical flow (EXR `U`,`V`, px/s)
//! gt/train/object_XXXX.png object ids (16-bit PNG, 0 = background, k+1 = objects[k])
//! gt/novel/covisible_XXXX.png 1 where some train view saw what the novel pixel shows,
//!                          else 0 (16-bit PNG, [`crate::covis`])
//! gt/test/…               the same at the test times
//! gt/novel/…              the same from the novel cameras
//! gt/event_flow.bin       per-event flow (px/s) and object id, one row per event of
//!                         events.evs (format: crate::gt)
//! ```
//!
//! XXXX is the frame's index in its manifest. The ground truth of the train frames is
//! the sharp render at the frame time (also when the image is blurred). The flow of an
//! event is the analytic flow at its pixel, linearly interpolated in time between the
//! two internal renders around it (the nearer one when the object differs); noise
//! events get flow 0 and object id [`NOISE_ID`].

use crate::config::SynthConfig;
use crate::gt::{EventFlowGt, NOISE_ID, write_event_flow_gt, write_object_png};
use crate::sim::{Simulator, luminance};
use crate::world::{Render, SynthWorld};
use scene::atomic::{AtomicDir, OutputRule, write_json_atomic};
use scene::error::{Error, Result};
use scene::events::EventStream;
use scene::image_io::{Image, write_exr_depth, write_exr_flow, write_png};
use scene::manifest::{
    EventsRef, Frame, FrameEncoding, Manifest, NOVEL_FILE, TEST_FILE, TRAIN_FILE,
};
use serde::{Deserialize, Serialize};
use stagekit::Settings;
use stagekit::progress::Progress;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Name of the event file inside the scene directory.
pub const EVENTS_FILE: &str = "events.evs";

/// What [`write_synthetic_scene`] produced and how long it took.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Summary {
    pub out_dir: PathBuf,
    pub preset: String,
    pub width: u32,
    pub height: u32,
    pub train_frames: usize,
    pub test_frames: usize,
    /// Frames of the novel-view split (0: none written).
    #[serde(default)]
    pub novel_frames: usize,
    pub internal_frames: usize,
    pub events: usize,
    pub noise_events: usize,
    /// Seconds spent rendering the internal frames and simulating events.
    pub simulate_s: f64,
    /// Seconds spent rendering and writing the train/test/novel frames and their ground
    /// truth.
    pub frames_s: f64,
    pub total_s: f64,
}

impl Summary {
    /// One line for people: `rigid 128x128, 9 train + 8 test frames + 8 novel views,
    /// 511087 events in 11.14 s`.
    pub fn line(&self) -> String {
        format!(
            "{} {}x{}, {} train + {} test frames + {} novel views, {} events in {:.2} s",
            self.preset,
            self.width,
            self.height,
            self.train_frames,
            self.test_frames,
            self.novel_frames,
            self.events,
            self.total_s
        )
    }
}

/// Render the recording at the internal rate and simulate its events, with the
/// per-event ground truth (see the module doc).
pub fn simulate_scene(world: &SynthWorld) -> Result<(EventStream, EventFlowGt)> {
    simulate_scene_shown(world, None)
}

/// [`simulate_scene`], one step of `progress` per internal render.
fn simulate_scene_shown(
    world: &SynthWorld,
    progress: Option<&Progress>,
) -> Result<(EventStream, EventFlowGt)> {
    let cfg = world.config();
    let (w, h) = (cfg.width, cfg.height);
    cfg.events
        .validate()
        .map_err(|e| Error::Other(format!("synthetic scene: simulator settings: {e}")))?;
    let mut sim = Simulator::new(w, h, &cfg.events, cfg.seed);
    let mut events = EventStream::new(w, h);
    let mut noise = Vec::new();
    let mut gt = EventFlowGt {
        width: w,
        height: h,
        ..Default::default()
    };
    let mut prev: Option<(f64, Render)> = None;
    for (k, t) in cfg.render_times().into_iter().enumerate() {
        if let Some(p) = progress {
            p.set(k as u64 + 1, || format!("{} events", events.len()));
        }
        let render = world.render(t);
        let start = events.len();
        sim.push_frame_flagged(t, &luminance(&render.rgb), &mut events, Some(&mut noise))?;
        if let Some((t0, before)) = &prev {
            for (i, &is_noise) in noise.iter().enumerate().skip(start) {
                let pix = events.y[i] as usize * w as usize + events.x[i] as usize;
                let (u, v, id) = if is_noise {
                    (0.0, 0.0, NOISE_ID)
                } else {
                    event_flow(before, &render, pix, (events.t[i] - t0) / (t - t0))
                };
                gt.index.push(i as u64);
                gt.u.push(u);
                gt.v.push(v);
                gt.object.push(id);
            }
        }
        prev = Some((t, render));
    }
    Ok((events, gt))
}

/// The frames' progress across the three splits.
struct Shown {
    progress: Progress,
    done: u64,
}

impl Shown {
    fn step(&mut self, split: &str) {
        self.done += 1;
        self.progress.set(self.done, || split.to_string());
    }
}

/// Flow and object at pixel `pix`, fraction `a` of the way from render `r0` to `r1`.
fn event_flow(r0: &Render, r1: &Render, pix: usize, a: f64) -> (f32, f32, u16) {
    let a = a.clamp(0.0, 1.0) as f32;
    if r0.object_id[pix] == r1.object_id[pix] {
        let lerp = |x: f32, y: f32| x + (y - x) * a;
        (
            lerp(r0.flow_u[pix], r1.flow_u[pix]),
            lerp(r0.flow_v[pix], r1.flow_v[pix]),
            r0.object_id[pix],
        )
    } else {
        let r = if a < 0.5 { r0 } else { r1 };
        (r.flow_u[pix], r.flow_v[pix], r.object_id[pix])
    }
}

/// A train frame: the sharp render, or the mean of `blur_subframes` renders over the
/// exposure (centred on `t`, clamped to the recording).
fn train_image(world: &SynthWorld, t: f64, sharp: &Render) -> Vec<f32> {
    let cfg = world.config();
    let n = cfg.blur_subframes;
    if n <= 1 || cfg.exposure_s <= 0.0 {
        return sharp.rgb.clone();
    }
    let mut acc = vec![0f32; sharp.rgb.len()];
    for k in 0..n {
        let s = t + cfg.exposure_s * ((k as f64 + 0.5) / n as f64 - 0.5);
        let r = world.render_frame(s.clamp(0.0, cfg.duration));
        for (a, c) in acc.iter_mut().zip(&r.rgb) {
            *a += c / n as f32;
        }
    }
    acc
}

/// Render and write the frames of one split (`train`, `test` or `novel`: from the
/// novel-view cameras) with their ground truth; returns the manifest frames.
fn write_split(
    world: &SynthWorld,
    root: &Path,
    split: &str,
    times: &[f64],
    progress: &mut Shown,
) -> Result<Vec<Frame>> {
    let cfg = world.config();
    let (w, h) = (cfg.width, cfg.height);
    let gt_dir = root.join("gt").join(split);
    let novel = split == "novel";
    let mut frames = Vec::with_capacity(times.len());
    for (k, &t) in times.iter().enumerate() {
        progress.step(split);
        let (r, camera) = if novel {
            (world.render_novel_frame(t), world.novel_camera_at(t))
        } else {
            (world.render_frame(t), world.camera_at(t))
        };
        let rgb = if split == "train" {
            train_image(world, t, &r)
        } else {
            r.rgb.clone()
        };
        let file_path = format!("images/{split}_{k:04}.png");
        let img = Image {
            width: w,
            height: h,
            channels: 3,
            data: rgb,
        };
        write_png(root.join(&file_path), &img)?;
        write_exr_depth(gt_dir.join(format!("depth_{k:04}.exr")), w, h, &r.depth)?;
        write_exr_flow(
            gt_dir.join(format!("flow_{k:04}.exr")),
            w,
            h,
            &r.flow_u,
            &r.flow_v,
        )?;
        write_object_png(
            gt_dir.join(format!("object_{k:04}.png")),
            w,
            h,
            &r.object_id,
        )?;
        if novel {
            let seen = crate::covis::novel_covisible(world, t, &cfg.train_times());
            let ids: Vec<u16> = seen.iter().map(|&s| u16::from(s)).collect();
            write_object_png(gt_dir.join(format!("covisible_{k:04}.png")), w, h, &ids)?;
        }
        frames.push(Frame {
            file_path,
            timestamp: t,
            time: (t / cfg.duration).clamp(0.0, 1.0),
            cam_to_world: camera.cam_to_world,
        });
    }
    Ok(frames)
}

/// Write the synthetic scene of `cfg` to `out_dir` (layout in the module doc). The
/// directory appears complete or not at all; it must not exist yet, or be empty.
pub fn write_synthetic_scene(cfg: &SynthConfig, out_dir: &Path) -> Result<Summary> {
    write_synthetic_scene_with(cfg, out_dir, &OutputRule::new(SYNTH_COMMAND))
}

/// The command whose outputs [`write_synthetic_scene`] marks (an earlier one may be
/// replaced under `--force`).
pub const SYNTH_COMMAND: &str = "degs synth";

/// [`write_synthetic_scene`] under `rule` (e.g. forced: an earlier scene is replaced).
pub fn write_synthetic_scene_with(
    cfg: &SynthConfig,
    out_dir: &Path,
    rule: &OutputRule,
) -> Result<Summary> {
    let start = Instant::now();
    rule.check(out_dir)?;
    let world =
        SynthWorld::new(cfg).map_err(|e| Error::Other(format!("synthetic scene settings: {e}")))?;
    let dir = AtomicDir::new(out_dir, rule)?;
    let root = dir.path().to_path_buf();

    let t_sim = Instant::now();
    let renders = cfg.render_times().len() as u64;
    let sim_progress = Progress::new("events", renders);
    let (events, gt) = simulate_scene_shown(&world, Some(&sim_progress))?;
    sim_progress.finish();
    scene::formats::write_evs(root.join(EVENTS_FILE), &events)?;
    write_event_flow_gt(root.join("gt").join("event_flow.bin"), &gt)?;
    let simulate_s = t_sim.elapsed().as_secs_f64();

    let t_frames = Instant::now();
    let camera = world.intrinsics();
    let (train_t, test_t, novel_t) = (cfg.train_times(), cfg.test_times(), cfg.novel_times());
    let mut shown = Shown {
        progress: Progress::new(
            "frames",
            (train_t.len() + test_t.len() + novel_t.len()) as u64,
        ),
        done: 0,
    };
    let train = Manifest {
        camera,
        frames: write_split(&world, &root, "train", &train_t, &mut shown)?,
        events: Some(EventsRef {
            path: EVENTS_FILE.into(),
            contrast_threshold: cfg.events.nominal_threshold(),
        }),
        frame_encoding: Some(FrameEncoding::Linear),
    };
    let test = Manifest {
        camera,
        frames: write_split(&world, &root, "test", &test_t, &mut shown)?,
        events: None,
        frame_encoding: Some(FrameEncoding::Linear),
    };
    let novel = write_split(&world, &root, "novel", &novel_t, &mut shown)?;
    shown.progress.finish();
    train.write(root.join(TRAIN_FILE))?;
    test.write(root.join(TEST_FILE))?;
    if !novel.is_empty() {
        Manifest {
            frames: novel.clone(),
            ..test.clone()
        }
        .write(root.join(NOVEL_FILE))?;
    }
    write_json_atomic(&root.join("synth.json"), cfg)?;
    let frames_s = t_frames.elapsed().as_secs_f64();

    let mut summary = Summary {
        out_dir: out_dir.to_path_buf(),
        preset: cfg.preset.clone(),
        width: cfg.width,
        height: cfg.height,
        train_frames: train.frames.len(),
        test_frames: test.frames.len(),
        novel_frames: novel.len(),
        internal_frames: cfg.render_times().len(),
        events: events.len(),
        noise_events: gt.object.iter().filter(|&&o| o == NOISE_ID).count(),
        simulate_s,
        frames_s,
        total_s: 0.0,
    };
    summary.total_s = start.elapsed().as_secs_f64();
    write_json_atomic(&root.join("report.json"), &summary)?;
    dir.commit()?;
    Ok(summary)
}
