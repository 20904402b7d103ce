//! A COLMAP sparse model for the RGB frames, with an event file and the frames' times:
//!
//! ```text
//! SRC/sparse/0/  (else SRC/sparse/, else SRC)   cameras, images, points3D: .bin or .txt
//! SRC/images/NAME                               each registered image, as images.* names it
//! SRC/events.{evs,txt,npz,aedat4,raw,es}        or --events FILE
//! SRC/timestamps.txt                            or --timestamps FILE: `NAME SECONDS` lines;
//!                                               without one, the last number in each
//!                                               image's file name × --name-seconds
//! ```
//!
//! COLMAP stores each image's world → camera transform `x_c = R x_w + t` (quaternion
//! `qw qx qy qz`, then `t`) in OpenCV camera axes, so its camera → world pose is `(Rᵀ,
//! −Rᵀt)`, flipped to the manifest's OpenGL axes by [`crate::convention`]. COLMAP puts
//! the centre of the top-left pixel at (½, ½), degs at (0, 0): `cx = cx_colmap − ½`.
//! Camera models: SIMPLE_PINHOLE, PINHOLE, and the radial-tangential ones that are the
//! OpenCV model with fewer terms (SIMPLE_RADIAL, RADIAL, OPENCV); the others (fisheye,
//! FOV, thin prism, full OpenCV's rational terms) are refused by name. The images must
//! share one camera. Images COLMAP did not register have no pose and are left out (a
//! warning counts them when the images folder holds more). COLMAP's world has an
//! arbitrary origin and unit: the import moves the median of its 3D points to the
//! origin and scales it so the cameras are [`SCENE_DISTANCE`] from there (said in the
//! summary), which is where the warm-up looks for the scene when the cameras' axes are
//! nearly parallel (`gaussians::train::init::camera_bounds`).

use crate::aligned::{EventsAlignment, event_file, read_for_sensor};
use crate::colmap_files::model_params;
pub use crate::colmap_files::{ColmapCamera, ColmapImage, ColmapModel, ColmapOptions};
use crate::recording::{FrameImage, Recording, SourceFrame};
use glam::{DQuat, DVec3};
use scene::camera::Distortion;
use scene::error::{Error, Result};
use scene::manifest::FrameEncoding;
use scene::{Intrinsics, Pose};
use std::path::{Path, PathBuf};

impl ColmapModel {
    /// The folder with the model: `sparse/0`, else `sparse`, else `src` itself.
    pub fn find(src: &Path) -> Result<PathBuf> {
        let has = |d: &Path| d.join("cameras.bin").is_file() || d.join("cameras.txt").is_file();
        [src.join("sparse/0"), src.join("sparse"), src.to_path_buf()]
            .into_iter()
            .find(|d| has(d))
            .ok_or_else(|| {
                Error::invalid(
                    src,
                    "no COLMAP model: no cameras.bin or cameras.txt in sparse/0/, sparse/ or here",
                )
            })
    }

    /// Read `dir`'s model: the binary files when `cameras.bin` is there, else the text.
    pub fn read(dir: &Path) -> Result<ColmapModel> {
        if dir.join("cameras.bin").is_file() {
            crate::colmap_files::read_bin(dir)
        } else {
            crate::colmap_files::read_txt(dir)
        }
    }
}

/// Write `model` as COLMAP text files in `dir` (no 2D points, empty tracks): the
/// exporter of the round-trip tests.
pub fn write_txt(model: &ColmapModel, dir: &Path) -> Result<()> {
    crate::colmap_files::write_txt(model, dir)
}

/// The camera's intrinsics in degs' convention (pixel centres at integers).
pub fn intrinsics(cam: &ColmapCamera, file: &Path) -> Result<Intrinsics> {
    let p = &cam.params;
    let dist = |k1, k2, p1, p2| Distortion {
        k1,
        k2,
        p1,
        p2,
        k3: 0.0,
    };
    let (fx, fy, cx, cy, d) = match (cam.model.as_str(), p.len()) {
        ("SIMPLE_PINHOLE", 3) => (p[0], p[0], p[1], p[2], None),
        ("PINHOLE", 4) => (p[0], p[1], p[2], p[3], None),
        ("SIMPLE_RADIAL", 4) => (p[0], p[0], p[1], p[2], Some(dist(p[3], 0.0, 0.0, 0.0))),
        ("RADIAL", 5) => (p[0], p[0], p[1], p[2], Some(dist(p[3], p[4], 0.0, 0.0))),
        ("OPENCV", 8) => (p[0], p[1], p[2], p[3], Some(dist(p[4], p[5], p[6], p[7]))),
        (m, n) if model_params(m).is_some_and(|(_, k)| k == n) => {
            return Err(Error::invalid(
                file,
                format!(
                    "camera {}: model {m} is not supported (SIMPLE_PINHOLE, PINHOLE, \
                     SIMPLE_RADIAL, RADIAL or OPENCV); undistort the images first \
                     (`colmap image_undistorter` writes a PINHOLE model)",
                    cam.id
                ),
            ));
        }
        (m, n) => {
            return Err(Error::invalid(
                file,
                format!("camera {}: model {m} with {n} parameters", cam.id),
            ));
        }
    };
    if !(fx > 0.0 && fy > 0.0 && [cx, cy].iter().all(|v| v.is_finite())) {
        return Err(Error::invalid(
            file,
            format!("camera {}: focal lengths {fx}, {fy}", cam.id),
        ));
    }
    Ok(Intrinsics {
        width: cam.width,
        height: cam.height,
        fx,
        fy,
        cx: cx - 0.5,
        cy: cy - 0.5,
        distortion: d.filter(|d| !d.is_zero()),
    })
}

/// The image's camera → world pose in the manifest's OpenGL axes.
pub fn pose(img: &ColmapImage) -> Pose {
    let [w, x, y, z] = img.q;
    let r = DQuat::from_xyzw(x, y, z, w).normalize();
    let t = DVec3::from_array(img.t);
    let inv = r.inverse();
    crate::convention::opencv_to_opengl(Pose::new(inv, -(inv * t)))
}

/// The median distance from the cameras to the scene's centre after the import.
pub const SCENE_DISTANCE: f64 = 3.0;

/// The similarity the import applies to COLMAP's world, `x ↦ scale·(x − centre)`: the
/// centre is the per-axis median of the 3D points (robust to stray ones), the scale
/// brings the median camera distance to it to [`SCENE_DISTANCE`]. None without points.
pub fn normalisation(model: &ColmapModel, poses: &[Pose]) -> Option<(DVec3, f64)> {
    if model.points.is_empty() || poses.is_empty() {
        return None;
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let axis = |k: usize| median(model.points.iter().map(|(p, _)| p[k]).collect());
    let centre = DVec3::new(axis(0), axis(1), axis(2));
    let d = median(
        poses
            .iter()
            .map(|p| (p.translation - centre).length())
            .collect(),
    );
    (d > 0.0 && d.is_finite()).then(|| (centre, SCENE_DISTANCE / d))
}

/// Read SRC (layout above) into a recording.
pub(crate) fn read_colmap(src: &Path, o: &ColmapOptions) -> Result<Recording> {
    let dir = ColmapModel::find(src)?;
    let model = ColmapModel::read(&dir)?;
    let cameras_file = dir.join("cameras");
    let Some(first) = model.images.first() else {
        return Err(Error::invalid(&dir, "the model has no registered images"));
    };
    if let Some(other) = model.images.iter().find(|i| i.camera_id != first.camera_id) {
        return Err(Error::invalid(
            &dir,
            format!(
                "images {} and {} use different cameras ({} and {}): degs takes one camera",
                first.name, other.name, first.camera_id, other.camera_id
            ),
        ));
    }
    let cam = (model.cameras.iter())
        .find(|c| c.id == first.camera_id)
        .ok_or_else(|| {
            Error::invalid(&dir, format!("no camera {} in cameras.*", first.camera_id))
        })?;
    let camera = intrinsics(cam, &cameras_file)?;
    let times = crate::colmap_files::timestamps(src, o, &model.images)?;
    let poses: Vec<Pose> = model.images.iter().map(pose).collect();
    let (centre, scale) = normalisation(&model, &poses).ok_or_else(|| {
        Error::invalid(
            &dir,
            "no 3D points in front of the cameras: cannot place the scene",
        )
    })?;
    let mut warnings = vec![format!(
        "COLMAP's world is moved by −({:.4}, {:.4}, {:.4}) and scaled by {scale:.6}: the \
         scene's centre (the median of its 3D points) at the origin, the cameras {SCENE_DISTANCE} \
         units from it (COLMAP's unit is arbitrary; the defaults were tuned at that size)",
        centre.x, centre.y, centre.z
    )];
    let mut frames: Vec<SourceFrame> = (model.images.iter().zip(&times).zip(&poses))
        .map(|((img, &timestamp), p)| SourceFrame {
            image: FrameImage::File(src.join("images").join(&img.name)),
            timestamp,
            pose: Pose::new(p.rotation, scale * (p.translation - centre)),
        })
        .collect();
    frames.sort_by(|a, b| a.timestamp.total_cmp(&b.timestamp));
    if let Some(w) = frames.windows(2).find(|w| w[1].timestamp <= w[0].timestamp) {
        return Err(Error::invalid(
            src,
            format!("two images at the same time {} s", w[0].timestamp),
        ));
    }
    for f in &frames {
        if let FrameImage::File(p) = &f.image
            && !p.is_file()
        {
            return Err(Error::invalid(
                p,
                "the model names this image, which is not there",
            ));
        }
    }
    let on_disk = std::fs::read_dir(src.join("images")).map_or(0, |d| d.count());
    if on_disk > frames.len() {
        warnings.push(format!(
            "{} of {on_disk} files in images/ are not registered in the model (no pose): left out",
            on_disk - frames.len()
        ));
    }
    let alignment = EventsAlignment {
        events: o.events.clone(),
        ..EventsAlignment::default()
    };
    let events_path = event_file(src, &alignment, None, &dir.join("images"))?;
    let events = read_for_sensor(&events_path, camera.width, camera.height)?;
    Ok(Recording {
        layout: "colmap",
        camera,
        frames,
        events,
        frame_encoding: FrameEncoding::Srgb,
        warnings,
        held_out: None,
    })
}
