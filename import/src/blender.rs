//! D-NeRF / Blender transforms with an event file beside them (what E-D3DGS-style
//! synthetic data look like):
//!
//! ```text
//! SRC/transforms_train.json   camera_angle_x (or fl_x …), frames: file_path, time ∈ [0,1],
//!                             transform_matrix (camera-to-world, OpenGL axes already)
//! SRC/transforms_test.json    optional; its frames stay test frames (unless --test-every)
//! SRC/events.{evs,txt,npz,aedat4,raw,es}   or the manifest's events.path, or --events FILE
//! ```
//!
//! Frames that carry a `timestamp` keep it. Frames with only the normalised `time` are
//! placed on the events' clock as `timestamp = offset + time · duration`; `offset` and
//! `duration` come from `--time-offset` / `--duration`, else from the events' first
//! timestamp and span (with a warning: the events may start after the first frame).
//! `transforms_val.json` is ignored. Blender PNGs are sRGB with alpha (composited over
//! white when read), so the scene says `frame_encoding: srgb` unless the manifest says.

use crate::aligned::{EventsAlignment, TimeMap, event_file, read_for_sensor};
use crate::recording::{FrameImage, Recording, SourceFrame};
use scene::Scene;
use scene::atomic::{AtomicDir, OutputRule, write_bytes_atomic, write_json_atomic};
use scene::error::{Error, Result};
use scene::manifest::{FrameEncoding, Manifest, TEST_FILE, TRAIN_FILE};
use std::path::Path;

/// Read a D-NeRF / Blender folder plus its events.
pub(crate) fn read_blender(src: &Path, o: &EventsAlignment) -> Result<Recording> {
    let train_path = src.join(TRAIN_FILE);
    let train = Manifest::read(&train_path)?;
    let test_path = src.join(TEST_FILE);
    let test = if test_path.is_file() {
        Some(Manifest::read(&test_path)?)
    } else {
        None
    };
    let cam = train.camera;
    let events_ref = train.events.as_ref().map(|e| e.path.as_str());
    let events_path = event_file(src, o, events_ref, &train_path)?;
    let events = read_for_sensor(&events_path, cam.width, cam.height)?;
    let mut warnings = Vec::new();
    let times = TimeMap::new(o, &events)?;
    let mut frames = Vec::new();
    let splits = [
        (Some(&train), false, &train_path),
        (test.as_ref(), true, &test_path),
    ];
    let mut normalised_only = 0;
    for (m, is_test, path) in splits {
        let Some(m) = m else { continue };
        if (m.camera.width, m.camera.height) != (cam.width, cam.height) {
            return Err(Error::invalid(
                path,
                "camera size differs from the train file's",
            ));
        }
        let raw = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let json: serde_json::Value = serde_json::from_str(&raw)
            .map_err(|e| Error::invalid(path, format!("not JSON: {e}")))?;
        for (i, f) in m.frames.iter().enumerate() {
            let has_timestamp = json["frames"][i].get("timestamp").is_some();
            let timestamp = if has_timestamp {
                f.timestamp
            } else {
                normalised_only += 1;
                times.seconds(f.time)
            };

            let mut image = src.join(&f.file_path);
            if image.extension().is_none() {
                image.set_extension("png");
            }
            frames.push((
                is_test,
                SourceFrame {
                    image: FrameImage::File(image),
                    timestamp,
                    pose: f.cam_to_world,
                },
            ));
        }
    }
    warnings.extend(times.warning(normalised_only));
    frames.sort_by(|a, b| a.1.timestamp.total_cmp(&b.1.timestamp));
    let held_out = frames.iter().map(|f| f.0).collect();
    Ok(Recording {
        layout: "blender",
        camera: cam,
        frames: frames.into_iter().map(|f| f.1).collect(),
        events,
        frame_encoding: train.frame_encoding.unwrap_or(FrameEncoding::Srgb),
        warnings,
        held_out: Some(held_out),
    })
}

/// Write `scene` as a D-NeRF folder at `out`: `camera_angle_x` (the scene's camera must
/// be centred with square pixels), frames with `file_path` without extension and only
/// the normalised `time = (timestamp − offset) / duration`, the events as `events.evs`.
/// For tests of the normalised-time mapping.
pub fn export_blender(scene: &Scene, offset: f64, duration: f64, out: &Path) -> Result<()> {
    let dir = AtomicDir::new(out, &OutputRule::new("export"))?;
    let root = dir.path();
    let cam = &scene.train.camera;
    for (name, m, split) in [
        (TRAIN_FILE, &scene.train, "train"),
        (TEST_FILE, &scene.test, "test"),
    ] {
        let mut frames = Vec::new();
        for (k, f) in m.frames.iter().enumerate() {
            let rel = format!("{split}/r_{k:03}");
            let src = scene.image_path(f);
            let bytes = std::fs::read(&src).map_err(|e| Error::io(&src, e))?;
            write_bytes_atomic(&root.join(format!("{rel}.png")), &bytes)?;
            let m = f.cam_to_world.matrix().transpose().to_cols_array_2d();
            frames.push(serde_json::json!({
                "file_path": rel,
                "time": (f.timestamp - offset) / duration,
                "transform_matrix": m,
            }));
        }
        let json = serde_json::json!({"camera_angle_x": cam.fov_x(), "frames": frames});
        write_json_atomic(&root.join(name), &json)?;
    }
    scene::formats::write_evs(root.join("events.evs"), &scene.load_events()?)?;
    dir.commit()?;
    Ok(())
}
