//! `degs eval` on what a scene can say beyond the whole image: test frames that are
//! train frames (its scene checks), and the novel views' PSNR on the pixels of moving
//! objects and on those some train view saw, with the contact sheet.

mod eval_common;
use eval_common::*;
use scene::image_io::{read_image, write_png};
use scene::manifest::Scene;
use std::fs;

/// A run over a scene whose test frame is a train frame (same time and camera): `eval`
/// still scores it and records and prints why those scores are not held-out scores.
#[test]
fn eval_says_when_test_frames_are_train_frames() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path().join("cache-root");
    let scene_dir = tiny_scene(d.path());
    let path = scene_dir.join("transforms_test.json");
    let train: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(scene_dir.join("transforms_train.json")).unwrap())
            .unwrap();
    let mut test: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(&path).unwrap()).unwrap();
    let keep = test["frames"][0]["file_path"].clone();
    test["frames"][0] = train["frames"][1].clone();
    test["frames"][0]["file_path"] = keep;
    fs::write(&path, test.to_string()).unwrap();
    let scene = Scene::open(&scene_dir).unwrap();
    let g = d.path().join("g");
    renders(&g, &scene, 0.0);
    fabricate_run(&root, "dup", &scene_dir, &g, None);
    let run = root.join("runs/dup");
    let o = degs(&["eval", run.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(err.contains("test frames are train frames"), "{err}");
    let m: serde_json::Value =
        serde_json::from_slice(&fs::read(run.join("metrics.json")).unwrap()).unwrap();
    let findings = m["scene_findings"].as_array().unwrap();
    assert!(
        findings
            .iter()
            .any(|f| f.as_str().unwrap().starts_with("error: 1 of 2 test frames")),
        "{findings:?}"
    );
}

/// The pixel whose value the test changes in novel view `k` (object ids `ids`, `seen`
/// its co-visibility mask): frame 0 the first moving one, the others the first still one
/// some train view saw.
fn changed_pixel(k: usize, ids: &[u16], seen: &[u16], moving: &[u16]) -> usize {
    (0..ids.len())
        .position(|p| {
            if k == 0 {
                moving.contains(&ids[p])
            } else {
                !moving.contains(&ids[p]) && seen[p] != 0
            }
        })
        .unwrap()
}

/// The novel views' PSNR on moving-object pixels: a render off by `δ` levels in one value
/// of one moving pixel scores `10·log10(255²·3M/δ²)` over the M moving pixels; one off at
/// a still pixel leaves it at the cap.
#[test]
fn eval_scores_the_novel_views_on_the_pixels_of_moving_objects() {
    let Exact {
        dir: _dir,
        root,
        scene_dir,
        scene,
        g,
    } = exact_renders(true);
    let moving = moving_ids(&scene_dir);
    assert!(!moving.is_empty());
    let delta = 40.0f32;
    let mut want = Vec::new();
    for k in 0..scene.novel.frames.len() {
        let (_, _, ids) =
            synth::gt::read_object_png(scene_dir.join(format!("gt/novel/object_{k:04}.png")))
                .unwrap();
        let m = ids.iter().filter(|o| moving.contains(o)).count();
        let (_, _, seen) =
            synth::gt::read_object_png(scene_dir.join(format!("gt/novel/covisible_{k:04}.png")))
                .unwrap();
        // Frame 0: one value of a moving pixel; frame 1: one of a still pixel some train
        // view saw.
        let pick = changed_pixel(k, &ids, &seen, &moving);
        let p = g.join(format!("renders/novel/{k:04}.png"));
        let mut img = read_image(&p).unwrap();
        let v = (img.data[pick * 3] * 255.0).round();
        img.data[pick * 3] = if v + delta <= 255.0 {
            v + delta
        } else {
            v - delta
        } / 255.0;
        write_png(&p, &img).unwrap();
        want.push((
            m,
            if k == 0 {
                10.0 * (255.0f64.powi(2) * 3.0 * m as f64 / (delta as f64).powi(2)).log10()
            } else {
                100.0
            },
        ));
    }
    fabricate_run(&root, "mv", &scene_dir, &g, None);
    let run = root.join("runs/mv");
    let o = degs(&["eval", run.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m: serde_json::Value =
        serde_json::from_slice(&fs::read(run.join("metrics.json")).unwrap()).unwrap();
    let novel = m["novel_frames"].as_array().unwrap();
    for (k, (pixels, psnr)) in want.iter().enumerate() {
        assert_eq!(
            novel[k]["moving_pixels"].as_u64(),
            Some(*pixels as u64),
            "{k}"
        );
        let got = novel[k]["moving_psnr"].as_f64().unwrap();
        assert!((got - psnr).abs() < 1e-9, "frame {k}: {got} vs {psnr}");
    }
    let mean = m["novel_moving_psnr_mean"].as_f64().unwrap();
    assert!((mean - (want[0].1 + want[1].1) / 2.0).abs() < 1e-9);
    // The co-visible pixels: the same closed form where the changed value lies among
    // them, the cap where it does not.
    let mut closed_forms = 0;
    for (k, frame) in novel.iter().enumerate() {
        let (_, _, seen) =
            synth::gt::read_object_png(scene_dir.join(format!("gt/novel/covisible_{k:04}.png")))
                .unwrap();
        let (_, _, ids) =
            synth::gt::read_object_png(scene_dir.join(format!("gt/novel/object_{k:04}.png")))
                .unwrap();
        let pick = changed_pixel(k, &ids, &seen, &moving);
        let mc = seen.iter().filter(|&&v| v != 0).count();
        assert!(mc > 0 && mc <= seen.len());
        assert_eq!(frame["covisible_pixels"].as_u64(), Some(mc as u64));
        let want = if seen[pick] != 0 {
            10.0 * (255.0f64.powi(2) * 3.0 * mc as f64 / (delta as f64).powi(2)).log10()
        } else {
            100.0
        };
        let got = frame["covisible_psnr"].as_f64().unwrap();
        assert!((got - want).abs() < 1e-9, "frame {k}: {got} vs {want}");
        // Of those, the still ones (no moving object in the ground truth): the changed
        // value counts only where it is still and seen.
        let still = |p: usize| seen[p] != 0 && !moving.contains(&ids[p]);
        let ms = (0..seen.len()).filter(|&p| still(p)).count();
        assert!(ms > 0 && ms < mc, "frame {k}: {ms} of {mc}");
        assert_eq!(frame["covisible_still_pixels"].as_u64(), Some(ms as u64));
        let want = if still(pick) {
            closed_forms += 1;
            10.0 * (255.0f64.powi(2) * 3.0 * ms as f64 / (delta as f64).powi(2)).log10()
        } else {
            100.0
        };
        let got = frame["covisible_still_psnr"].as_f64().unwrap();
        assert!((got - want).abs() < 1e-9, "frame {k}: {got} vs {want}");
    }
    assert_eq!(
        closed_forms, 1,
        "frame 1's changed still pixel is one a train view saw"
    );
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("pixels of moving objects"), "{out}");
    assert!(out.contains("pixels some train view saw"), "{out}");
    assert!(out.contains("of those the still ones"), "{out}");
    // The sheet: per row the ground truth, the render and |difference| ×4, each panel
    // enlarged to at least 128 px; frame 0's changed value shows in its difference.
    let sheet = read_image(run.join("novel_sheet.png")).unwrap();
    let gt = read_image(scene.image_path(&scene.novel.frames[0])).unwrap();
    let z = 128u32.div_ceil(gt.width);
    assert_eq!(
        (sheet.width, sheet.height),
        (3 * z * gt.width + 4, 2 * z * gt.height + 2)
    );
    let (_, _, ids) =
        synth::gt::read_object_png(scene_dir.join("gt/novel/object_0000.png")).unwrap();
    let pick = ids.iter().position(|o| moving.contains(o)).unwrap() as u32;
    let (x, y) = (pick % gt.width, pick / gt.width);
    let at = |panel: u32| {
        let sx = panel * (z * gt.width + 2) + z * x;
        sheet.data[((z * y * sheet.width + sx) * 3) as usize]
    };
    assert_eq!(at(0), gt.data[(pick * 3) as usize]);
    assert!(
        (at(2) - (4.0 * delta / 255.0).min(1.0)).abs() < 1e-6,
        "{}",
        at(2)
    );
}

/// The novel views' SSIM on the masks and the depth error on the moving pixels: renders
/// equal to the ground truth score SSIM 1 on both masks; a render depth 1.1 × the true
/// one scores a relative error of 0.1 (frame 0), an empty render (depth 0) 1 (frame 1),
/// both over the moving pixels the ground truth depth covers.
#[test]
fn eval_scores_ssim_on_the_masks_and_the_depth_of_moving_objects() {
    use scene::image_io::{read_exr_depth, write_exr_depth};
    let Exact {
        dir: _dir,
        root,
        scene_dir,
        scene,
        g,
    } = exact_renders(true);
    let depth = g.join("renders/novel_depth");
    fs::create_dir_all(&depth).unwrap();
    for k in 0..scene.novel.frames.len() {
        let (w, h, z) =
            read_exr_depth(scene_dir.join(format!("gt/novel/depth_{k:04}.exr"))).unwrap();
        let scale = if k == 0 { 1.1 } else { 0.0 };
        let z: Vec<f32> = z.iter().map(|v| v * scale).collect();
        write_exr_depth(depth.join(format!("{k:04}.exr")), w, h, &z).unwrap();
    }
    fabricate_run(&root, "dz", &scene_dir, &g, None);
    let run = root.join("runs/dz");
    let o = degs(&["eval", run.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m: serde_json::Value =
        serde_json::from_slice(&fs::read(run.join("metrics.json")).unwrap()).unwrap();
    let novel = m["novel_frames"].as_array().unwrap();
    for (k, f) in novel.iter().enumerate() {
        assert_eq!(f["moving_ssim"].as_f64(), Some(1.0), "frame {k}");
        assert_eq!(f["covisible_ssim"].as_f64(), Some(1.0), "frame {k}");
        let want = if k == 0 { 0.1 } else { 1.0 };
        let got = f["moving_depth_error"].as_f64().unwrap();
        assert!((got - want).abs() < 1e-6, "frame {k}: {got} vs {want}");
    }
    let mean = m["novel_moving_depth_error_mean"].as_f64().unwrap();
    assert!((mean - 0.55).abs() < 1e-6, "{mean}");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("depth off by 55.0 %"), "{out}");
}

/// LPIPS on the masks: renders equal to the ground truth score 0 on both; a render whose
/// moving objects alone are painted grey (frame 0) scores far more over their pixels
/// than over the whole image, where the unchanged rest dilutes it.
#[test]
fn eval_scores_lpips_on_the_masks() {
    let Exact {
        dir: _dir,
        root,
        scene_dir,
        scene: _,
        g,
    } = exact_renders(true);
    let ids = |k: usize| {
        synth::gt::read_object_png(scene_dir.join(format!("gt/novel/object_{k:04}.png")))
            .unwrap()
            .2
    };
    let moving = moving_ids(&scene_dir);
    let moves = |o: u16| moving.contains(&o);
    let p = g.join("renders/novel/0000.png");
    let mut img = read_image(&p).unwrap();
    for (i, _) in ids(0).iter().enumerate().filter(|(_, o)| moves(**o)) {
        img.data[3 * i..3 * i + 3].fill(0.5);
    }
    write_png(&p, &img).unwrap();
    fabricate_run(&root, "lp", &scene_dir, &g, None);
    let run = root.join("runs/lp");
    let Some((o, m)) = eval_with_lpips(&run) else {
        return;
    };
    let novel = m["novel_frames"].as_array().unwrap();
    for f in &novel[1..] {
        assert!(f["moving_lpips"].as_f64().unwrap().abs() < 1e-9, "{f}");
        assert!(f["covisible_lpips"].as_f64().unwrap().abs() < 1e-9, "{f}");
    }
    let (moving, whole) = (
        novel[0]["moving_lpips"].as_f64().unwrap(),
        novel[0]["lpips"].as_f64().unwrap(),
    );
    assert!(moving > 2.0 * whole && whole > 0.0, "{moving} vs {whole}");
    let mean = m["novel_moving_lpips_mean"].as_f64().unwrap();
    assert!((mean - moving / novel.len() as f64).abs() < 1e-9, "{mean}");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("LPIPS"), "{out}");
}
