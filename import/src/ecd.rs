//! The Event Camera Dataset layout (Mueggler et al., IJRR 2017; rpg_dvs_ros exports):
//!
//! ```text
//! SRC/calib.txt        fx fy cx cy [k1 k2 p1 p2 k3]   (OpenCV radial-tangential)
//! SRC/images.txt       t images/frame_00000000.png    (one frame per line, seconds)
//! SRC/images/          the APS frames (8-bit grey PNG)
//! SRC/events.txt       t x y p                        (p ∈ {0, 1}; distorted pixels)
//! SRC/groundtruth.txt  t px py pz qx qy qz qw         (camera-to-world, OpenCV axes)
//! ```
//!
//! All times are seconds on one clock. The ground-truth pose is the camera's pose in
//! the motion-capture world, its camera frame the optical frame of OpenCV (x right,
//! y down, z forward); [`crate::convention`] turns it into the manifest's OpenGL axes.
//! Poses are interpolated to the frame times (translation lerp, rotation slerp between
//! the two nearest ground-truth samples). A frame outside the ground truth's time span
//! (no extrapolation), or more than half a median frame interval outside the events'
//! span, is dropped with a warning. The frames keep their
//! distortion (the camera model has the same 5 coefficients) and their grey PNG bytes;
//! they are the DAVIS APS readout, linear in irradiance, so the scene says
//! `frame_encoding: linear` unless `--frame-encoding` says otherwise.

use crate::convention::{opencv_to_opengl, opengl_to_opencv};
use crate::recording::{FrameImage, Recording, SourceFrame};
use crate::table::{check_increasing, number, read_text, rows};
use glam::{DQuat, DVec3};
use scene::atomic::{AtomicDir, OutputRule, write_bytes_atomic};
use scene::error::{Error, IoContext, Result};
use scene::formats::ReadOptions;
use scene::manifest::FrameEncoding;
use scene::{Distortion, Intrinsics, Pose, Scene, Trajectory};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

pub(crate) const CALIB: &str = "calib.txt";
pub(crate) const IMAGES: &str = "images.txt";
pub const EVENTS: &str = "events.txt";
pub(crate) const GROUNDTRUTH: &str = "groundtruth.txt";

/// Read an ECD recording (layout in the module doc).
pub fn read_ecd(src: &Path) -> Result<Recording> {
    for name in [CALIB, IMAGES, EVENTS, GROUNDTRUTH] {
        let p = src.join(name);
        if !p.is_file() {
            return Err(Error::invalid(
                &p,
                format!(
                    "missing: the ECD layout needs {CALIB}, {IMAGES} (+ images/), {EVENTS} and {GROUNDTRUTH}"
                ),
            ));
        }
    }
    let frames = read_images_txt(src)?;
    let first = &frames[0].1;
    let (w, h) = image::image_dimensions(first)
        .map_err(|e| Error::invalid(first, format!("cannot read image header: {e}")))?;
    let camera = read_calib(&src.join(CALIB), w, h)?;
    let events = scene::formats::read_text(
        src.join(EVENTS),
        &ReadOptions {
            sensor: Some((w, h)),
            coord_scale: None,
        },
    )?;
    let gt = read_groundtruth(&src.join(GROUNDTRUTH))?;
    let (g0, g1) = (gt.times[0], gt.times[gt.times.len() - 1]);
    let (e0, e1) = match (events.t.first(), events.t.last()) {
        (Some(&a), Some(&b)) => (a, b),
        _ => return Err(Error::invalid(src.join(EVENTS), "no events")),
    };
    // Events "cover" a frame up to half a (median) frame interval beyond their span:
    // the simulator's or sensor's first event comes a little after the first frame.
    let times: Vec<f64> = frames.iter().map(|f| f.0).collect();
    let slack = 0.5 * scene::manifest::median_interval(&times);
    let (c0, c1) = (e0 - slack, e1 + slack);
    let mut warnings = Vec::new();
    let mut out = Vec::new();
    let (mut no_pose, mut no_events) = (0, 0);
    for (t, path) in frames.iter() {
        if *t < g0 || *t > g1 {
            no_pose += 1;
        } else if *t < c0 || *t > c1 {
            no_events += 1;
        } else {
            out.push(SourceFrame {
                image: FrameImage::File(path.clone()),
                timestamp: *t,
                pose: gt.pose_at(*t),
            });
        }
    }
    if no_pose > 0 {
        warnings.push(format!(
            "{no_pose} of {} frames lie outside the ground truth's {g0} … {g1} s and were left out",
            frames.len()
        ));
    }
    if no_events > 0 {
        warnings.push(format!(
            "{no_events} of {} frames lie more than half a frame interval outside the events' {e0} … {e1} s and were left out",
            frames.len()
        ));
    }
    if out.is_empty() {
        return Err(Error::invalid(
            src.join(IMAGES),
            format!(
                "no frame lies inside both the ground truth ({g0} … {g1} s) and the events ({e0} … {e1} s)"
            ),
        ));
    }
    Ok(Recording {
        layout: "ecd",
        camera,
        frames: out,
        events,
        frame_encoding: FrameEncoding::Linear,
        warnings,
        held_out: None,
    })
}

/// `images.txt`: (timestamp, absolute image path) per frame, times increasing.
fn read_images_txt(src: &Path) -> Result<Vec<(f64, PathBuf)>> {
    let path = src.join(IMAGES);
    let text = read_text(&path)?;
    let rows = rows(&path, &text, 2, 2)?;
    if rows.is_empty() {
        return Err(Error::invalid(&path, "no frames listed"));
    }
    let mut out = Vec::with_capacity(rows.len());
    for r in &rows {
        let t = number(&path, r, 0, "timestamp")?;
        let img = src.join(r.fields[1]);
        if !img.is_file() {
            return Err(Error::invalid(
                &path,
                format!("line {}: image {} does not exist", r.line, img.display()),
            ));
        }
        out.push((t, img));
    }
    let times: Vec<f64> = out.iter().map(|f| f.0).collect();
    check_increasing(&path, &rows, &times)?;
    Ok(out)
}

/// The camera of `calib` (ECD `calib.txt`), or without one a guess (fx = fy = width,
/// centre at the image centre) with a warning saying so.
pub(crate) fn calib_or_guess(
    calib: Option<&Path>,
    w: u32,
    h: u32,
    warnings: &mut Vec<String>,
) -> Result<Intrinsics> {
    if let Some(c) = calib {
        return read_calib(c, w, h);
    }
    warnings.push(format!(
        "no calibration: assumed fx = fy = {w} px, centre at the image centre (pass --calib calib.txt)"
    ));
    Ok(Intrinsics {
        width: w,
        height: h,
        fx: w as f64,
        fy: w as f64,
        cx: (w as f64 - 1.0) * 0.5,
        cy: (h as f64 - 1.0) * 0.5,
        distortion: None,
    })
}

/// `calib.txt`: `fx fy cx cy` and optionally `k1 k2 p1 p2 k3` (missing ones are 0).
pub fn read_calib(path: &Path, width: u32, height: u32) -> Result<Intrinsics> {
    let text = read_text(path)?;
    let rows = rows(path, &text, 4, 9)?;
    let [r] = rows.as_slice() else {
        return Err(Error::invalid(
            path,
            format!("{} data lines, expected one", rows.len()),
        ));
    };
    let names = ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"];
    let mut v = [0.0; 9];
    for (k, name) in names.iter().enumerate().take(r.fields.len()) {
        v[k] = number(path, r, k, name)?;
    }
    if !(v[0] > 0.0 && v[1] > 0.0) {
        return Err(Error::invalid(
            path,
            format!("focal lengths fx {} fy {} must be > 0", v[0], v[1]),
        ));
    }
    let d = Distortion {
        k1: v[4],
        k2: v[5],
        p1: v[6],
        p2: v[7],
        k3: v[8],
    };
    Ok(Intrinsics {
        width,
        height,
        fx: v[0],
        fy: v[1],
        cx: v[2],
        cy: v[3],
        distortion: (!d.is_zero()).then_some(d),
    })
}

/// `groundtruth.txt` as a trajectory in the manifest's axes.
pub(crate) fn read_groundtruth(path: &Path) -> Result<Trajectory> {
    let text = read_text(path)?;
    let rows = rows(path, &text, 8, 8)?;
    if rows.is_empty() {
        return Err(Error::invalid(path, "no poses"));
    }
    let names = ["timestamp", "px", "py", "pz", "qx", "qy", "qz", "qw"];
    let mut times = Vec::with_capacity(rows.len());
    let mut poses = Vec::with_capacity(rows.len());
    for r in &rows {
        let mut v = [0.0; 8];
        for (k, name) in names.iter().enumerate() {
            v[k] = number(path, r, k, name)?;
        }
        let q = DQuat::from_xyzw(v[4], v[5], v[6], v[7]);
        let norm = q.length();
        if !(0.5..=2.0).contains(&norm) {
            return Err(Error::invalid(
                path,
                format!(
                    "line {}: quaternion norm {norm} is far from 1 (expected qx qy qz qw)",
                    r.line
                ),
            ));
        }
        times.push(v[0]);
        let cv = Pose::new(q / norm, DVec3::new(v[1], v[2], v[3]));
        poses.push(opencv_to_opengl(cv));
    }
    check_increasing(path, &rows, &times)?;
    Trajectory::new(times, poses).map_err(|m| Error::invalid(path, m))
}

/// Write `scene` (train and test frames merged in time order, its events, its camera)
/// in the ECD layout at `out`; the ground truth holds the frames' poses plus
/// `extra_poses` (camera-to-world, manifest axes; those at a frame's time are skipped).
/// The inverse of [`read_ecd`] for tests and for handing scenes to ECD tools.
pub fn export_ecd(scene: &Scene, extra_poses: &[(f64, Pose)], out: &Path) -> Result<()> {
    let dir = AtomicDir::new(out, &OutputRule::new("export"))?;
    let root = dir.path();
    let frames = crate::recording::frames_by_time(scene);
    let mut images = String::from("# timestamp filename\n");
    let mut poses: Vec<(f64, Pose)> = Vec::new();
    for (k, f) in frames.iter().enumerate() {
        let src = scene.image_path(f);
        let ext = src
            .extension()
            .map_or("png".into(), |e| e.to_string_lossy());
        let rel = format!("images/frame_{k:08}.{ext}");
        let bytes = std::fs::read(&src).at(&src)?;
        write_bytes_atomic(&root.join(&rel), &bytes)?;
        let _ = writeln!(images, "{} {rel}", f.timestamp);
        poses.push((f.timestamp, f.cam_to_world));
    }
    poses.extend(
        extra_poses
            .iter()
            .filter(|(t, _)| !frames.iter().any(|f| f.timestamp == *t)),
    );
    poses.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut gt = String::from("# timestamp tx ty tz qx qy qz qw\n");
    for (t, p) in &poses {
        let cv = opengl_to_opencv(*p);
        let (q, c) = (cv.rotation, cv.translation);
        let _ = writeln!(
            gt,
            "{t} {} {} {} {} {} {} {}",
            c.x, c.y, c.z, q.x, q.y, q.z, q.w
        );
    }
    let k = &scene.train.camera;
    let d = k.distortion.unwrap_or_default();
    let calib = format!(
        "{} {} {} {} {} {} {} {} {}\n",
        k.fx, k.fy, k.cx, k.cy, d.k1, d.k2, d.p1, d.p2, d.k3
    );
    let ev = scene.load_events()?;
    let mut events = String::with_capacity(ev.len() * 24);
    for i in 0..ev.len() {
        let p = u8::from(ev.p[i] > 0);
        let _ = writeln!(events, "{} {} {} {p}", ev.t[i], ev.x[i], ev.y[i]);
    }
    write_bytes_atomic(&root.join(IMAGES), images.as_bytes())?;
    write_bytes_atomic(&root.join(GROUNDTRUTH), gt.as_bytes())?;
    write_bytes_atomic(&root.join(CALIB), calib.as_bytes())?;
    write_bytes_atomic(&root.join(EVENTS), events.as_bytes())?;
    dir.commit()?;
    Ok(())
}
