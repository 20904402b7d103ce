//! `gaussians export`: a trained dynamic model as a PLY sequence. An outside reader
//! (Python `plyfile`, and `zipfile` for the zip) opens the files; rendering a frame's
//! PLY as a static cloud equals rendering the model at that frame's time.

mod python;
use gaussians::model::Model;
use gaussians::raster::{Rasterizer, TileRasterizer};
use gaussians::stage::{self, TrainArgs};
use gaussians::train::TrainSettings;
use python::python_with_plyfile;
use scene::manifest::Scene;
use stagekit::StageArgs;
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// The `rigid` preset (moving box and ball) at 40×40, RGB only, coarse textures.
fn tiny_scene(dir: &Path) {
    let mut cfg = synth::SynthConfig::preset("rigid").unwrap();
    for o in &mut cfg.objects {
        o.texture.cell *= 4.0;
        o.texture.detail = 0.0;
    }
    (cfg.width, cfg.height, cfg.train_fps, cfg.test_frames) = (40, 40, 5.0, 3);
    cfg.supersample = 1;
    synth::write_rgb_synthetic_scene(&cfg, dir).unwrap();
}

/// A short warm-up with its deformation field on (so the model moves).
fn trained_model(tmp: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let scene = tmp.join("scene");
    tiny_scene(&scene);
    let mut s = TrainSettings {
        iterations: 200,
        static_iterations: 50,
        init_points: 1500,
        sh_degree: 1,
        sh_interval: 100,
        ..TrainSettings::default()
    };
    (s.field.width, s.field.depth) = (16, 2);
    (
        s.densify.from_iter,
        s.densify.interval,
        s.densify.until_iter,
    ) = (60, 40, 150);
    // Keep the field whatever the model is worth without it: the test needs motion.
    (s.size.tolerance_db, s.static_tolerance_px) = (0.0, 0.0);
    let cfg = tmp.join("settings.toml");
    std::fs::write(&cfg, stagekit::settings::to_toml(&s).unwrap()).unwrap();
    let model = tmp.join("model");
    let args = TrainArgs {
        stage: StageArgs::new(&scene, &model).with_config(cfg),
        ..TrainArgs::default()
    };
    stage::train(&args, &AtomicBool::new(false), |_| {}).unwrap();
    (scene, model)
}

#[test]
fn the_exported_sequence_renders_as_the_model_and_outside_readers_open_it() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene_dir, model_dir) = trained_model(tmp.path());
    let out = tmp.path().join("export");
    let r =
        gaussians::export::export(&model_dir, &scene_dir, &out, (None, false), |_, _| {}).unwrap();
    let scene = Scene::open(&scene_dir).unwrap();
    let model = Model::load(&model_dir).unwrap();

    // One file per distinct train or test time, in time order, numbered from 1.
    let mut times: Vec<f64> = scene
        .train
        .frames
        .iter()
        .chain(&scene.test.frames)
        .map(|f| f.time)
        .collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    assert_eq!(r.frames.len(), times.len());
    for (k, (f, t)) in r.frames.iter().zip(&times).enumerate() {
        assert_eq!(f.file, format!("frame_{:04}.ply", k + 1));
        assert_eq!(f.time, *t);
    }
    // Seconds: the scene's own clock at the train frames.
    for fr in &scene.train.frames {
        let e = r.frames.iter().find(|e| e.time == fr.time).unwrap();
        assert!(
            (e.seconds - fr.timestamp).abs() < 1e-9,
            "{} vs {}",
            e.seconds,
            fr.timestamp
        );
    }

    // Rendering frame k's PLY as a still cloud is rendering the model at its time.
    let cam = scene.camera(&scene.test.frames[1]);
    let mut moved = 0.0f32;
    for f in [
        &r.frames[0],
        &r.frames[r.frames.len() / 2],
        r.frames.last().unwrap(),
    ] {
        let (splats, degree) = gaussians::ply::read(&out.join(&f.file)).unwrap();
        assert_eq!(degree, model.info.sh_degree);
        let still = TileRasterizer
            .render(&splats, &cam, degree, model.info.background)
            .0;
        let moving = model.render(&cam, f.time as f32);
        assert_eq!(still.rgb, moving.rgb, "{}", f.file);
        let at = model.at(f.time as f32);
        let first = model.at(r.frames[0].time as f32);
        for (a, b) in at.means.iter().zip(&first.means) {
            moved = moved.max((0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f32::max));
        }
    }
    assert!(
        moved > 1e-4,
        "the model is dynamic: its Gaussians moved {moved}"
    );

    // Outside readers: plyfile reads the count, the 3DGS fields and the deformed centres;
    // zipfile lists the same files, in order, with the same bytes.
    let python = python_with_plyfile().expect("a Python with plyfile (see python/mod.rs)");
    let last = r.frames.last().unwrap();
    let script = format!(
        r#"
import plyfile, zipfile, sys
v = plyfile.PlyData.read("{ply}")["vertex"]
names = [p.name for p in v.properties]
need = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
assert all(n in names for n in need), names
print(len(v.data), sum(n.startswith("f_rest_") for n in names))
print(repr(float(v.data["x"][0])), repr(float(v.data["z"][-1])))
z = zipfile.ZipFile("{zip}")
print(" ".join(z.namelist()))
print(all(z.read(n) == open("{dir}/" + n, "rb").read() for n in z.namelist()))
"#,
        ply = out.join(&last.file).display(),
        zip = out.join(&r.zip).display(),
        dir = out.display(),
    );
    let o = std::process::Command::new(&python)
        .args(["-c", &script])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8(o.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let at = model.at(last.time as f32);
    // Degree 1: 3 coefficients × 3 channels of f_rest.
    assert_eq!(lines[0], format!("{} 9", at.len()));
    let xs: Vec<f64> = lines[1].split(' ').map(|v| v.parse().unwrap()).collect();
    assert_eq!(
        xs,
        [at.means[0][0] as f64, at.means[at.len() - 1][2] as f64]
    );
    let names: Vec<String> = r.frames.iter().map(|f| f.file.clone()).collect();
    assert_eq!(lines[2], names.join(" "));
    assert_eq!(lines[3], "True");
}

#[test]
fn fps_gives_a_regular_grid_over_the_recording_and_bad_rates_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("scene");
    tiny_scene(&dir);
    let scene = Scene::open(&dir).unwrap();
    let (first, last) = (&scene.train.frames[0], scene.train.frames.last().unwrap());
    let t = gaussians::export::export_times(&scene, Some(20.0)).unwrap();
    let span = last.timestamp - first.timestamp;
    assert_eq!(t.len(), (span * 20.0 + 1e-9).floor() as usize + 1);
    for (k, &(s, time)) in t.iter().enumerate() {
        assert!((s - (first.timestamp + k as f64 / 20.0)).abs() < 1e-12);
        // The normalised time is the same line through the train frames.
        let expect = first.time + (s - first.timestamp) / span * (last.time - first.time);
        assert!((time - expect).abs() < 1e-12);
    }
    for bad in [0.0, -5.0, f64::NAN] {
        let e = gaussians::export::export_times(&scene, Some(bad)).unwrap_err();
        assert!(e.to_string().contains("--fps"), "{e}");
    }
}

/// The frames of `gaussians video` in `out/frames/`, decoded.
fn video_frames(out: &Path, n: usize) -> Vec<scene::image_io::Image> {
    (1..=n)
        .map(|k| {
            let p = out.join("frames").join(gaussians::video::frame_file(k));
            scene::image_io::read_image(&p).unwrap()
        })
        .collect()
}

/// The largest difference in 8-bit levels between a PNG frame and a fresh render.
fn max_level_diff(a: &scene::image_io::Image, b: &scene::image_io::Image) -> f32 {
    assert_eq!((a.width, a.height), (b.width, b.height));
    (a.data.iter().zip(&b.data))
        .map(|(x, y)| ((x - y) * 255.0).abs())
        .fold(0.0, f32::max)
}

/// `gaussians video`: along the recorded path at the train frames' own rate, each frame
/// is the model rendered at that train camera and time; the orbit's first frame is the
/// middle train camera, its cameras all look at one point at one distance; the written
/// `cameras.json` renders the same frames again as a cameras file; the GIF decodes to
/// the frames (within its 256-colour palette); without `ffmpeg` the report says why
/// there is no MP4.
#[test]
fn videos_render_the_model_along_recorded_orbit_and_file_paths() {
    use gaussians::video::{VideoSettings, render_video};
    let tmp = tempfile::tempdir().unwrap();
    let (scene_dir, model_dir) = trained_model(tmp.path());
    let scene = Scene::open(&scene_dir).unwrap();
    let model = Model::load(&model_dir).unwrap();
    let train = &scene.train.frames;
    let span = train.last().unwrap().timestamp - train[0].timestamp;
    let rate = (train.len() - 1) as f64 / span;
    let settings = |path: &str, fps: Option<f64>| VideoSettings {
        path: path.to_string(),
        fps,
        ..VideoSettings::default()
    };
    // Recorded, at the train rate: frame k is train frame k; by the binary, with a
    // PATH that has no ffmpeg.
    let rec = tmp.path().join("recorded");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_gaussians"))
        .args(["video", "--path", "recorded", "--fps", &rate.to_string()])
        .arg("--scene")
        .arg(&scene_dir)
        .arg("--model")
        .arg(&model_dir)
        .arg("--out")
        .arg(&rec)
        .env("PATH", tmp.path())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("ffmpeg is not on the PATH"), "{err}");
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(rec.join("report.json")).unwrap()).unwrap();
    assert!(r["mp4"].is_null(), "{r}");
    let n = r["frames"].as_u64().unwrap() as usize;
    assert_eq!(n, train.len());
    let frames = video_frames(&rec, n);
    for (k, f) in train.iter().enumerate() {
        let want = model.render(&scene.camera(f), f.time as f32).rgb_image();
        let d = max_level_diff(&frames[k], &want);
        assert!(
            d <= 0.5 + 1e-3,
            "frame {k}: {d} levels off the train camera's render"
        );
    }
    // The GIF: as many frames, each within the palette's error of its PNG.
    let gif = std::fs::File::open(rec.join("preview.gif")).unwrap();
    let dec = image::codecs::gif::GifDecoder::new(std::io::BufReader::new(gif)).unwrap();
    let decoded = image::AnimationDecoder::into_frames(dec)
        .collect_frames()
        .unwrap();
    assert_eq!(decoded.len(), frames.len());
    for (g, p) in decoded.iter().zip(&frames) {
        let buf = g.buffer();
        assert_eq!((buf.width(), buf.height()), (p.width, p.height));
        let mean: f64 = (buf.pixels().enumerate())
            .map(|(i, px)| {
                (0..3)
                    .map(|c| (px[c] as f64 - (p.data[3 * i + c] * 255.0).round() as f64).abs())
                    .sum::<f64>()
            })
            .sum::<f64>()
            / (3 * p.width * p.height) as f64;
        assert!(
            mean < 6.0,
            "GIF frame off its PNG by {mean:.2} levels on average"
        );
    }
    // The cameras file renders the same frames again.
    let again = tmp.path().join("again");
    let cams = rec.join("cameras.json");
    let r2 = render_video(
        &model_dir,
        &scene_dir,
        &again,
        &settings(cams.to_str().unwrap(), None),
        false,
        |_, _| {},
    )
    .unwrap();
    assert_eq!(r2.frames, n);
    for (a, b) in video_frames(&again, r2.frames).iter().zip(&frames) {
        assert!(max_level_diff(a, b) <= 0.5 + 1e-3);
    }
    // Orbit: starts at the middle train camera; every optical axis meets one point.
    let orbit = tmp.path().join("orbit");
    let r3 = render_video(
        &model_dir,
        &scene_dir,
        &orbit,
        &settings("orbit", Some(3.0 * rate)),
        false,
        |_, _| {},
    )
    .unwrap();
    let m = scene::manifest::Manifest::read(orbit.join("cameras.json")).unwrap();
    assert_eq!(m.frames.len(), r3.frames);
    let middle = train[train.len() / 2].cam_to_world;
    let p0 = m.frames[0].cam_to_world;
    assert!((p0.translation - middle.translation).length() < 1e-9);
    assert!(p0.rotation.angle_between(middle.rotation) < 1e-9);
    let axis = |p: &scene::camera::Pose| (p.translation, p.rotation * glam::DVec3::NEG_Z);
    let (o1, d1) = axis(&m.frames[r3.frames / 4].cam_to_world);
    let (o2, d2) = axis(&m.frames[3 * r3.frames / 4].cam_to_world);
    // Closest points of the two axes (they swing ±20° apart: not parallel).
    let w = o1 - o2;
    let (b, d, e) = (d1.dot(d2), d1.dot(w), d2.dot(w));
    let (s, t) = ((b * e - d) / (1.0 - b * b), (e - b * d) / (1.0 - b * b));
    let (c1, c2) = (o1 + s * d1, o2 + t * d2);
    assert!((c1 - c2).length() < 1e-6 && s > 0.0, "{c1} vs {c2}");
    for f in &m.frames {
        let dist = (f.cam_to_world.translation - c1).length();
        assert!((dist - s).abs() < 1e-6, "{dist} vs {s}");
    }
}
