//! `degs import colmap` against a model COLMAP itself built (`testdata/colmap_static/`:
//! COLMAP 3.8's feature_extractor (PINHOLE, one camera), exhaustive_matcher and mapper on
//! the 21 frames of `degs synth --preset static --set width=320 --set height=240 --set
//! train_fps=12 --set novel_angle_deg=0`; 21 of 21 registered, 0.36 px reprojection
//! error). After the similarity that best maps COLMAP's world onto the scene's, every
//! imported pose must be within 1° and 1 % of the camera's distance to the scene of the
//! ground truth, and the intrinsics those of the synthetic camera.

mod common;
use glam::{DQuat, DVec3};
use import::colmap::{ColmapModel, write_txt};
use import::{ImportOptions, Layout, import};
use scene::Scene;
use scene::events::EventStream;
use scene::manifest::Manifest;
use std::path::{Path, PathBuf};

fn fixture() -> PathBuf {
    testkit::testdata::shared_data("colmap_static")
}

/// SRC for `degs import colmap`: the model, the frames rendered again from the scene's
/// settings (the poses come from the model; the images are copied), the timestamps and a
/// few events over the recording.
fn source(dir: &Path, model_files: &Path, with_frames: bool) -> PathBuf {
    let cfg: synth::SynthConfig =
        serde_json::from_str(&std::fs::read_to_string(fixture().join("synth.json")).unwrap())
            .unwrap();
    let frames = dir.join("frames");
    if with_frames && !frames.exists() {
        synth::write_rgb_synthetic_scene(&cfg, &frames).unwrap();
    }
    let src = dir.join(format!(
        "src-{}",
        model_files.file_name().unwrap().to_string_lossy()
    ));
    std::fs::create_dir_all(src.join("sparse/0")).unwrap();
    for e in std::fs::read_dir(model_files).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), src.join("sparse/0").join(e.file_name())).unwrap();
    }
    std::fs::create_dir_all(src.join("images")).unwrap();
    for e in std::fs::read_dir(frames.join("images"))
        .into_iter()
        .flatten()
    {
        let e = e.unwrap();
        std::fs::copy(e.path(), src.join("images").join(e.file_name())).unwrap();
    }
    std::fs::copy(fixture().join("timestamps.txt"), src.join("timestamps.txt")).unwrap();
    let n = 200;
    let ev = EventStream {
        width: cfg.width,
        height: cfg.height,
        t: (0..n).map(|k| k as f64 / n as f64).collect(),
        x: (0..n).map(|k| (k % cfg.width as usize) as u16).collect(),
        y: (0..n).map(|k| (k % cfg.height as usize) as u16).collect(),
        p: (0..n).map(|k| if k % 2 == 0 { 1 } else { -1 }).collect(),
    };
    scene::formats::evs::write_evs(src.join("events.evs"), &ev).unwrap();
    src
}

/// The ground truth's poses by timestamp.
fn truth() -> Vec<(f64, scene::Pose)> {
    let mut v: Vec<(f64, scene::Pose)> = ["transforms_train.json", "transforms_test.json"]
        .iter()
        .flat_map(|f| Manifest::read(fixture().join(f)).unwrap().frames)
        .map(|f| (f.timestamp, f.cam_to_world))
        .collect();
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    v
}

/// The imported scene's poses by timestamp.
fn imported(out: &Path) -> Vec<(f64, scene::Pose)> {
    let s = Scene::open(out).unwrap();
    let mut v: Vec<(f64, scene::Pose)> = (s.train.frames.iter().chain(&s.test.frames))
        .map(|f| (f.timestamp, f.cam_to_world))
        .collect();
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    v
}

/// The similarity `x ↦ s·R·x + t` taking `from` onto `to`: R the mean of the per-camera
/// rotations `R_to · R_fromᵀ` (quaternions, signs aligned), then s and t by least squares
/// on the camera centres.
fn align(from: &[scene::Pose], to: &[scene::Pose]) -> (f64, DQuat, DVec3) {
    let q0 = to[0].rotation * from[0].rotation.inverse();
    let sum = (from.iter().zip(to)).fold(glam::DVec4::ZERO, |acc, (a, b)| {
        let q = b.rotation * a.rotation.inverse();
        let q = if q.dot(q0) < 0.0 { -q } else { q };
        acc + glam::DVec4::new(q.x, q.y, q.z, q.w)
    });
    let r = DQuat::from_vec4(sum).normalize();
    let n = from.len() as f64;
    let ca = from.iter().map(|p| p.translation).sum::<DVec3>() / n;
    let cb = to.iter().map(|p| p.translation).sum::<DVec3>() / n;
    let (mut num, mut den) = (0.0, 0.0);
    for (a, b) in from.iter().zip(to) {
        let ra = r * (a.translation - ca);
        num += ra.dot(b.translation - cb);
        den += ra.length_squared();
    }
    let s = num / den;
    (s, r, cb - s * (r * ca))
}

#[test]
fn a_model_colmap_built_imports_within_a_degree_and_a_percent() {
    let dir = tempfile::tempdir().unwrap();
    let src = source(dir.path(), &fixture().join("sparse/0"), true);
    let out = dir.path().join("scene");
    let summary = import(Layout::Colmap, &src, &ImportOptions::default(), &out).unwrap();
    assert_eq!(summary.frames, 21, "{summary}");
    let (got, want) = (imported(&out), truth());
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(&want) {
        assert_eq!(g.0, w.0, "timestamps from timestamps.txt");
    }
    // COLMAP's arbitrary world is brought to the origin at the scene and cameras 3 units
    // from it (the median of the points; the median camera distance).
    let mut d: Vec<f64> = got.iter().map(|g| g.1.translation.length()).collect();
    d.sort_by(f64::total_cmp);
    assert!(
        (d[d.len() / 2] - import::colmap::SCENE_DISTANCE).abs() < 1e-9,
        "{d:?}"
    );
    assert!(
        summary.warnings.iter().any(|w| w.contains("scaled by")),
        "{summary}"
    );
    let from: Vec<_> = got.iter().map(|g| g.1).collect();
    let to: Vec<_> = want.iter().map(|w| w.1).collect();
    let (s, r, t) = align(&from, &to);
    // The scene's size: the ground-truth camera's distance to what it looks at.
    let cfg: synth::SynthConfig =
        serde_json::from_str(&std::fs::read_to_string(fixture().join("synth.json")).unwrap())
            .unwrap();
    let size = (cfg.camera.eye - cfg.camera.target).length();
    let (mut worst_deg, mut worst_pos) = (0.0f64, 0.0f64);
    for (a, b) in from.iter().zip(&to) {
        let rot = (r * a.rotation).angle_between(b.rotation).to_degrees();
        let pos = (s * (r * a.translation) + t - b.translation).length() / size;
        (worst_deg, worst_pos) = (worst_deg.max(rot), worst_pos.max(pos));
    }
    eprintln!(
        "COLMAP → truth: scale {s:.4}, worst rotation {worst_deg:.3}°, worst position {:.3} % of {size:.2}",
        100.0 * worst_pos
    );
    assert!(worst_deg < 1.0, "{worst_deg}°");
    assert!(worst_pos < 0.01, "{} %", 100.0 * worst_pos);
    // Intrinsics: COLMAP keeps the principal point at the image centre, (160, 120) in its
    // pixel convention = (159.5, 119.5) in degs'; the focal length is refined.
    let cam = Scene::open(&out).unwrap().train.camera;
    let true_f = 0.5 * cfg.width as f64 / (0.5 * cfg.fov_x_deg.to_radians()).tan();
    assert_eq!(
        (cam.width, cam.height, cam.cx, cam.cy),
        (320, 240, 159.5, 119.5)
    );
    assert!(
        (cam.fx / true_f - 1.0).abs() < 0.02,
        "fx {} vs {true_f}",
        cam.fx
    );
    assert!(cam.distortion.is_none());

    // The text files say the same: the binary model written as text and imported again.
    let model = ColmapModel::read(&fixture().join("sparse/0")).unwrap();
    assert_eq!((model.cameras.len(), model.images.len()), (1, 21));
    assert!(model.points.len() > 1000, "{}", model.points.len());
    let txt = dir.path().join("txt");
    std::fs::create_dir_all(&txt).unwrap();
    write_txt(&model, &txt).unwrap();
    assert_eq!(ColmapModel::read(&txt).unwrap(), model);
    let out_txt = dir.path().join("scene-txt");
    import(
        Layout::Colmap,
        &source(dir.path(), &txt, true),
        &ImportOptions::default(),
        &out_txt,
    )
    .unwrap();
    for (a, b) in imported(&out).iter().zip(imported(&out_txt)) {
        assert_eq!(a.0, b.0);
        assert!((a.1.translation - b.1.translation).length() < 1e-12);
        assert!(a.1.rotation.angle_between(b.1.rotation) < 1e-12);
    }
}

#[test]
fn unsupported_camera_models_and_truncated_files_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let mut model = ColmapModel::read(&fixture().join("sparse/0")).unwrap();
    model.cameras[0].model = "OPENCV_FISHEYE".into();
    model.cameras[0].params = vec![277.0, 277.0, 160.0, 120.0, 0.1, 0.0, 0.0, 0.0];
    let txt = dir.path().join("fisheye");
    std::fs::create_dir_all(&txt).unwrap();
    write_txt(&model, &txt).unwrap();
    let e = import(
        Layout::Colmap,
        &source(dir.path(), &txt, false),
        &ImportOptions::default(),
        &dir.path().join("out"),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("OPENCV_FISHEYE is not supported"), "{e}");
    // A binary images file cut short names the file and the byte.
    let cut = dir.path().join("cut");
    std::fs::create_dir_all(&cut).unwrap();
    for f in ["cameras.bin", "points3D.bin"] {
        std::fs::copy(fixture().join("sparse/0").join(f), cut.join(f)).unwrap();
    }
    let bytes = std::fs::read(fixture().join("sparse/0/images.bin")).unwrap();
    std::fs::write(cut.join("images.bin"), &bytes[..bytes.len() / 2]).unwrap();
    let e = ColmapModel::read(&cut).unwrap_err().to_string();
    assert!(e.contains("images.bin") && e.contains("truncated"), "{e}");
}
