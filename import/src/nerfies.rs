//! nerfies / HyperNeRF / NeRF-DS captures (the paper's real dynamic scenes, re-recorded
//! with an event camera) with an event file beside them:
//!
//! ```text
//! SRC/dataset.json     ids; train_ids and val_ids (val frames become test frames)
//! SRC/metadata.json    per id: time_id (or warp_id, the frame's time index), camera_id, …
//! SRC/camera/ID.json   orientation (3×3, world → camera, OpenCV axes), position (the
//!                      camera centre), focal_length, pixel_aspect_ratio, principal_point,
//!                      skew, radial_distortion [k1 k2 k3], tangential_distortion [p1 p2],
//!                      image_size [w h] (of rgb/1x)
//! SRC/scene.json       optional: center, scale (world = (p − center) · scale)
//! SRC/rgb/Nx/ID.png    the frames at 1/N of full size
//! SRC/events.{evs,txt,npz,aedat4,raw,es}   or --events FILE
//! ```
//!
//! Conventions, as the layout's own loaders read them: pixel centres sit at integer + ½
//! (so our `cx = principal_point_x − ½`), `fy = focal_length · pixel_aspect_ratio`, the
//! distortion is OpenCV's radial-tangential, and a camera at 1/N scales focal length and
//! principal point by 1/N. A frame's normalised time is `time_id / max time_id` (the
//! loaders of Deform-GS and 4DGS do the same), placed on the events' clock as in the
//! blender layout (`--time-offset`, `--duration`). `scene.json` is applied, so the scene
//! has the layout's normalised scale. Skewed pixels are refused; all frames must share
//! one camera (a multi-camera capture is refused, naming the camera that differs).

use crate::aligned::{EventsAlignment, TimeMap, event_file, read_for_sensor};
use crate::convention::{opencv_to_opengl, opengl_to_opencv};
use crate::recording::{FrameImage, Recording, SourceFrame};
use glam::{DMat3, DQuat, DVec3};
use scene::atomic::{AtomicDir, OutputRule, write_bytes_atomic, write_json_atomic};
use scene::error::{Error, IoContext, Result};
use scene::manifest::FrameEncoding;
use scene::{Distortion, Intrinsics, Pose, Scene};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Deserialize)]
struct Dataset {
    ids: Vec<String>,
    #[serde(default)]
    val_ids: Vec<String>,
}

#[derive(Deserialize)]
struct Meta {
    time_id: Option<u64>,
    warp_id: Option<u64>,
}

#[derive(Deserialize)]
struct SceneJson {
    center: [f64; 3],
    scale: f64,
}

/// `camera/ID.json`.
#[derive(Debug, Deserialize, serde::Serialize)]
struct CameraJson {
    orientation: [[f64; 3]; 3],
    position: [f64; 3],
    focal_length: f64,
    #[serde(default = "one")]
    pixel_aspect_ratio: f64,
    principal_point: [f64; 2],
    #[serde(default)]
    skew: f64,
    #[serde(default)]
    radial_distortion: Option<Vec<f64>>,
    #[serde(default)]
    tangential_distortion: Option<Vec<f64>>,
    image_size: [u32; 2],
}

fn one() -> f64 {
    1.0
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).at(path)?;
    serde_json::from_str(&text).map_err(|e| Error::invalid(path, format!("{e}")))
}

/// The frame folder `rgb/{N}x`: `downscale` if given, else 1 if present, else the
/// smallest N present.
fn frame_scale(src: &Path, downscale: Option<u32>) -> Result<u32> {
    let dir = |n: u32| src.join("rgb").join(format!("{n}x"));
    if let Some(n) = downscale {
        return if n >= 1 && dir(n).is_dir() {
            Ok(n)
        } else {
            Err(Error::invalid(
                dir(n),
                "no such frame folder (--downscale N reads rgb/Nx/)",
            ))
        };
    }
    (1..=64)
        .find(|&n| dir(n).is_dir())
        .ok_or_else(|| Error::invalid(src.join("rgb"), "no frame folder rgb/1x/, rgb/2x/, … found"))
}

/// Intrinsics of rgb/{n}x from a camera file (full-size values).
fn intrinsics(c: &CameraJson, n: u32, path: &Path) -> Result<Intrinsics> {
    let bad = |what: &str| Err(Error::invalid(path, what.to_string()));
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !positive(c.focal_length)
        || !positive(c.pixel_aspect_ratio)
        || !c.principal_point.iter().all(|v| v.is_finite())
    {
        return bad("focal_length, pixel_aspect_ratio and principal_point must be finite, > 0");
    }
    if c.skew.abs() > 1e-6 * c.focal_length {
        return bad("skewed pixels (skew ≠ 0) are not supported");
    }
    let s = 1.0 / n as f64;
    let radial = c.radial_distortion.clone().unwrap_or_default();
    let tangential = c.tangential_distortion.clone().unwrap_or_default();
    if radial.len() > 3
        || tangential.len() > 2
        || radial.iter().chain(&tangential).any(|v| !v.is_finite())
    {
        return bad("radial_distortion takes up to 3 finite values, tangential_distortion up to 2");
    }
    let at = |v: &[f64], i: usize| v.get(i).copied().unwrap_or(0.0);
    let d = Distortion {
        k1: at(&radial, 0),
        k2: at(&radial, 1),
        k3: at(&radial, 2),
        p1: at(&tangential, 0),
        p2: at(&tangential, 1),
    };
    let [w, h] = c.image_size;
    if w == 0 || h == 0 {
        return bad("image_size must be positive");
    }
    Ok(Intrinsics {
        width: (w as f64 * s).round() as u32,
        height: (h as f64 * s).round() as u32,
        fx: c.focal_length * s,
        fy: c.focal_length * c.pixel_aspect_ratio * s,
        cx: c.principal_point[0] * s - 0.5,
        cy: c.principal_point[1] * s - 0.5,
        distortion: (!d.is_zero()).then_some(d),
    })
}

/// Camera-to-world pose in the manifest's axes from a camera file and scene.json.
fn pose(c: &CameraJson, norm: Option<&SceneJson>, path: &Path) -> Result<Pose> {
    // The rows of `orientation` map world to camera; read as columns they give its
    // transpose, the camera-to-world rotation.
    let r_cw = DMat3::from_cols_array_2d(&c.orientation);
    let ortho = (r_cw.transpose() * r_cw - DMat3::IDENTITY).to_cols_array();
    if ortho.iter().any(|v| !v.is_finite() || v.abs() > 1e-4) || r_cw.determinant() < 0.0 {
        return Err(Error::invalid(path, "orientation is not a rotation matrix"));
    }
    let mut centre = DVec3::from(c.position);
    if !centre.is_finite() {
        return Err(Error::invalid(path, "position is not finite"));
    }
    if let Some(n) = norm {
        centre = (centre - DVec3::from(n.center)) * n.scale;
    }
    Ok(opencv_to_opengl(Pose::new(
        DQuat::from_mat3(&r_cw).normalize(),
        centre,
    )))
}

/// Read a nerfies-style capture plus its events.
pub(crate) fn read_nerfies(
    src: &Path,
    o: &EventsAlignment,
    downscale: Option<u32>,
) -> Result<Recording> {
    let dataset_path = src.join("dataset.json");
    let dataset: Dataset = read_json(&dataset_path)?;
    let meta_path = src.join("metadata.json");
    let meta: BTreeMap<String, Meta> = read_json(&meta_path)?;
    let scene_path = src.join("scene.json");
    let norm: Option<SceneJson> = if scene_path.is_file() {
        let n: SceneJson = read_json(&scene_path)?;
        if !(n.scale.is_finite() && n.scale > 0.0 && n.center.iter().all(|v| v.is_finite())) {
            return Err(Error::invalid(
                &scene_path,
                "scale must be finite and > 0, center finite",
            ));
        }
        Some(n)
    } else {
        None
    };
    if dataset.ids.is_empty() {
        return Err(Error::invalid(&dataset_path, "no ids"));
    }
    let n = frame_scale(src, downscale)?;
    let mut time_ids = Vec::with_capacity(dataset.ids.len());
    for id in &dataset.ids {
        let m = meta.get(id).ok_or_else(|| {
            Error::invalid(
                &meta_path,
                format!("no entry for id {id:?} of dataset.json"),
            )
        })?;
        let t = m.time_id.or(m.warp_id).ok_or_else(|| {
            Error::invalid(&meta_path, format!("{id:?}: neither time_id nor warp_id"))
        })?;
        time_ids.push(t);
    }
    let max_id = time_ids.iter().copied().max().unwrap_or(0).max(1) as f64;
    if let Some(id) = dataset.val_ids.iter().find(|v| !dataset.ids.contains(v)) {
        return Err(Error::invalid(
            &dataset_path,
            format!("val_ids names {id:?}, which is not among its ids"),
        ));
    }

    let mut camera: Option<(Intrinsics, std::path::PathBuf)> = None;
    let mut frames = Vec::with_capacity(dataset.ids.len());
    for (id, &tid) in dataset.ids.iter().zip(&time_ids) {
        let cam_path = src.join("camera").join(format!("{id}.json"));
        let c: CameraJson = read_json(&cam_path)?;
        let k = intrinsics(&c, n, &cam_path)?;
        match &camera {
            None => camera = Some((k, cam_path.clone())),
            Some((k0, p0)) if !same_camera(k0, &k) => {
                return Err(Error::invalid(
                    &cam_path,
                    format!(
                        "its intrinsics differ from those of {}: one scene has one camera \
                         (import the frames of one camera)",
                        p0.display()
                    ),
                ));
            }
            Some(_) => {}
        }
        let image = src
            .join("rgb")
            .join(format!("{n}x"))
            .join(format!("{id}.png"));
        frames.push((
            dataset.val_ids.contains(id),
            tid as f64 / max_id,
            SourceFrame {
                image: FrameImage::File(image),
                timestamp: 0.0,
                pose: pose(&c, norm.as_ref(), &cam_path)?,
            },
        ));
    }
    let (cam, _) = camera.expect("ids is not empty");
    let events_path = event_file(src, o, None, &dataset_path)?;
    let events = read_for_sensor(&events_path, cam.width, cam.height)?;
    let times = TimeMap::new(o, &events)?;
    let mut warnings: Vec<String> = times.warning(frames.len()).into_iter().collect();
    if dataset.val_ids.is_empty() {
        warnings.push("dataset.json has no val_ids: no test frames unless --test-every".into());
    }
    for f in &mut frames {
        f.2.timestamp = times.seconds(f.1);
    }
    frames.sort_by(|a, b| a.2.timestamp.total_cmp(&b.2.timestamp));
    Ok(Recording {
        layout: "nerfies",
        camera: cam,
        held_out: (!dataset.val_ids.is_empty()).then(|| frames.iter().map(|f| f.0).collect()),
        frames: frames.into_iter().map(|f| f.2).collect(),
        events,
        frame_encoding: FrameEncoding::Srgb,
        warnings,
    })
}

/// Intrinsics equal up to float noise (files round-trip through decimal text).
fn same_camera(a: &Intrinsics, b: &Intrinsics) -> bool {
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-9 * (1.0 + x.abs().max(y.abs()));
    (a.width, a.height) == (b.width, b.height)
        && close(a.fx, b.fx)
        && close(a.fy, b.fy)
        && close(a.cx, b.cx)
        && close(a.cy, b.cy)
        && a.distortion.unwrap_or_default() == b.distortion.unwrap_or_default()
}

/// Where [`export_nerfies`] puts a scene: `world_file = world / scale + center`, frame
/// times as `time_id = (timestamp − offset) · ticks_per_second` (must be whole).
#[derive(Clone, Copy, Debug)]
pub struct NerfiesExport {
    pub center: [f64; 3],
    pub scale: f64,
    pub offset: f64,
    pub ticks_per_second: f64,
}

/// Write `scene` in the nerfies layout at `out` (frames in rgb/1x, train frames in
/// train_ids, test frames in val_ids, events as events.evs). For the round-trip tests.
pub fn export_nerfies(scene: &Scene, x: &NerfiesExport, out: &Path) -> Result<()> {
    let dir = AtomicDir::new(out, &OutputRule::new("export"))?;
    let root = dir.path();
    let cam = scene.train.camera;
    let d = cam.distortion.unwrap_or_default();
    let (mut ids, mut train_ids, mut val_ids) = (vec![], vec![], vec![]);
    let mut meta = serde_json::Map::new();
    for (split, m) in [("train", &scene.train), ("test", &scene.test)] {
        for (k, f) in m.frames.iter().enumerate() {
            let id = format!("{split}_{k:03}");
            let ticks = (f.timestamp - x.offset) * x.ticks_per_second;
            if ticks.fract() != 0.0 || ticks < 0.0 {
                return Err(Error::Other(format!(
                    "frame time {} s is not a whole tick of 1/{} s after {}",
                    f.timestamp, x.ticks_per_second, x.offset
                )));
            }
            meta.insert(
                id.clone(),
                serde_json::json!({"time_id": ticks as u64, "warp_id": ticks as u64,
                    "appearance_id": ticks as u64, "camera_id": 0}),
            );
            let src = scene.image_path(f);
            let bytes = std::fs::read(&src).at(&src)?;
            write_bytes_atomic(&root.join(format!("rgb/1x/{id}.png")), &bytes)?;
            let cv = opengl_to_opencv(f.cam_to_world);
            let r_cw = DMat3::from_quat(cv.rotation);
            let c = CameraJson {
                // Rows of the world → camera rotation = columns of camera → world.
                orientation: r_cw.to_cols_array_2d(),
                position: (cv.translation / x.scale + DVec3::from(x.center)).to_array(),
                focal_length: cam.fx,
                pixel_aspect_ratio: cam.fy / cam.fx,
                principal_point: [cam.cx + 0.5, cam.cy + 0.5],
                skew: 0.0,
                radial_distortion: Some(vec![d.k1, d.k2, d.k3]),
                tangential_distortion: Some(vec![d.p1, d.p2]),
                image_size: [cam.width, cam.height],
            };
            write_json_atomic(&root.join(format!("camera/{id}.json")), &c)?;
            if split == "train" {
                train_ids.push(id.clone());
            } else {
                val_ids.push(id.clone());
            }
            ids.push(id);
        }
    }
    let dataset = serde_json::json!({"count": ids.len(), "num_exemplars": train_ids.len(),
        "ids": ids, "train_ids": train_ids, "val_ids": val_ids});
    write_json_atomic(&root.join("dataset.json"), &dataset)?;
    write_json_atomic(&root.join("metadata.json"), &meta)?;
    let sj = serde_json::json!({"center": x.center, "scale": x.scale, "near": 0.01, "far": 100.0});
    write_json_atomic(&root.join("scene.json"), &sj)?;
    scene::formats::write_evs(root.join("events.evs"), &scene.load_events()?)?;
    dir.commit()?;
    Ok(())
}
