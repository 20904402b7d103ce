//! The scene manifest (DESIGN §3): `transforms_train.json` / `transforms_test.json`
//! (and the optional novel-view split `transforms_novel.json`) in the D-NeRF /
//! nerfstudio layout, and [`Scene`], a validated scene directory.
//!
//! Layout read and written here:
//!
//! ```json
//! {
//!   "camera": {"w": 346, "h": 260, "fl_x": 300.0, "fl_y": 300.0, "cx": 172.5, "cy": 129.5,
//!              "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0, "k3": 0.0},
//!   "frames": [{"file_path": "images/r_000.png", "timestamp": 0.0, "time": 0.0,
//!               "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}],
//!   "events": {"path": "events.evs", "contrast_threshold": 0.1}
//! }
//! ```
//!
//! Accepted variants when reading:
//! - the camera fields may sit at the top level instead of in `camera` (nerfstudio);
//! - `camera_angle_x` (horizontal field of view, radians; D-NeRF/Blender) instead of
//!   `fl_x`…: a centred camera ([`Intrinsics::from_fov_x`]). Its size comes from `w`,`h`
//!   if given, else from the header of the first frame's image;
//! - distortion `k1 k2 p1 p2 k3` (OpenCV radial-tangential, nerfstudio names); missing
//!   coefficients are 0, all-zero means none;
//! - a frame without `timestamp` uses its `time` as timestamp (D-NeRF has no clock);
//! - a `file_path` without extension means `<file_path>.png` (Blender convention).
//!
//! `transform_matrix` is camera-to-world in OpenGL axes, stored as a list of rows.
//! `cx`, `cy` use this project's pixel convention (pixel centres at integer coordinates,
//! as OpenCV calibrations); a missing `cx`/`cy` means the image centre `(w − 1)/2`.
//! Files converted from COLMAP, whose pixel centres sit at +0.5, need `cx − 0.5`.
//! [`Manifest::write`] always writes the `camera` object form with explicit intrinsics.

use crate::camera::{Distortion, Intrinsics, Pose, Trajectory};
use crate::error::{Error, IoContext, Result};
use crate::events::EventStream;
use glam::DMat4;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Default contrast threshold C of the event generation model (DESIGN §3).
pub const DEFAULT_CONTRAST_THRESHOLD: f64 = 0.1;

/// File names of a scene directory.
pub const TRAIN_FILE: &str = "transforms_train.json";
pub const TEST_FILE: &str = "transforms_test.json";
/// Held-out frames at test times seen from cameras off the recorded path (optional).
pub const NOVEL_FILE: &str = "transforms_novel.json";

/// One RGB frame with its camera pose.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Image path relative to the manifest's directory.
    pub file_path: String,
    /// Seconds, on the clock of the event stream.
    pub timestamp: f64,
    /// Normalised time in [0, 1] over the recording.
    pub time: f64,
    pub cam_to_world: Pose,
}

/// The median time between consecutive `times` (in time order; 0 for fewer than two):
/// a frame rate's interval that one dropped or late frame does not move.
pub fn median_interval(times: &[f64]) -> f64 {
    let mut d: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied().unwrap_or(0.0)
}

/// Where the event stream is and its contrast threshold.
#[derive(Clone, Debug, PartialEq)]
pub struct EventsRef {
    /// Path relative to the manifest's directory (`.txt`, `.npz`, `.evs`, `.aedat4`).
    pub path: String,
    pub contrast_threshold: f64,
}

/// How the frames' 8-bit codes map to intensity (`frame_encoding` in the manifest).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrameEncoding {
    /// The sRGB transfer curve (PNG/JPEG convention; what a missing field means).
    Srgb,
    /// Linear in the stored code (`degs synth` writes these).
    Linear,
}

impl FrameEncoding {
    pub fn is_srgb(self) -> bool {
        self == FrameEncoding::Srgb
    }
}

/// The content of one `transforms_*.json`.
#[derive(Clone, Debug, PartialEq)]
pub struct Manifest {
    pub camera: Intrinsics,
    pub frames: Vec<Frame>,
    pub events: Option<EventsRef>,
    /// How the frames are encoded; `None` (the field absent) means sRGB for 8-bit images.
    pub frame_encoding: Option<FrameEncoding>,
}

/// Camera fields as they appear in the file (all optional: checked after parsing).
#[derive(Default, Serialize, Deserialize)]
struct RawCamera {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    w: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    h: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    fl_x: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    fl_y: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cx: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cy: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    camera_angle_x: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    k1: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    k2: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    p1: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    p2: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    k3: Option<f64>,
}

#[derive(Serialize, Deserialize)]
struct RawFrame {
    file_path: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    timestamp: Option<f64>,
    time: f64,
    transform_matrix: [[f64; 4]; 4],
}

#[derive(Serialize, Deserialize)]
struct RawEvents {
    path: String,
    #[serde(default = "default_contrast")]
    contrast_threshold: f64,
}

fn default_contrast() -> f64 {
    DEFAULT_CONTRAST_THRESHOLD
}

#[derive(Serialize, Deserialize)]
struct RawManifest {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    camera: Option<RawCamera>,
    #[serde(flatten)]
    top: RawCamera,
    frames: Vec<RawFrame>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    events: Option<RawEvents>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    frame_encoding: Option<FrameEncoding>,
}

impl Manifest {
    /// Whether the frames' codes are sRGB (the default when the manifest does not say).
    pub fn frames_srgb(&self) -> bool {
        self.frame_encoding.is_none_or(|e| e.is_srgb())
    }

    /// Read and check one manifest: camera complete and finite, every frame's pose rigid,
    /// `time` in [0, 1], timestamps finite and strictly increasing. Errors name the file
    /// and the frame index.
    pub fn read(path: impl AsRef<Path>) -> Result<Manifest> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).at(path)?;
        let raw: RawManifest = serde_json::from_str(&text)
            .map_err(|e| Error::invalid(path, format!("not a valid manifest: {e}")))?;
        let dir = path.parent().unwrap_or(Path::new(""));
        let bad = |msg: String| Error::invalid(path, msg);

        let mut frames: Vec<Frame> = Vec::with_capacity(raw.frames.len());
        for (i, f) in raw.frames.iter().enumerate() {
            let timestamp = f.timestamp.unwrap_or(f.time);
            if !timestamp.is_finite() {
                return Err(bad(format!(
                    "frame {i}: timestamp {timestamp} is not finite"
                )));
            }
            if !(0.0..=1.0).contains(&f.time) {
                return Err(bad(format!("frame {i}: time {} is outside [0, 1]", f.time)));
            }
            if let Some(prev) = frames.last()
                && timestamp <= prev.timestamp
            {
                return Err(bad(format!(
                    "frame {i} ({}) at {timestamp} s is not after frame {} ({}) at {} s: \
                     the times of one split must increase",
                    f.file_path,
                    i - 1,
                    prev.file_path,
                    prev.timestamp
                )));
            }
            let m = DMat4::from_cols_array_2d(&f.transform_matrix).transpose();
            let cam_to_world = Pose::from_matrix(m).map_err(|e| {
                bad(format!(
                    "frame {i} ({}): transform_matrix: {e}",
                    f.file_path
                ))
            })?;
            frames.push(Frame {
                file_path: f.file_path.clone(),
                timestamp,
                time: f.time,
                cam_to_world,
            });
        }

        let cam = raw.camera.as_ref().unwrap_or(&raw.top);
        let camera = intrinsics_from_raw(cam, || {
            let first = frames
                .first()
                .ok_or_else(|| bad("camera_angle_x without w, h and no frame to size it".into()))?;
            let img = resolve_image_path(dir, &first.file_path);
            image::image_dimensions(&img)
                .map_err(|e| Error::invalid(&img, format!("cannot read image header: {e}")))
        })
        .map_err(|e| match e {
            Error::Other(msg) => bad(msg),
            other => other,
        })?;

        let events = match raw.events {
            None => None,
            Some(ev) => {
                let c = ev.contrast_threshold;
                if !(c.is_finite() && c > 0.0) {
                    return Err(bad(format!(
                        "events.contrast_threshold {c} must be finite and > 0"
                    )));
                }
                if ev.path.is_empty() {
                    return Err(bad("events.path is empty".into()));
                }
                Some(EventsRef {
                    path: ev.path,
                    contrast_threshold: c,
                })
            }
        };
        Ok(Manifest {
            camera,
            frames,
            events,
            frame_encoding: raw.frame_encoding,
        })
    }

    /// Write atomically in the `camera` object form (pretty JSON; f64 values exactly).
    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        // JSON cannot hold NaN/inf (serde_json would write `null`): refuse them here.
        if let Some((i, f)) = self.frames.iter().enumerate().find(|(_, f)| {
            !(f.timestamp.is_finite() && f.time.is_finite() && f.cam_to_world.matrix().is_finite())
        }) {
            return Err(Error::invalid(
                path,
                format!(
                    "frame {i} ({}): non-finite timestamp, time or pose",
                    f.file_path
                ),
            ));
        }
        let c = &self.camera;
        let cam_values = [c.fx, c.fy, c.cx, c.cy];
        let dist = c
            .distortion
            .map_or([0.0; 5], |d| [d.k1, d.k2, d.p1, d.p2, d.k3]);
        if cam_values.iter().chain(&dist).any(|v| !v.is_finite()) {
            return Err(Error::invalid(path, "camera has non-finite parameters"));
        }
        let d = c.distortion.filter(|d| !d.is_zero());
        let camera = RawCamera {
            w: Some(c.width),
            h: Some(c.height),
            fl_x: Some(c.fx),
            fl_y: Some(c.fy),
            cx: Some(c.cx),
            cy: Some(c.cy),
            camera_angle_x: None,
            k1: d.map(|d| d.k1),
            k2: d.map(|d| d.k2),
            p1: d.map(|d| d.p1),
            p2: d.map(|d| d.p2),
            k3: d.map(|d| d.k3),
        };
        let raw = RawManifest {
            camera: Some(camera),
            top: RawCamera::default(),
            frames: self
                .frames
                .iter()
                .map(|f| RawFrame {
                    file_path: f.file_path.clone(),
                    timestamp: Some(f.timestamp),
                    time: f.time,
                    transform_matrix: f.cam_to_world.matrix().transpose().to_cols_array_2d(),
                })
                .collect(),
            events: self.events.as_ref().map(|e| RawEvents {
                path: e.path.clone(),
                contrast_threshold: e.contrast_threshold,
            }),
            frame_encoding: self.frame_encoding,
        };
        crate::atomic::write_json_atomic(path, &raw)
    }

    /// Frame timestamps and poses as an interpolating trajectory. `Err` if the manifest has
    /// no frames.
    pub fn trajectory(&self) -> std::result::Result<Trajectory, String> {
        Trajectory::new(
            self.frames.iter().map(|f| f.timestamp).collect(),
            self.frames.iter().map(|f| f.cam_to_world).collect(),
        )
    }
}

/// Build intrinsics from the raw fields; `size` supplies (w, h) for the
/// `camera_angle_x` form when the file does not. Field errors come back as `Error::Other`.
fn intrinsics_from_raw(
    c: &RawCamera,
    size: impl FnOnce() -> Result<(u32, u32)>,
) -> Result<Intrinsics> {
    let distortion = {
        let d = Distortion {
            k1: c.k1.unwrap_or(0.0),
            k2: c.k2.unwrap_or(0.0),
            p1: c.p1.unwrap_or(0.0),
            p2: c.p2.unwrap_or(0.0),
            k3: c.k3.unwrap_or(0.0),
        };
        if [d.k1, d.k2, d.p1, d.p2, d.k3]
            .iter()
            .any(|v| !v.is_finite())
        {
            return Err(Error::Other(format!(
                "camera distortion has non-finite coefficients: {d:?}"
            )));
        }
        (!d.is_zero()).then_some(d)
    };
    let mut k = if let (Some(fx), Some(w), Some(h)) = (c.fl_x, c.w, c.h) {
        let fy = c.fl_y.unwrap_or(fx);
        let cx = c.cx.unwrap_or((w as f64 - 1.0) * 0.5);
        let cy = c.cy.unwrap_or((h as f64 - 1.0) * 0.5);
        Intrinsics {
            width: w,
            height: h,
            fx,
            fy,
            cx,
            cy,
            distortion: None,
        }
    } else if let Some(angle) = c.camera_angle_x {
        if !(angle.is_finite() && angle > 0.0 && angle < std::f64::consts::PI) {
            return Err(Error::Other(format!(
                "camera_angle_x {angle} must be in (0, π)"
            )));
        }
        let (w, h) = match (c.w, c.h) {
            (Some(w), Some(h)) => (w, h),
            _ => size()?,
        };
        Intrinsics::from_fov_x(w, h, angle)
    } else {
        return Err(Error::Other(
            "camera needs w, h, fl_x (and optionally fl_y, cx, cy) or camera_angle_x".into(),
        ));
    };
    k.distortion = distortion;
    if k.width == 0 || k.height == 0 {
        return Err(Error::Other(format!(
            "camera size {}x{} is empty",
            k.width, k.height
        )));
    }
    let ok = k.fx.is_finite()
        && k.fy.is_finite()
        && k.fx > 0.0
        && k.fy > 0.0
        && k.cx.is_finite()
        && k.cy.is_finite();
    if !ok {
        return Err(Error::Other(format!(
            "camera focal lengths must be finite and > 0 and the centre finite: fx {} fy {} cx {} cy {}",
            k.fx, k.fy, k.cx, k.cy
        )));
    }
    Ok(k)
}

/// `dir/file_path`, with `.png` appended when the path has no extension.
fn resolve_image_path(dir: &Path, file_path: &str) -> PathBuf {
    let p = dir.join(file_path);
    if p.extension().is_none() {
        p.with_extension("png")
    } else {
        p
    }
}

/// A validated scene directory (DESIGN §3).
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub root: PathBuf,
    pub train: Manifest,
    /// Held-out frames; empty (with the train camera) when `transforms_test.json` is absent.
    pub test: Manifest,
    /// Novel views: held-out frames from cameras off the recorded path (`degs synth`
    /// puts them at the test times); empty (with the train camera) when
    /// `transforms_novel.json` is absent.
    pub novel: Manifest,
}

impl Scene {
    /// Open `dir`: read the manifests and check that the train file has frames, every
    /// image exists with the camera's size (header only), every file uses the same
    /// sensor size, and the events file (if any) exists. The events themselves are read
    /// by [`Scene::load_events`].
    pub fn open(dir: impl AsRef<Path>) -> Result<Scene> {
        let root = dir.as_ref().to_path_buf();
        if !root.is_dir() {
            return Err(Error::invalid(&root, "scene directory does not exist"));
        }
        let train_path = root.join(TRAIN_FILE);
        let train = Manifest::read(&train_path)?;
        if train.frames.is_empty() {
            return Err(Error::invalid(&train_path, "no frames"));
        }
        let (test_path, novel_path) = (root.join(TEST_FILE), root.join(NOVEL_FILE));
        let optional = |path: &Path| -> Result<Manifest> {
            if path.exists() {
                return Manifest::read(path);
            }
            Ok(Manifest {
                camera: train.camera,
                frames: Vec::new(),
                events: None,
                frame_encoding: train.frame_encoding,
            })
        };
        let (test, novel) = (optional(&test_path)?, optional(&novel_path)?);
        let scene = Scene {
            root,
            train,
            test,
            novel,
        };
        let files = [
            (&train_path, &scene.train),
            (&test_path, &scene.test),
            (&novel_path, &scene.novel),
        ];
        for (path, m) in files {
            if (m.camera.width, m.camera.height)
                != (scene.train.camera.width, scene.train.camera.height)
            {
                return Err(Error::invalid(
                    path,
                    format!(
                        "camera is {}x{} but the train camera is {}x{}",
                        m.camera.width,
                        m.camera.height,
                        scene.train.camera.width,
                        scene.train.camera.height
                    ),
                ));
            }
            for (i, f) in m.frames.iter().enumerate() {
                let img = scene.image_path(f);
                if !img.is_file() {
                    return Err(Error::invalid(
                        path,
                        format!("frame {i}: image {} does not exist", img.display()),
                    ));
                }
                let (w, h) = image::image_dimensions(&img).map_err(|e| {
                    Error::invalid(
                        path,
                        format!("frame {i}: cannot read {}: {e}", img.display()),
                    )
                })?;
                if (w, h) != (m.camera.width, m.camera.height) {
                    return Err(Error::invalid(
                        path,
                        format!(
                            "frame {i}: image {} is {w}x{h} but the camera is {}x{}",
                            img.display(),
                            m.camera.width,
                            m.camera.height
                        ),
                    ));
                }
            }
        }
        if let Some(ev) = &scene.train.events {
            let p = scene.root.join(&ev.path);
            if !p.is_file() {
                return Err(Error::invalid(
                    &train_path,
                    format!("events file {} does not exist", p.display()),
                ));
            }
        }
        Ok(scene)
    }

    /// Absolute path of a frame's image.
    pub fn image_path(&self, frame: &Frame) -> PathBuf {
        resolve_image_path(&self.root, &frame.file_path)
    }

    /// Path of the event stream, if the scene has one.
    pub fn events_path(&self) -> Option<PathBuf> {
        self.train.events.as_ref().map(|e| self.root.join(&e.path))
    }

    /// Read the event stream with the camera's sensor size; `Err` when the scene has no
    /// events or the stream's sensor differs from the camera.
    pub fn load_events(&self) -> Result<EventStream> {
        let path = self.events_path().ok_or_else(|| {
            Error::invalid(self.root.join(TRAIN_FILE), "the scene has no events entry")
        })?;
        let cam = &self.train.camera;
        let opts = crate::formats::ReadOptions {
            sensor: Some((cam.width, cam.height)),
            coord_scale: None,
        };
        let ev = crate::formats::read_events(&path, &opts)?;
        if (ev.width, ev.height) != (cam.width, cam.height) {
            return Err(Error::invalid(
                &path,
                format!(
                    "event sensor is {}x{} but the camera is {}x{}",
                    ev.width, ev.height, cam.width, cam.height
                ),
            ));
        }
        Ok(ev)
    }

    /// Contrast threshold C of the events ([`DEFAULT_CONTRAST_THRESHOLD`] if none given).
    pub fn contrast_threshold(&self) -> f64 {
        self.train
            .events
            .as_ref()
            .map_or(DEFAULT_CONTRAST_THRESHOLD, |e| e.contrast_threshold)
    }

    /// Camera trajectory through the train frames (timestamps in seconds).
    pub fn train_trajectory(&self) -> Trajectory {
        // `open` checked: at least one frame, strictly increasing timestamps.
        Trajectory {
            times: self.train.frames.iter().map(|f| f.timestamp).collect(),
            poses: self.train.frames.iter().map(|f| f.cam_to_world).collect(),
        }
    }

    /// The train camera at a frame's pose.
    pub fn camera(&self, frame: &Frame) -> crate::camera::Camera {
        crate::camera::Camera {
            intrinsics: self.train.camera,
            cam_to_world: frame.cam_to_world,
        }
    }
}
