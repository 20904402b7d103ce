//! RGB-only synthetic scene directories: the manifests and frames of a
//! [`SynthConfig`], no events and no ground truth. For tests and benchmarks of the RGB
//! warm-up without the event simulator (`gaussians synth-rgb`).

use crate::config::SynthConfig;
use crate::world::SynthWorld;
use scene::atomic::{AtomicDir, OutputRule};
use scene::error::{Error, Result};
use scene::image_io::{Image, write_png};
use scene::manifest::{Frame, FrameEncoding, Manifest, NOVEL_FILE, TEST_FILE, TRAIN_FILE};
use std::path::Path;

/// Write an RGB-only scene directory (manifests + PNGs, no events) of a synthetic
/// configuration. Frame layout and times as the full synthetic writer
/// ([`crate::scene_dir::write_synthetic_scene`]: `images/{split}_NNNN.png`,
/// `time = t / duration`, the novel-view split when `novel_angle_deg` ≠ 0). The
/// directory appears complete or not at all.
pub fn write_rgb_synthetic_scene(cfg: &SynthConfig, out: &Path) -> Result<()> {
    let world =
        SynthWorld::new(cfg).map_err(|e| Error::Other(format!("synthetic scene settings: {e}")))?;
    let dir = AtomicDir::new(out, &OutputRule::new("gaussians synth-rgb"))?;
    for (split, times, file) in [
        ("train", cfg.train_times(), TRAIN_FILE),
        ("test", cfg.test_times(), TEST_FILE),
        ("novel", cfg.novel_times(), NOVEL_FILE),
    ] {
        if times.is_empty() && split == "novel" {
            continue;
        }
        let mut frames = Vec::new();
        for (k, &t) in times.iter().enumerate() {
            let (r, camera) = if split == "novel" {
                (world.render_novel_frame(t), world.novel_camera_at(t))
            } else {
                (world.render_frame(t), world.camera_at(t))
            };
            let file_path = format!("images/{split}_{k:04}.png");
            let img = Image {
                width: r.width,
                height: r.height,
                channels: 3,
                data: r.rgb,
            };
            write_png(dir.path().join(&file_path), &img)?;
            frames.push(Frame {
                file_path,
                timestamp: t,
                time: (t / cfg.duration).clamp(0.0, 1.0),
                cam_to_world: camera.cam_to_world,
            });
        }
        Manifest {
            camera: world.intrinsics(),
            frames,
            events: None,
            frame_encoding: Some(FrameEncoding::Linear),
        }
        .write(dir.path().join(file))?;
    }
    dir.commit()?;
    Ok(())
}
