//! `degs run` over the real stage binaries on a tiny synthetic scene (32×32 px, three
//! train and two test frames, one LoCM epoch, 200 warm-up and 30 joint iterations: a few seconds
//! on two cores): every built stage leaves a cache entry with its report, a second run
//! runs nothing, the warm-up beats the mean-colour baseline on the test frames, and
//! both the warm-up and the joint training score the novel views (15° off the path),
//! and the joint training's LPIPS (model and 2D baselines, scored in memory) is
//! `degs eval`'s (scored from the PNG files).

use degs_tests::{TINY_STAGES, Workspace, entry, read_json, stage_record, stderr};

const SCENE: &str = r#"
name = "tiny"

[scene]
synth = "rigid"

[scene.settings]
width = 32
height = 32
duration = 0.25
render_rate_hz = 200
test_frames = 2
supersample = 1
"#;

const BUILT: [&str; 5] = ["synth", "evflow", "gaussians", "assoc", "deform"];

#[test]
fn degs_run_builds_every_stage_once_and_beats_the_mean_colour() {
    let w = Workspace::new();
    let lpips = degs_tests::lpips_weights();
    let exp = w.experiment("tiny", &format!("{SCENE}\n{TINY_STAGES}"));
    let exp = exp.to_str().unwrap();

    let out = w.degs(&["run", exp, "-j", "2", "--quiet"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let first = w.run_record("tiny");
    assert_eq!(first["status"], "ok", "{first}");
    for stage in BUILT {
        let s = stage_record(&first, stage);
        assert_eq!(s["action"], "ran", "{stage}: {s}");
        let dir = entry(&first, stage);
        assert!(
            dir.starts_with(w.cache.join("cache").join(stage)),
            "{stage}: {}",
            dir.display()
        );
        assert!(read_json(&dir.join("report.json")).is_object(), "{stage}");
    }

    // the test PSNR of the warm-up the run built, against predicting each test frame
    // by its own mean colour
    let report = read_json(&entry(&first, "gaussians").join("report.json"));
    let psnr = report["test"]["psnr_mean"].as_f64().unwrap();
    let baseline = report["test"]["mean_colour_psnr_mean"].as_f64().unwrap();
    assert!(
        psnr.is_finite() && psnr > baseline,
        "test PSNR {psnr} dB, mean colour {baseline} dB"
    );
    assert_novel_views(&entry(&first, "gaussians"), &report);

    // the joint training: finite losses of every term, rebinding, a PoseNet, a test PSNR
    let dir = entry(&first, "deform");
    let report = read_json(&dir.join("report.json"));
    assert_eq!(report["iterations"], 30, "{report}");
    assert!(report["rebinds"].as_u64().unwrap() >= 3, "{report}");
    let curve = report["curve"].as_array().unwrap();
    assert_eq!(curve.len(), 6, "{report}");
    for p in curve {
        for k in ["l_rgb", "l_event", "l_motion", "total"] {
            let v = p[k].as_f64().unwrap();
            assert!(v.is_finite() && v >= 0.0, "{k} = {v} at {p}");
        }
    }
    assert!(
        curve.iter().any(|p| p["l_event"].as_f64().unwrap() > 0.0),
        "{report}"
    );
    assert!(dir.join("posenet.safetensors").is_file());
    let psnr = report["test"]["psnr_mean"].as_f64().unwrap();
    assert!(
        psnr.is_finite() && psnr > baseline,
        "deform test PSNR {psnr} dB"
    );
    assert_novel_views(&dir, &report);
    // the 2D baselines are scored on the test frames only
    assert!(
        report["baselines"]["blend"]["psnr_mean"]
            .as_f64()
            .unwrap()
            .is_finite()
    );
    assert!(report["novel"].get("baselines").is_none(), "{report}");
    if lpips {
        assert_lpips_is_the_evaluations(&w, &report);
    }
    // the joint model's size, as the warm-up reports it: the files' bytes
    let size = &report["model_size"];
    assert_eq!(size["gaussians"], report["gaussians"], "{report}");
    let ply = std::fs::metadata(dir.join("point_cloud.ply"))
        .unwrap()
        .len();
    assert_eq!(size["bytes"]["ply"].as_u64(), Some(ply), "{report}");
    let parts: u64 = ["ply", "field", "dynamic_flags", "model_json"]
        .iter()
        .map(|k| size["bytes"][k].as_u64().unwrap())
        .sum();
    assert_eq!(size["bytes"]["total"].as_u64(), Some(parts), "{report}");

    // everything is cached: the second run runs nothing
    let out = w.degs(&["run", exp, "-j", "2", "--quiet"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let second = w.run_record("tiny");
    for stage in BUILT {
        let s = stage_record(&second, stage);
        assert_eq!(s["action"], "cached", "{stage}: {s}");
        assert_eq!(s["key"], stage_record(&first, stage)["key"], "{stage}");
    }
    for s in second["stages"].as_array().unwrap() {
        assert!(
            !["ran", "rebuilt", "failed"].contains(&s["action"].as_str().unwrap()),
            "{s}"
        );
    }

    // `degs export`: the joint model as a PLY sequence at 8 frames per second over the
    // recording (its train frames span 0.25 s: 3 files), in runs/tiny/export/, each of
    // the model's Gaussian count; a second export finds it cached and replaces the folder
    let model = read_json(&entry(&first, "deform").join("model.json"));
    let gaussians = model["gaussians"].as_u64().unwrap();
    for _ in 0..2 {
        let out = w.degs(&["export", "tiny", "--fps", "8"]);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let dir = w.cache.join("runs/tiny/export");
    let times = read_json(&dir.join("times.json"));
    let times = times.as_array().unwrap();
    assert_eq!(times.len(), 3, "{times:?}");
    for (k, t) in times.iter().enumerate() {
        let file = format!("frame_{:04}.ply", k + 1);
        assert_eq!(t["file"], file.as_str());
        assert!(
            (t["seconds"].as_f64().unwrap() - k as f64 / 8.0).abs() < 1e-9,
            "{t}"
        );
        let bytes = std::fs::read(dir.join(&file)).unwrap();
        let header = String::from_utf8_lossy(&bytes[..bytes.len().min(400)]).to_string();
        assert!(
            header.contains(&format!("element vertex {gaussians}\n")),
            "{header}"
        );
    }
    assert!(dir.join("sequence.zip").is_file());
    assert!(
        !dir.join(".degs-entry.json").exists(),
        "the cache's manifest stays out"
    );

    // `degs render`: the joint model along the recorded path at 12 frames per second of
    // recording time (0.25 s: 4 frames) in runs/tiny/video/; then along the cameras it
    // wrote, given back as a file: the same frames again, a node of its own.
    let out = w.degs(&["render", "tiny", "--fps", "12"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let said = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        said.contains("4 frames of the deform model (recorded path"),
        "{said}"
    );
    let video = w.cache.join("runs/tiny/video");
    let first_frames: Vec<Vec<u8>> = (1..=4)
        .map(|k| std::fs::read(video.join(format!("frames/{k:04}.png"))).unwrap())
        .collect();
    assert!(video.join("preview.gif").is_file());
    let cams = w.cache.join("cams.json");
    std::fs::copy(video.join("cameras.json"), &cams).unwrap();
    let out = w.degs(&["render", "tiny", "--path", cams.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    for (k, before) in first_frames.iter().enumerate() {
        let again = std::fs::read(video.join(format!("frames/{:04}.png", k + 1))).unwrap();
        assert!(
            again == *before,
            "frame {k} differs when rendered from cameras.json"
        );
    }
    let report = read_json(&video.join("report.json"));
    assert_eq!(report["path"], cams.to_str().unwrap(), "{report}");
}

/// The deform report's test LPIPS (model, novel views, nearest frame and blend, from the
/// images in memory) against `degs eval`'s (the evaluate stage: the PNGs read back).
fn assert_lpips_is_the_evaluations(w: &Workspace, report: &serde_json::Value) {
    let out = w.degs(&["eval", "tiny"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let m = read_json(&w.cache.join("runs/tiny/metrics.json"));
    assert_eq!(m["lpips_net"], "vgg", "{m}");
    let close = |stage: &serde_json::Value, eval: &serde_json::Value, what: &str| {
        let (a, b) = (stage.as_f64(), eval.as_f64());
        let (Some(a), Some(b)) = (a, b) else {
            panic!("{what}: report {stage}, eval {eval}");
        };
        assert!(
            a > 0.0 && (a - b).abs() < 1e-5,
            "{what}: report {a}, eval {b}"
        );
    };
    close(&report["test"]["lpips_mean"], &m["lpips_mean"], "test");
    close(
        &report["novel"]["lpips_mean"],
        &m["novel_lpips_mean"],
        "novel",
    );
    for b in ["nearest", "blend"] {
        let stage = &report["baselines"][b]["lpips_mean"];
        close(stage, &m["baselines"][b]["lpips_mean"], b);
    }
    // the event pseudo image differs by design: the stage's uses the C it trained with,
    // the evaluation's the scene's
    let events = report["baselines"]["events"]["lpips_mean"]
        .as_f64()
        .unwrap();
    assert!(events > 0.0 && events < 1.0, "{report}");
}

/// A stage's report has a `novel` section for the scene's two novel views, with a
/// finite PSNR above the mean-colour baseline's, and their renders.
fn assert_novel_views(dir: &std::path::Path, report: &serde_json::Value) {
    let novel = &report["novel"];
    assert_eq!(novel["frames"], 2, "{report}");
    let psnr = novel["psnr_mean"].as_f64().unwrap();
    let baseline = novel["mean_colour_psnr_mean"].as_f64().unwrap();
    assert!(
        psnr.is_finite() && psnr > baseline,
        "{}: novel PSNR {psnr} dB, mean colour {baseline} dB",
        dir.display()
    );
    assert_eq!(novel["psnr"].as_array().unwrap().len(), 2);
    for i in 0..2 {
        let render = dir.join(format!("renders/novel/{i:04}.png"));
        assert!(render.is_file(), "{}", render.display());
    }
}

/// `rigid` at 64² over 1 s (9 train frames): enough for the tracks init to lift the box
/// and the ball as moving; the warm-up stopped after its init.
const MOVING: &str = r#"
name = "moving"

[scene]
synth = "rigid"

[scene.settings]
width = 64
height = 64
render_rate_hz = 200
supersample = 1

[gaussians]
iterations = 1
static_iterations = 0

[gaussians.size]
tolerance_db = 0
"#;

#[test]
fn what_a_stage_warns_of_reaches_the_record_the_output_and_eval() {
    // The scene's box and ball move and it has no depth priors, so the warm-up placed
    // their Gaussians at a distance nothing gave, and says so in its report: `degs run`
    // keeps that in the run record and prints it, `degs eval` prints it and writes it
    // into metrics.json beside the novel views' figures it concerns.
    let w = Workspace::new();
    let exp = w.experiment("moving", MOVING);
    let out = w.degs(&[
        "run",
        exp.to_str().unwrap(),
        "--until",
        "gaussians",
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let record = w.run_record("moving");
    let report = read_json(&entry(&record, "gaussians").join("report.json"));
    let said = report["warnings"].as_array().unwrap();
    assert_eq!(said.len(), 1, "{}", report["tracks_init"]);
    let text = said[0].as_str().unwrap();
    assert!(
        text.contains("without a depth prior") && text.contains("no depth priors"),
        "{text}"
    );
    assert_eq!(
        stage_record(&record, "gaussians")["warnings"],
        report["warnings"]
    );
    let line = format!("warning (gaussians): {text}");
    assert!(stderr(&out).contains(&line), "{}", stderr(&out));
    // (LPIPS is not what this checks.)
    let out = w.degs_with(&["eval", "moving"], &[("DEGS_LPIPS", "off")]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains(&line), "{}", stderr(&out));
    let metrics = read_json(&w.cache.join("runs/moving/metrics.json"));
    assert_eq!(metrics["warnings"], serde_json::json!([line]), "{metrics}");
}
