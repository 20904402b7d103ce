//! `degs eval RUN` and `degs compare RUN…` on fabricated run directories: a tiny
//! synthetic scene, renders of the test frames and novel views with a known error,
//! flow files with a known error, the 2D baselines computed or read from a report.

mod eval_common;
use eval_common::*;
use evaluate::baselines;
use evflow::flowfile::{EvFlow, write_evflow};
use scene::evaluation as figures;
use scene::image_io::{read_image, write_png};
use scene::manifest::Scene;
use std::fs;
use std::path::Path;

#[test]
fn eval_and_compare_report_known_errors() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path().join("cache-root");
    let scene_dir = tiny_scene(d.path());
    let scene = Scene::open(&scene_dir).unwrap();
    let gt = synth::gt::read_event_flow_gt(scene_dir.join("gt/event_flow.bin")).unwrap();
    let noise = gt
        .object
        .iter()
        .filter(|&&o| o == synth::gt::NOISE_ID)
        .count();
    assert!(noise > 0 && noise < gt.len(), "{noise} of {}", gt.len());

    // run A: one render off by 40 levels in one value, one novel view off by 20;
    // flow off by (3, -4) px/s, noise events given absurd flow (they must not count)
    let a = d.path().join("a-gaussians");
    let psnr1 = renders(&a, &scene, 40.0);
    assert_eq!(scene.novel.frames.len(), 2);
    let novel1 = copies(&a.join("renders/novel"), &scene, &scene.novel.frames, 20.0);
    let flows = d.path().join("a-evflow");
    fs::create_dir_all(flows.join("flow")).unwrap();
    let half = gt.len() / 2;
    for (w, range) in [(0usize, 0..half), (1, half..gt.len())] {
        let mut fl = EvFlow {
            width: gt.width,
            height: gt.height,
            t_a: 0.1 * w as f64,
            t_b: 0.1 * w as f64 + 0.125,
            t_ref: 0.1 * w as f64,
            ..EvFlow::default()
        };
        for j in range {
            fl.index.push(gt.index[j]);
            let bad = gt.object[j] == synth::gt::NOISE_ID;
            fl.u.push(if bad { 1e4 } else { gt.u[j] + 3.0 });
            fl.v.push(if bad { 1e4 } else { gt.v[j] - 4.0 });
        }
        write_evflow(&flows.join(format!("flow/{w:04}.evflow")), &fl).unwrap();
    }
    fabricate_run(&root, "a", &scene_dir, &a, Some(&flows));
    // run B: perfect renders, no flow stage
    let b = d.path().join("b-gaussians");
    renders(&b, &scene, 0.0);
    fabricate_run(&root, "b", &scene_dir, &b, None);

    let run_a = root.join("runs/a");
    let o = degs(&["eval", run_a.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m: serde_json::Value =
        serde_json::from_slice(&fs::read(run_a.join("metrics.json")).unwrap()).unwrap();
    let frames = m["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 2);
    assert_eq!(frames[0]["psnr"], 100.0);
    assert_eq!(frames[0]["ssim"], 1.0);
    let p1 = frames[1]["psnr"].as_f64().unwrap();
    assert!((p1 - psnr1).abs() < 1e-9, "{p1} vs {psnr1}");
    let s1 = frames[1]["ssim"].as_f64().unwrap();
    assert!(s1 < 1.0 && s1 > 0.9, "{s1}");
    let mean = m["psnr_mean"].as_f64().unwrap();
    assert!((mean - (100.0 + psnr1) / 2.0).abs() < 1e-9);
    assert_eq!(m["render_stage"], "gaussians");
    // the novel views: frame 0 exact, frame 1 off by 20 levels in one value
    let novel = m["novel_frames"].as_array().unwrap();
    assert_eq!(novel.len(), 2);
    assert!(
        novel[1]["test_image"]
            .as_str()
            .unwrap()
            .ends_with("novel_0001.png")
    );
    assert!((novel[1]["psnr"].as_f64().unwrap() - novel1).abs() < 1e-9);
    let novel_mean = m["novel_psnr_mean"].as_f64().unwrap();
    assert!((novel_mean - (100.0 + novel1) / 2.0).abs() < 1e-9);
    assert!(novel1 > psnr1 + 5.9, "{novel1} vs {psnr1}"); // half the error: +6.02 dB
    // the 2D baselines, computed from the scene (the run has no deform stage)
    let want = scene_baselines(&scene_dir);
    let b = &m["baselines"];
    assert_eq!(b["source"], "computed from the scene");
    // Nearest and blend against their definitions, written out here from the PNGs.
    let (near_ref, blend_ref) = reference_nearest_and_blend(&scene_dir);
    for (key, want, reference) in [
        ("nearest", want.nearest, near_ref),
        ("blend", want.blend, blend_ref),
    ] {
        let got = b[key]["psnr_mean"].as_f64().unwrap();
        assert!(
            (got - reference).abs() < 1e-9,
            "{key}: {got} vs {reference}"
        );
        assert!((b[key]["ssim_mean"].as_f64().unwrap() - want.ssim_mean).abs() < 1e-9);
    }
    let events = want.events.unwrap();
    assert!((b["events"]["psnr_mean"].as_f64().unwrap() - events.psnr_mean).abs() < 1e-9);
    // The event pseudo image against its definition written out here (equal: no pixel
    // of this scene is masked as a rate outlier, which the reference does not do).
    let reference = reference_event_pseudo_image(&scene_dir);
    assert!(
        (events.psnr_mean - reference).abs() < 1e-9,
        "event pseudo image {} dB, reference {reference} dB",
        events.psnr_mean
    );
    // and printed under the table, beside the model's figures
    let out = String::from_utf8_lossy(&o.stdout).to_string();
    let line = |label: &str| {
        out.lines()
            .find(|l| l.trim_start().starts_with(label))
            .unwrap_or_else(|| panic!("no {label} line in\n{out}"))
            .to_string()
    };
    let figures = |s: &figures::Score| format!("{:.2} {:.4}", s.psnr_mean, s.ssim_mean);
    // PSNR and SSIM: the first two numbers after the label.
    let first_two = |l: String| {
        let words: Vec<&str> = l.split_whitespace().collect();
        let at = words.iter().position(|w| w.parse::<f64>().is_ok()).unwrap();
        words[at..at + 2].join(" ")
    };
    assert_eq!(
        first_two(line("nearest train frame")),
        figures(&want.nearest)
    );
    assert_eq!(first_two(line("linear blend")), figures(&want.blend));
    assert_eq!(first_two(line("event pseudo image")), figures(&events));
    // The baselines' images beside the run: the blend's score the blend's PSNR against
    // the test frames, and on the moving objects' pixels (ids from synth.json, masks
    // gt/test/object_NNNN.png) the PSNR written out here.
    let run_dir = root.join("runs/a");
    let moving = moving_ids(&scene_dir);
    let level = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as f64;
    let (mut whole, mut on_moving, mut on_still) = (0.0, 0.0, 0.0);
    for (k, f) in scene.test.frames.iter().enumerate() {
        let img = read_image(run_dir.join(format!("baselines/blend/{k:04}.png"))).unwrap();
        let target = read_image(scene.image_path(f)).unwrap();
        let (_, _, ids) =
            synth::gt::read_object_png(scene_dir.join(format!("gt/test/object_{k:04}.png")))
                .unwrap();
        let (mut all, mut mv, mut n) = (0.0, 0.0, 0usize);
        for (i, (&a, &b)) in img.data.iter().zip(&target.data).enumerate() {
            let e = (level(a) - level(b)).powi(2);
            all += e;
            if moving.contains(&ids[i / 3]) {
                mv += e;
                n += 1;
            }
        }
        assert!(n > 0, "frame {k}: no moving pixels");
        let psnr = |mse: f64| 10.0 * (255.0f64.powi(2) / mse).log10();
        whole += psnr(all / img.data.len() as f64);
        on_moving += psnr(mv / n as f64);
        on_still += psnr((all - mv) / (img.data.len() - n) as f64);
    }
    let frames = scene.test.frames.len() as f64;
    assert!(
        (whole / frames - blend_ref).abs() < 1e-9,
        "{whole} vs {blend_ref}"
    );
    let got = b["blend"]["moving_psnr_mean"].as_f64().unwrap();
    assert!(
        (got - on_moving / frames).abs() < 1e-9,
        "{got} vs {on_moving}"
    );
    // and on the others (the still scene), whose error the moving pixels' hides
    let got = b["blend"]["still_psnr_mean"].as_f64().unwrap();
    assert!(
        (got - on_still / frames).abs() < 1e-9,
        "{got} vs {on_still}"
    );
    assert!(
        m["still_psnr_mean"].as_f64().is_some(),
        "the model's still pixels"
    );
    // The model's exact frame (frame 0) scores the cap on its moving pixels too.
    assert_eq!(m["frames"][0]["moving_psnr"].as_f64(), Some(100.0));
    // The sheet: the frame, then model, event image and blend each with its difference.
    let sheet = read_image(run_dir.join("test_sheet.png")).unwrap();
    let first = read_image(scene.image_path(&scene.test.frames[0])).unwrap();
    let z = 128u32.div_ceil(first.width);
    assert_eq!(
        (sheet.width, sheet.height),
        (7 * z * first.width + 6 * 2, 2 * z * first.height + 2)
    );
    // The error map: model, event image, blend; each pixel's |error| (channel mean)
    // averaged over the two frames, ×8, as 8-bit grey.
    let map = read_image(run_dir.join("test_error_map.png")).unwrap();
    let (w, h) = (first.width, first.height);
    assert_eq!((map.width, map.height), (3 * z * w + 2 * 2, z * h));
    let code =
        |x: u32, y: u32| (map.data[((y * map.width + x) * map.channels) as usize] * 255.0).round();
    // the model: frame 1 off by 40 levels in one channel of pixel (0, 0), exact elsewhere
    let want = (8.0 * 40.0 / 255.0 / 3.0 / 2.0 * 255.0f64).round() as f32;
    assert_eq!(code(0, 0), want);
    assert_eq!(code(z - 1, z - 1), want);
    let off = (0..z * h)
        .flat_map(|y| (0..z * w).map(move |x| (x, y)))
        .filter(|&(x, y)| (x >= z || y >= z) && code(x, y) != 0.0)
        .map(|(x, y)| (x, y, code(x, y)))
        .collect::<Vec<_>>();
    assert!(
        off.is_empty(),
        "{} pixels: {:?}",
        off.len(),
        &off[..off.len().min(8)]
    );
    // the blend, against its images read here
    let gts: Vec<_> = (0..2)
        .map(|k| read_image(scene.image_path(&scene.test.frames[k])).unwrap())
        .collect();
    let blend: Vec<_> = (0..2)
        .map(|k| read_image(run_dir.join(format!("baselines/blend/{k:04}.png"))).unwrap())
        .collect();
    let x0 = 2 * (z * w + 2);
    for (x, y) in [(0, 0), (w / 2, h / 2), (w - 1, h - 1)] {
        let mut e = 0.0f64;
        for k in 0..2 {
            let o = ((y * w + x) * 3) as usize;
            e += (0..3)
                .map(|c| f64::from((gts[k].data[o + c] - blend[k].data[o + c]).abs()))
                .sum::<f64>()
                / 6.0;
        }
        let want = ((8.0 * e).min(1.0) * 255.0).round() as f32;
        let got = code(x0 + z * x, z * y);
        assert!(
            (got - want).abs() <= 1.0,
            "blend at ({x}, {y}): {got} vs {want}"
        );
    }
    assert!(
        out.contains("where the error stays") && out.contains("test_error_map.png"),
        "{out}"
    );
    assert!(
        line("model (gaussians renders)").contains(&format!("{:.2}", mean)),
        "{out}"
    );
    assert!(
        out.contains("2D baselines: computed from the scene"),
        "{out}"
    );
    assert!(out.contains("novel views"), "{out}");
    assert!(out.contains("cannot render a new viewpoint"), "{out}");
    // flow: |(3, -4)| = 5 px/s for every non-noise event (f32 rounding of gt + 3)
    assert_eq!(m["flow_source"], "gt/event_flow.bin");
    assert_eq!(
        m["flow_events"].as_u64().unwrap() as usize,
        gt.len() - noise
    );
    let epe = m["flow_epe"].as_f64().unwrap();
    assert!((epe - 5.0).abs() < 1e-3, "{epe}");
    let err_px = m["flow_err_px"].as_f64().unwrap();
    assert!((err_px - 5.0 * 0.125).abs() < 1e-3, "{err_px}");
    assert_eq!(m["flow_outliers"], 0.0);

    // compare by run directory and by experiment name (with --cache)
    let o = degs(&[
        "compare",
        run_a.to_str().unwrap(),
        "b",
        "--cache",
        root.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let table = String::from_utf8_lossy(&o.stdout).to_string();
    let lines: Vec<&str> = table.lines().collect();
    assert_eq!(lines.len(), 3, "{table}");
    assert!(lines[0].contains("PSNR dB") && lines[0].contains("EPE px/s"));
    assert!(lines[0].contains("novel dB") && lines[0].contains("novel SSIM"));
    let cols = |l: &str| l.split_whitespace().map(str::to_string).collect::<Vec<_>>();
    let ca = cols(lines[1]);
    assert_eq!(ca[1], format!("{:.2}", (100.0 + psnr1) / 2.0), "{table}");
    assert_eq!(ca[3], "2");
    assert_eq!(ca[4], format!("{:.2}", (100.0 + novel1) / 2.0), "{table}");
    assert_eq!(ca[6], "5.000");
    assert_eq!(ca[7], "0.625");
    assert_eq!(ca[8], "0.0%");
    let cb = cols(lines[2]);
    assert_eq!(cb[0], "b");
    // run B rendered no novel views
    assert_eq!(&cb[1..7], ["100.00", "1.0000", "2", "-", "-", "-"]);
    assert!(root.join("runs/b/metrics.json").is_file());
}

#[test]
fn eval_errors_name_what_is_wrong() {
    let Exact {
        dir: _d,
        root,
        scene_dir,
        scene: _,
        g,
    } = exact_renders(false);
    fs::remove_file(g.join("renders/0001.png")).unwrap();
    fabricate_run(&root, "short", &scene_dir, &g, None);
    let o = degs(&["eval", root.join("runs/short").to_str().unwrap()]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(err.contains("2 test frames but 1 renders"), "{err}");
    assert!(err.contains("renders"), "{err}");

    let o = degs(&["eval", "no-such-run", "--cache", root.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("no-such-run"));

    let bad = root.join("runs/bad");
    fs::create_dir_all(&bad).unwrap();
    fs::write(bad.join("run.json"), "{ truncated").unwrap();
    let o = degs(&["eval", bad.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("run.json"));
}

/// The nearest-frame and linear-blend baselines by their definitions, from the PNGs
/// decoded by the `image` crate: the train frame nearest in time (the earlier one on a
/// tie), and `(1 − s)·a + s·b` of the two neighbouring train frames on the stored values
/// (`s` the fraction of the interval); mean PSNR over the test frames on 8-bit levels.
fn reference_nearest_and_blend(dir: &Path) -> (f64, f64) {
    let scene = Scene::open(dir).unwrap();
    let load = |f: &scene::manifest::Frame| -> Vec<f32> {
        let img = image::open(scene.image_path(f)).unwrap().to_rgb8();
        img.as_raw().iter().map(|&v| v as f32 / 255.0).collect()
    };
    let psnr = |a: &[f32], b: &[f32]| {
        let level = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as f64;
        let mse = a
            .iter()
            .zip(b)
            .map(|(&x, &y)| (level(x) - level(y)).powi(2))
            .sum::<f64>()
            / a.len() as f64;
        10.0 * (255.0f64 * 255.0 / mse).log10()
    };
    let train: Vec<(f64, Vec<f32>)> = scene
        .train
        .frames
        .iter()
        .map(|f| (f.timestamp, load(f)))
        .collect();
    let (mut near, mut blend) = (0.0, 0.0);
    for f in &scene.test.frames {
        let t = f.timestamp;
        let j = train.iter().rposition(|(tj, _)| *tj <= t).unwrap();
        assert!(
            j + 1 < train.len(),
            "a test frame after the last train frame"
        );
        let ((ta, a), (tb, b)) = (&train[j], &train[j + 1]);
        let s = ((t - ta) / (tb - ta)) as f32;
        let target = load(f);
        near += psnr(if s <= 0.5 { a } else { b }, &target);
        let mix: Vec<f32> = a
            .iter()
            .zip(b)
            .map(|(x, y)| (1.0 - s) * x + s * y)
            .collect();
        blend += psnr(&mix, &target);
    }
    let n = scene.test.frames.len() as f64;
    (near / n, blend / n)
}

/// The two-sided event pseudo image by its definition (Eq. 11 from both neighbours),
/// on a scene with linear frames: per pixel and channel, the left frame carried to `t`
/// by the events of `(ta, t]` (`ln I_a + C·n`) and the right one back by those of
/// `(t, tb]` (`ln I_b − C·n`), each side only where its frame lies in [0.01, 1), blended
/// in log space by `s = (t − ta)/(tb − ta)`; where no side is usable, or the result
/// leaves [0.01, 1], the linear blend. Mean PSNR on 8-bit levels over the test frames.
fn reference_event_pseudo_image(dir: &Path) -> f64 {
    let scene = Scene::open(dir).unwrap();
    let c = scene.contrast_threshold();
    let ev = scene.load_events().unwrap();
    let load = |f: &scene::manifest::Frame| -> Vec<f64> {
        let img = image::open(scene.image_path(f)).unwrap().to_rgb32f();
        img.as_raw().iter().map(|&v| v as f64).collect()
    };
    let (w, h) = (ev.width as usize, ev.height as usize);
    let net = |t0: f64, t1: f64| {
        let mut n = vec![0.0f64; w * h];
        for i in 0..ev.len() {
            if ev.t[i] > t0 && ev.t[i] <= t1 {
                n[ev.y[i] as usize * w + ev.x[i] as usize] += f64::from(ev.p[i]);
            }
        }
        n
    };
    let train: Vec<(f64, Vec<f64>)> = scene
        .train
        .frames
        .iter()
        .map(|f| (f.timestamp, load(f)))
        .collect();
    let mut total = 0.0;
    for f in &scene.test.frames {
        let t = f.timestamp;
        let j = train.iter().rposition(|(tj, _)| *tj <= t).unwrap();
        let ((ta, a), (tb, b)) = (&train[j], &train[j + 1]);
        let s = (t - ta) / (tb - ta);
        let (nl, nr) = (net(*ta, t), net(t, *tb));
        let usable = |v: f64| (0.01..1.0).contains(&v);
        let target = load(f);
        let mut mse = 0.0;
        for k in 0..target.len() {
            let p = k / 3;
            let left = usable(a[k]).then(|| a[k].ln() + c * nl[p]);
            let right = usable(b[k]).then(|| b[k].ln() - c * nr[p]);
            let blend = (1.0 - s as f32 as f64) * a[k] + (s as f32 as f64) * b[k];
            let log = match (left, right) {
                (Some(l), Some(r)) => Some((1.0 - s) * l + s * r),
                (x, None) | (None, x) => x,
            };
            let v = log
                .map(f64::exp)
                .filter(|v| (0.01..=1.0).contains(v))
                .unwrap_or(blend);
            let level = |x: f64| (x.clamp(0.0, 1.0) * 255.0).round();
            mse += (level(v) - level(target[k])).powi(2);
        }
        mse /= target.len() as f64;
        total += 10.0 * (255.0f64.powi(2) / mse).log10();
    }
    total / scene.test.frames.len() as f64
}

/// An image as the LPIPS crate takes it (3 channels, as `read_image` gives).
fn lpips_rgb(i: &scene::image_io::Image) -> lpips::Rgb<'_> {
    lpips::Rgb {
        data: &i.data,
        width: i.width as usize,
        height: i.height as usize,
    }
}

/// The 2D baselines of the scene's test frames, computed as the deform stage does.
fn scene_baselines(dir: &Path) -> figures::BaselineFigures {
    let out = tempfile::tempdir().unwrap();
    baselines::compute(&Scene::open(dir).unwrap(), out.path())
        .unwrap()
        .unwrap()
        .0
}

#[test]
fn eval_scores_the_baselines_itself_not_from_the_deform_report() {
    let Exact {
        dir: d,
        root,
        scene_dir,
        scene,
        g,
    } = exact_renders(false);
    // the deform entry: its renders (one off by 40 levels) and its report's baselines
    let deform = d.path().join("deform");
    let psnr1 = renders(&deform, &scene, 40.0);
    fs::write(
        deform.join("report.json"),
        r#"{"test": {"psnr_mean": 1.0}, "baselines": {
            "nearest": {"psnr_mean": 21.125, "ssim_mean": 0.625, "psnr": [20.0, 22.25]},
            "blend": {"psnr_mean": 23.5, "ssim_mean": 0.75, "psnr": [23.0, 24.0]},
            "events": {"psnr_mean": 24.875, "ssim_mean": 0.8125, "psnr": [24.0, 25.75]}}}"#,
    )
    .unwrap();
    fabricate_run_with(&root, "j", &scene_dir, &g, None, Some(&deform));
    let run = root.join("runs/j");
    let o = degs(&["eval", run.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout).to_string();
    let block: Vec<&str> = out
        .lines()
        .skip_while(|l| !l.starts_with("test frames"))
        .collect();
    let cols = |l: &str| l.split_whitespace().map(str::to_string).collect::<Vec<_>>();
    let mean = format!("{:.2}", (100.0 + psnr1) / 2.0);
    assert_eq!(
        cols(block[1])[..3],
        ["model", "(deform", "renders)"],
        "{out}"
    );
    assert_eq!(cols(block[1])[3], mean, "{out}");
    // The baselines are the scene's own, scored with their images, not the report's
    // (whose figures here are made up).
    let want = scene_baselines(&scene_dir);
    let two = |s: &figures::Score| [format!("{:.2}", s.psnr_mean), format!("{:.4}", s.ssim_mean)];
    assert_eq!(cols(block[2])[3..5], two(&want.nearest), "{out}");
    assert_eq!(cols(block[3])[2..4], two(&want.blend), "{out}");
    assert_eq!(
        cols(block[4])[4..6],
        two(want.events.as_ref().unwrap()),
        "{out}"
    );
    assert_eq!(block[5], "  2D baselines: computed from the scene", "{out}");
    // where to look: the sheet and the error map, then (no novel views rendered by the
    // deform entry) no novel block
    assert!(block[6].ends_with("test_sheet.png"), "{out}");
    assert!(block[7].ends_with("test_error_map.png"), "{out}");
    assert_eq!(block.len(), 8, "{out}");
    let m: serde_json::Value =
        serde_json::from_slice(&fs::read(run.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(m["render_stage"], "deform");
    assert!(
        (m["baselines"]["blend"]["psnr_mean"].as_f64().unwrap() - want.blend.psnr_mean).abs()
            < 1e-9
    );
    assert!(m["baselines_note"].is_null());
    assert!(m["novel_psnr_mean"].is_null());
}

#[test]
fn eval_reports_lpips_beside_psnr_when_the_weights_are_there() {
    let Exact {
        dir: _d,
        root,
        scene_dir,
        scene: _,
        g,
    } = exact_renders(false);
    // Frame 1's render: every value moved by a quarter of the range (clamped).
    let f1 = g.join("renders/0001.png");
    let mut img = read_image(&f1).unwrap();
    img.data.iter_mut().for_each(|v| *v = (*v + 0.25).min(1.0));
    write_png(&f1, &img).unwrap();
    fabricate_run(&root, "lp", &scene_dir, &g, None);
    let run = root.join("runs/lp");
    let Some((o, m)) = eval_with_lpips(&run) else {
        return;
    };
    assert_eq!(m["lpips_net"], "vgg");
    let frames = m["frames"].as_array().unwrap();
    let l0 = frames[0]["lpips"].as_f64().unwrap();
    let l1 = frames[1]["lpips"].as_f64().unwrap();
    assert!(l0.abs() < 1e-9, "an exact render scores {l0}");
    assert!(l1 > 0.01, "a brightened render scores {l1}");
    let mean = m["lpips_mean"].as_f64().unwrap();
    assert!((mean - (l0 + l1) / 2.0).abs() < 1e-12);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("LPIPS (vgg"), "{out}");
    // The blend's LPIPS, whole and over the moving objects' pixels, as the metric gives
    // them on its images beside the run.
    let net = lpips::Lpips::load_cached(lpips::Variant::Vgg).unwrap();
    let scene = Scene::open(&scene_dir).unwrap();
    let moving_objects = moving_ids(&scene_dir);
    let (mut whole, mut moving, mut still) = (0.0, 0.0, 0.0);
    for (k, f) in scene.test.frames.iter().enumerate() {
        let a = read_image(scene.image_path(f)).unwrap();
        let b = read_image(run.join(format!("baselines/blend/{k:04}.png"))).unwrap();
        let d = net.distance_and_map(lpips_rgb(&a), lpips_rgb(&b)).unwrap();
        let (_, _, ids) =
            synth::gt::read_object_png(scene_dir.join(format!("gt/test/object_{k:04}.png")))
                .unwrap();
        let mask: Vec<bool> = ids.iter().map(|o| moving_objects.contains(o)).collect();
        whole += d.distance;
        moving += d.masked_mean(&mask).unwrap().unwrap();
        let others: Vec<bool> = mask.iter().map(|m| !m).collect();
        still += d.masked_mean(&others).unwrap().unwrap();
    }
    let n = scene.test.frames.len() as f64;
    let blend = &m["baselines"]["blend"];
    let got = blend["lpips_mean"].as_f64().unwrap();
    assert!((got - whole / n).abs() < 1e-9, "{got} vs {}", whole / n);
    let got = blend["moving_lpips_mean"].as_f64().unwrap();
    assert!((got - moving / n).abs() < 1e-9, "{got} vs {}", moving / n);
    let got = blend["still_lpips_mean"].as_f64().unwrap();
    assert!((got - still / n).abs() < 1e-9, "{got} vs {}", still / n);
    // Off: no LPIPS, and the note says so.
    let o = degs(&["eval", run.to_str().unwrap()]);
    assert!(o.status.success());
    let m: serde_json::Value =
        serde_json::from_slice(&fs::read(run.join("metrics.json")).unwrap()).unwrap();
    assert!(m["lpips_mean"].is_null() && m["frames"][0].get("lpips").is_none());
    assert!(m["lpips_note"].as_str().unwrap().contains("off"));
}
