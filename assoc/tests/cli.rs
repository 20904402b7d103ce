//! The `assoc` binary end to end (issue: assoc, item 2): a tiny hand-built scene (a
//! textured patch of Gaussians on the plane z = 0 in front of a slowly moving camera,
//! events placed at known pixels and times) and a static model whose depth maps it
//! renders itself go in; the output directory, its `report.json` figures and the exit
//! status of bad inputs are checked.

use stagekit::help::flag_help;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use assoc::read_assoc;
use gaussians::model::{Model, ModelInfo};
use gaussians::{Gaussian, Splats};
use glam::DVec3;
use scene::formats::write_evs;
use scene::image_io::{Image, read_exr_depth, write_exr_depth, write_png};
use scene::manifest::{EventsRef, Frame, Manifest, TRAIN_FILE};
use scene::{EventStream, Intrinsics, Pose, Scene};

const W: u32 = 48;
const H: u32 = 32;
/// Train frame times (seconds); `time` = timestamp / DURATION.
const TIMES: [f64; 3] = [0.1, 0.2, 0.3];
const DURATION: f64 = 0.4;
/// Events per frame window: every 3rd pixel in x and y.
const PER_WINDOW: usize = 16 * 11;
/// Events between windows (|t − t0| > δt for every frame).
const BETWEEN: usize = 40;

/// Gaussians on a 0.1 grid of the patch |x| ≤ 1.2, |y| ≤ 0.8 of the plane z = 0; the
/// camera (4 units away, ≈ 11 px per unit) sees it with a background border.
fn plane_model() -> Model {
    let mut s = Splats::default();
    for j in -8..=8 {
        for i in -12..=12 {
            let mean = [i as f32 * 0.1, j as f32 * 0.1, 0.0];
            s.push(Gaussian::isotropic(mean, 0.06f32.ln(), 4.0, [0.5; 3]));
        }
    }
    let info = ModelInfo {
        sh_degree: 0,
        gaussians: s.len(),
        ..Default::default()
    };
    Model {
        splats: s,
        field: None,
        info,
    }
}

/// Writes the scene (manifest, images, events) and returns the event stream.
fn write_scene(dir: &Path) -> EventStream {
    std::fs::create_dir_all(dir.join("images")).unwrap();
    let mut frames = Vec::new();
    for (i, &t) in TIMES.iter().enumerate() {
        let file_path = format!("images/train_{i:04}.png");
        let mut img = Image::new(W, H, 3);
        for (p, v) in img.data.iter_mut().enumerate() {
            *v = ((p * 7 + i) % 11) as f32 / 10.0;
        }
        write_png(dir.join(&file_path), &img).unwrap();
        let eye = DVec3::new(0.05 * i as f64, 0.0, 4.0);
        frames.push(Frame {
            file_path,
            timestamp: t,
            time: t / DURATION,
            cam_to_world: Pose::look_at(eye, DVec3::new(eye.x, 0.0, 0.0), DVec3::Y),
        });
    }
    let mut ev = EventStream::new(W, H);
    for &t0 in &TIMES {
        let mut j = 0;
        for v in (0..H as u16).step_by(3) {
            for u in (0..W as u16).step_by(3) {
                // Spread over [t0 − 8 ms, t0 + 8 ms), inside δt = 10 ms.
                let t = t0 - 0.008 + 0.016 * j as f64 / PER_WINDOW as f64;
                ev.push(t, u, v, if j % 2 == 0 { 1 } else { -1 });
                j += 1;
            }
        }
        assert_eq!(j, PER_WINDOW);
        for k in 0..BETWEEN {
            let t = t0 + 0.03 + 0.04 * k as f64 / BETWEEN as f64;
            ev.push(
                t,
                (k * 5 % W as usize) as u16,
                (k * 3 % H as usize) as u16,
                1,
            );
        }
    }
    ev.sort_by_time();
    write_evs(dir.join("events.evs"), &ev).unwrap();
    Manifest {
        camera: Intrinsics::from_fov_x(W, H, 1.0),
        frames,
        events: Some(EventsRef {
            path: "events.evs".into(),
            contrast_threshold: 0.2,
        }),
        frame_encoding: None,
    }
    .write(dir.join(TRAIN_FILE))
    .unwrap();
    ev
}

/// Alpha-normalised depth (0 where alpha < 0.5), as the warm-up writes it.
fn write_depths(model: &Model, scene: &Scene, dir: &Path) {
    std::fs::create_dir_all(dir.join("depth")).unwrap();
    for (i, frame) in scene.train.frames.iter().enumerate() {
        let f = model.render(&scene.camera(frame), frame.time as f32);
        let depth: Vec<f32> = f
            .depth
            .iter()
            .zip(&f.alpha)
            .map(|(&d, &a)| if a >= 0.5 { d / a } else { 0.0 })
            .collect();
        let path = assoc::stage::depth_path(dir, i);
        write_exr_depth(&path, f.width as u32, f.height as u32, &depth).unwrap();
    }
}

fn assoc(scene: &Path, model: &Path, out: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_assoc"))
        .arg("--scene")
        .arg(scene)
        .arg("--model")
        .arg(model)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap()
}

/// Entries of `dir` whose name starts with `prefix` (the output or its temp name).
fn named(dir: &Path, prefix: &str) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.file_name().unwrap().to_str().unwrap().starts_with(prefix))
        .collect()
}

/// A failed run: non-zero exit, exactly one line on stderr naming `file`, no output.
fn assert_fails_naming(o: &Output, file: &str, root: &Path, out_name: &str) -> String {
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.starts_with("assoc: error: "), "{stderr}");
    assert!(stderr.contains(file), "{stderr} does not name {file}");
    assert!(
        named(root, out_name).is_empty(),
        "{:?}",
        named(root, out_name)
    );
    stderr
}

#[test]
fn binary_writes_bindings_report_and_previews_and_fails_cleanly() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let scene_dir = root.join("scene");
    let events = write_scene(&scene_dir);
    assert_eq!(events.len(), TIMES.len() * (PER_WINDOW + BETWEEN));
    let scene = Scene::open(&scene_dir).unwrap();
    let model_dir = root.join("model");
    let model = plane_model();
    assert_eq!(model.splats.len(), 25 * 17);
    model.save(&model_dir).unwrap();
    write_depths(&model, &scene, &model_dir);

    let out = root.join("out");
    let o = assoc(&scene_dir, &model_dir, &out);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("assoc: 3 frames"), "{stderr}");

    // assoc.bin loads: one section per train frame, all Gaussians, default settings.
    let sections = read_assoc(&out.join("assoc.bin")).unwrap();
    assert_eq!(sections.len(), TIMES.len());
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["gaussians"], 425);
    assert_eq!(report["events_total"], events.len());
    let frames = report["frames"].as_array().unwrap();
    assert_eq!(frames.len(), TIMES.len());
    let num = |f: &serde_json::Value, k: &str| {
        f[k].as_f64()
            .unwrap_or_else(|| panic!("report.json frame lacks {k}: {f}"))
    };
    let mut bound_fraction = 0.0;
    for (i, (f, sec)) in frames.iter().zip(&sections).enumerate() {
        assert_eq!(num(f, "t0"), TIMES[i]);
        assert_eq!((sec.t0, sec.delta_t, sec.k), (TIMES[i], 0.01, 3));
        assert_eq!(sec.bindings.gaussians(), 425);
        // The window holds exactly the events placed in it; every one is used or dropped.
        let in_window = num(f, "events_in_window");
        let used = num(f, "events_used");
        let dropped = num(f, "events_dropped_no_depth") + num(f, "events_dropped_outside");
        assert_eq!(in_window, PER_WINDOW as f64, "frame {i}");
        assert_eq!(used + dropped, in_window, "frame {i}");
        assert_eq!(num(f, "events_dropped_outside"), 0.0);
        // Used = the window's events on pixels with depth in the model's depth map.
        let (w, h, depth) = read_exr_depth(assoc::stage::depth_path(&model_dir, i)).unwrap();
        assert_eq!((w, h), (W, H));
        let with_depth = (0..H as usize)
            .step_by(3)
            .flat_map(|v| (0..W as usize).step_by(3).map(move |u| (u, v)))
            .filter(|&(u, v)| depth[v * W as usize + u] > 0.0)
            .count();
        assert_eq!(used, with_depth as f64, "frame {i}");
        // The patch covers about half the view: both kinds of event occur.
        assert!(
            used > 40.0 && dropped > 40.0,
            "frame {i}: {used} used, {dropped} dropped"
        );
        // Gaussians bound: as in assoc.bin, and nearly all of the patch (events every
        // 3 px; a 2-px radius misses only points near a grid cell's centre, ≤ 2.12 px).
        let bound = num(f, "gaussians_bound");
        assert_eq!(bound, sec.bindings.bound() as f64, "frame {i}");
        assert!(
            (0.95 * 425.0..=425.0).contains(&bound),
            "frame {i}: {bound} bound"
        );
        bound_fraction += bound / 425.0 / TIMES.len() as f64;
        // Distances in pixel footprints: ordered and within the 2-px radius.
        let (med, p90, max) = (
            num(f, "distance_px_median"),
            num(f, "distance_px_p90"),
            num(f, "distance_px_max"),
        );
        assert!(
            0.0 < med && med <= p90 && p90 <= max && max <= 2.0 * (1.0 + 1e-5),
            "frame {i}: {med} {p90} {max}"
        );
    }
    assert!((report["bound_fraction_mean"].as_f64().unwrap() - bound_fraction).abs() < 1e-12);
    // One preview per train frame, at the scene's image size.
    let previews = named(&out.join("preview"), "");
    assert_eq!(previews.len(), TIMES.len(), "{previews:?}");
    for i in 0..TIMES.len() {
        let png = out.join("preview").join(format!("{i:04}.png"));
        assert_eq!(image::image_dimensions(&png).unwrap(), (W, H));
    }
    assert!(out.join("settings.toml").is_file());

    // A depth map of another size than the camera: exit 1, one line naming the file
    // and both sizes, no output directory (nor its temp name) left behind.
    let bad = assoc::stage::depth_path(&model_dir, 0);
    write_exr_depth(&bad, 24, 16, &[1.0; 24 * 16]).unwrap();
    let o = assoc(&scene_dir, &model_dir, &root.join("bad_out"));
    let line = assert_fails_naming(&o, &bad.display().to_string(), root, "bad_out");
    let want = format!(
        "assoc: error: {}: depth map is 24x16 but the camera is 48x32\n",
        bad.display()
    );
    assert_eq!(line, want);

    // A missing model directory: the same, naming the model's file.
    let missing = root.join("no_model");
    let o = assoc(&scene_dir, &missing, &root.join("bad_out"));
    let line = assert_fails_naming(&o, &missing.display().to_string(), root, "bad_out");
    // The OS's reason once (not repeated by the error chain).
    let info = missing.join(gaussians::model::INFO_FILE);
    let reason = std::fs::read_to_string(&info).unwrap_err();
    assert_eq!(
        line,
        format!("assoc: error: {}: {reason}\n", info.display())
    );
    assert!(!missing.exists());
    // The earlier good output is untouched by the failed runs.
    assert_eq!(read_assoc(&out.join("assoc.bin")).unwrap(), sections);
}

/// `--help` shows each setting's current default, from `AssocSettings::default()`.
#[test]
fn help_shows_the_settings_defaults() {
    let o = Command::new(env!("CARGO_BIN_EXE_assoc"))
        .arg("--help")
        .output()
        .unwrap();
    assert!(o.status.success());
    let help = String::from_utf8_lossy(&o.stdout);
    let d = assoc::AssocSettings::default();
    for (flag, default) in [
        ("--delta-t", d.delta_t.to_string()),
        ("--k", d.k.to_string()),
        ("--min-alpha", d.min_alpha.to_string()),
    ] {
        let line = flag_help(&help, flag);
        assert!(line.contains(&format!("[default: {default}]")), "{line}");
    }
}
