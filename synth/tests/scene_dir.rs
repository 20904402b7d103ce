//! Synthetic scene directories: layout accepted by `Scene::open`, ground truth equal to
//! the analytic renders, events consistent with the brightness change.

use glam::DVec2;
use scene::image_io::{read_exr_depth, read_exr_flow, read_image};
use scene::manifest::Scene;
use synth::gt::{NOISE_ID, read_event_flow_gt, read_object_png};
use synth::scene_dir::{simulate_scene, write_synthetic_scene};
use synth::sim::{SimConfig, luminance};
use synth::{SynthConfig, SynthWorld};

fn small(preset: &str) -> SynthConfig {
    SynthConfig {
        width: 48,
        height: 40,
        duration: 0.25,
        train_fps: 8.0,
        test_frames: 2,
        render_rate_hz: 400.0,
        ..SynthConfig::preset(preset).unwrap()
    }
}

#[test]
fn preset_scene_opens_and_its_ground_truth_matches_the_renders() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("scene");
    let cfg = small("nonrigid");
    let summary = write_synthetic_scene(&cfg, &out).unwrap();
    assert_eq!((summary.train_frames, summary.test_frames), (3, 2));
    assert_eq!(summary.internal_frames, 101);
    assert!(summary.events > 1000, "{}", summary.events);

    let scene = Scene::open(&out).unwrap();
    assert_eq!(scene.train.frames.len(), 3);
    assert_eq!(scene.test.frames.len(), 2);
    assert_eq!(scene.contrast_threshold(), 0.1);
    let events = scene.load_events().unwrap();
    assert_eq!(events.len(), summary.events);
    events.validate().unwrap();

    let world = SynthWorld::new(&cfg).unwrap();
    let k = world.intrinsics();
    assert_eq!(scene.train.camera.width, 48);
    assert!((scene.train.camera.fx - k.fx).abs() < 1e-9);
    for (split, frames) in [("train", &scene.train.frames), ("test", &scene.test.frames)] {
        for (i, f) in frames.iter().enumerate() {
            let r = world.render_frame(f.timestamp);
            let pose = world.camera_at(f.timestamp).cam_to_world;
            assert!((f.cam_to_world.translation - pose.translation).length() < 1e-9);
            assert!(f.cam_to_world.rotation.angle_between(pose.rotation) < 1e-6);
            let gt = out.join("gt").join(split);
            let (w, h, depth) = read_exr_depth(gt.join(format!("depth_{i:04}.exr"))).unwrap();
            assert_eq!((w, h), (48, 40));
            assert!(depth == r.depth, "{split} {i}: depth differs");
            let (_, _, u, v) = read_exr_flow(gt.join(format!("flow_{i:04}.exr"))).unwrap();
            assert!(u == r.flow_u && v == r.flow_v, "{split} {i}: flow differs");
            let (_, _, ids) = read_object_png(gt.join(format!("object_{i:04}.png"))).unwrap();
            assert!(ids == r.object_id, "{split} {i}: ids differ");
            // Images are the frame renders (frame_supersample) quantised to 8 bits.
            let img = read_image(scene.image_path(f)).unwrap();
            let worst = img
                .data
                .iter()
                .zip(&r.rgb)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(worst <= 0.5 / 255.0 + 1e-6, "{split} {i}: {worst}");
        }
    }
    // Train frame times k/8, test frames in between.
    let ts: Vec<f64> = scene.train.frames.iter().map(|f| f.timestamp).collect();
    assert_eq!(ts, vec![0.0, 0.125, 0.25]);
    let ts: Vec<f64> = scene.test.frames.iter().map(|f| f.timestamp).collect();
    assert_eq!(ts, vec![0.0625, 0.1875]);
    assert_eq!(scene.train.frames[2].time, 1.0);

    // Per-event ground truth: one row per event, close to the analytic flow at the
    // event's own time (away from occlusion edges the interpolation error is small).
    let gt = read_event_flow_gt(out.join("gt/event_flow.bin")).unwrap();
    assert_eq!(gt.len(), events.len());
    assert!(gt.index.iter().enumerate().all(|(i, &j)| j == i as u64));
    let mut rel = Vec::new();
    for i in (0..events.len()).step_by(37) {
        let px = DVec2::new(events.x[i] as f64, events.y[i] as f64);
        let hit = world.cast(events.t[i], px);
        let id = hit.map_or(0, |h| h.object + 1) as u16;
        if id != gt.object[i] {
            continue;
        }
        let f = world.flow_at(events.t[i], px);
        let g = DVec2::new(gt.u[i] as f64, gt.v[i] as f64);
        rel.push((f - g).length() / f.length().max(1.0));
    }
    rel.sort_by(f64::total_cmp);
    assert!(rel.len() > 100);
    let median = rel[rel.len() / 2];
    assert!(median < 1e-3, "median relative error {median}");
    assert!(!gt.object.contains(&NOISE_ID));
}

#[test]
fn events_integrate_to_the_log_brightness_change() {
    // Without threshold noise each pixel's reference level is L(0) + C·Σp and stays
    // within C of the current L (event generation model, docs/DESIGN.md §5 Eq. 11).
    let cfg = small("fast");
    let world = SynthWorld::new(&cfg).unwrap();
    let (events, _) = simulate_scene(&world).unwrap();
    let l = |t: f64| -> Vec<f64> {
        luminance(&world.render(t).rgb)
            .iter()
            .map(|&y| (1e-3 + y as f64).ln())
            .collect()
    };
    let (l0, l1) = (l(0.0), l(cfg.duration));
    let mut sum = vec![0i64; l0.len()];
    for i in 0..events.len() {
        sum[events.y[i] as usize * 48 + events.x[i] as usize] += events.p[i] as i64;
    }
    let c = cfg.events.threshold_pos;
    let mut changed = 0;
    for i in 0..l0.len() {
        let residual = l1[i] - (l0[i] + c * sum[i] as f64);
        assert!(residual.abs() < c + 1e-6, "pixel {i}: residual {residual}");
        changed += (sum[i] != 0) as usize;
    }
    assert!(changed > l0.len() / 4, "{changed}");
}

#[test]
fn every_preset_produces_events_and_simulation_is_deterministic() {
    for name in synth::PRESETS {
        let base = small(name);
        let cfg = SynthConfig {
            duration: 0.1,
            render_rate_hz: 200.0,
            events: SimConfig {
                shot_noise_hz: 2.0,
                threshold_sigma: 0.02,
                ..base.events
            },
            ..base
        };
        let world = SynthWorld::new(&cfg).unwrap();
        let (a, ga) = simulate_scene(&world).unwrap();
        let (b, gb) = simulate_scene(&world).unwrap();
        assert_eq!(a, b);
        assert_eq!(ga, gb);
        assert!(a.len() > 200, "{name}: {}", a.len());
        assert!(
            ga.object.contains(&NOISE_ID),
            "{name}: noise events are labelled"
        );
        let noise = ga.object.iter().filter(|&&o| o == NOISE_ID).count();
        assert!(
            ga.u.iter()
                .zip(&ga.object)
                .all(|(&u, &o)| o != NOISE_ID || u == 0.0)
        );
        // 48·40 px × 2 Hz × 0.1 s ≈ 384 noise events.
        assert!((noise as f64 - 384.0).abs() < 100.0, "{name}: {noise}");
    }
}

#[test]
fn blurred_train_frames_differ_from_sharp_test_renders() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("blur");
    let cfg = SynthConfig {
        blur_subframes: 5,
        exposure_s: 0.03,
        render_rate_hz: 100.0,
        ..small("fast")
    };
    write_synthetic_scene(&cfg, &out).unwrap();
    let world = SynthWorld::new(&cfg).unwrap();
    let scene = Scene::open(&out).unwrap();
    let f = &scene.train.frames[1];
    let img = read_image(scene.image_path(f)).unwrap();
    let sharp = world.render_frame(f.timestamp);
    let diff: f32 = img
        .data
        .iter()
        .zip(&sharp.rgb)
        .map(|(a, b)| (a - b).abs())
        .sum::<f32>()
        / img.data.len() as f32;
    assert!(diff > 0.01, "mean |blurred − sharp| = {diff}");
    // Ground truth stays the sharp render's.
    let (_, _, depth) = read_exr_depth(out.join("gt/train/depth_0001.exr")).unwrap();
    assert!(depth == sharp.depth);
}

#[test]
fn invalid_settings_leave_nothing_behind() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("bad");
    let mut cfg = small("rigid");
    cfg.events.threshold_pos = 0.0;
    cfg.events.threshold_neg = 0.0;
    let e = write_synthetic_scene(&cfg, &out).unwrap_err();
    assert!(e.to_string().contains("events.threshold_pos"), "{e}");
    assert!(!out.exists());
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0);
}

#[test]
fn the_rgb_only_writer_writes_the_frames_of_the_full_one() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = small("nonrigid");
    let (full, rgb) = (tmp.path().join("full"), tmp.path().join("rgb"));
    write_synthetic_scene(&cfg, &full).unwrap();
    synth::write_rgb_synthetic_scene(&cfg, &rgb).unwrap();
    let (a, b) = (Scene::open(&full).unwrap(), Scene::open(&rgb).unwrap());
    assert!(b.train.events.is_none() && !rgb.join("events.evs").exists());
    assert_eq!(b.novel.frames.len(), 2);
    for (ma, mb) in [
        (&a.train, &b.train),
        (&a.test, &b.test),
        (&a.novel, &b.novel),
    ] {
        assert_eq!(ma.camera, mb.camera);
        assert_eq!(ma.frames, mb.frames);
        for f in &ma.frames {
            let bytes = |root: &std::path::Path| std::fs::read(root.join(&f.file_path)).unwrap();
            assert!(bytes(&full) == bytes(&rgb), "{}", f.file_path);
        }
    }
}

#[test]
fn the_novel_split_is_written_at_the_test_times_from_the_novel_cameras() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("scene");
    let cfg = SynthConfig {
        frame_supersample: 2,
        ..small("rigid")
    };
    let summary = write_synthetic_scene(&cfg, &out).unwrap();
    assert_eq!(summary.novel_frames, 2);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["novel_frames"], 2);
    let scene = Scene::open(&out).unwrap();
    assert_eq!(scene.novel.frames.len(), 2);
    assert_eq!(scene.novel.camera, scene.test.camera);
    let world = SynthWorld::new(&cfg).unwrap();
    for (i, (f, t)) in scene
        .novel
        .frames
        .iter()
        .zip(&scene.test.frames)
        .enumerate()
    {
        assert_eq!(f.file_path, format!("images/novel_{i:04}.png"));
        assert_eq!((f.timestamp, f.time), (t.timestamp, t.time));
        let pose = world.novel_camera_at(f.timestamp).cam_to_world;
        assert!((f.cam_to_world.translation - pose.translation).length() < 1e-9);
        assert!(f.cam_to_world.rotation.angle_between(pose.rotation) < 1e-6);
        // 15° about the target, r ≈ 3.1: the centre is ~0.8 away from the test camera's
        let moved = (f.cam_to_world.translation - t.cam_to_world.translation).length();
        assert!(moved > 0.75 && moved < 0.9, "{moved}");
        let r = world.render_novel_frame(f.timestamp);
        let img = read_image(scene.image_path(f)).unwrap();
        let worst = img
            .data
            .iter()
            .zip(&r.rgb)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(worst <= 0.5 / 255.0 + 1e-6, "novel {i}: {worst}");
        // and differs from the test image at the same time
        let test = read_image(scene.image_path(t)).unwrap();
        let diff = img
            .data
            .iter()
            .zip(&test.data)
            .map(|(a, b)| (a - b).abs())
            .sum::<f32>()
            / img.data.len() as f32;
        assert!(diff > 0.02, "novel {i} ≈ test {i}: {diff}");
        let gt = out.join("gt/novel");
        let (_, _, depth) = read_exr_depth(gt.join(format!("depth_{i:04}.exr"))).unwrap();
        assert!(depth == r.depth, "novel {i}: depth differs");
        let (_, _, u, v) = read_exr_flow(gt.join(format!("flow_{i:04}.exr"))).unwrap();
        assert!(u == r.flow_u && v == r.flow_v, "novel {i}: flow differs");
        let (_, _, ids) = read_object_png(gt.join(format!("object_{i:04}.png"))).unwrap();
        assert!(ids == r.object_id, "novel {i}: ids differ");
    }

    // angle 0: no novel split at all
    let off = tmp.path().join("off");
    let cfg = SynthConfig {
        novel_angle_deg: 0.0,
        ..small("rigid")
    };
    assert_eq!(write_synthetic_scene(&cfg, &off).unwrap().novel_frames, 0);
    assert!(!off.join("transforms_novel.json").exists());
    assert!(!off.join("gt/novel").exists() && !off.join("images/novel_0000.png").exists());
    assert!(Scene::open(&off).unwrap().novel.frames.is_empty());
}
