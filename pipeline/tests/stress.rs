//! `degs stress` end to end through the `degs` binary: a real tiny synthetic scene and
//! its transforms, fake stages (the gaussians fake renders the test frames exactly).

mod common;
use common::{Fixture, stderr, stdout};
use serde_json::Value;
use std::fs;

#[test]
fn a_tiny_stress_run_writes_its_record_report_and_charts_without_nan() {
    let f = Fixture::new();
    let p = f.dir.path().join("st.toml");
    fs::write(
        &p,
        "name = \"st\"\n[base]\nname = \"b\"\n[base.scene]\nsynth = \"rigid\"\n\
         [base.scene.settings]\nwidth = 24\nheight = 16\nduration = 0.25\nrender_rate_hz = 200\n\
         supersample = 1\nframe_supersample = 1\ntrain_fps = 20\nnovel_angle_deg = 0\n\
         [stresses]\nfps = [20, 10]\nnoise_hz = [5]\ngap_fraction = [0.25]\n\
         corrupt = [\"nan-pose\", \"missing-frame\"]\n",
    )
    .unwrap();
    let out = f.degs(&["stress", p.to_str().unwrap(), "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stdout(&out).contains("14 runs (4 with an error)"),
        "{}",
        stdout(&out)
    );
    let dir = f.cache.join("runs").join("st");
    let rec: Value = serde_json::from_slice(&fs::read(dir.join("stress.json")).unwrap()).unwrap();
    let results = rec["results"].as_array().unwrap();
    // clean, fps-20, fps-10, noise-hz-5, gap-fraction-0.25, two corruptions; × 2 methods
    assert_eq!(results.len(), 14);
    let get = |variant: &str, method: &str| {
        results
            .iter()
            .find(|r| r["variant"] == variant && r["method"] == method)
            .unwrap_or_else(|| panic!("{variant} {method}"))
    };
    for r in results {
        assert_eq!(r["non_finite"].as_array().unwrap().len(), 0, "{r}");
    }
    for v in [
        "clean",
        "fps-20",
        "fps-10",
        "noise-hz-5",
        "gap-fraction-0.25",
    ] {
        for m in ["degs", "rgb"] {
            let r = get(v, m);
            assert_eq!(r["status"], "ok", "{r}");
            // the fake renders are the test frames: PSNR at its cap
            assert_eq!(r["psnr"].as_f64(), Some(100.0), "{r}");
            assert!(r["nearest_psnr"].as_f64().unwrap() > 5.0, "{r}");
        }
    }
    assert_eq!(get("fps-10", "degs")["train_frames"], 3);
    assert_eq!(get("clean", "degs")["train_frames"], 6);
    // the synth node of fps-20 is the clean one: only 5 scenes were generated
    let log = fs::read_to_string(&f.log).unwrap();
    assert_eq!(
        log.lines()
            .filter(|l| l.starts_with("start deform"))
            .count(),
        12
    );
    assert_eq!(
        log.lines()
            .filter(|l| l.starts_with("start gaussians"))
            .count(),
        6
    );
    let err = get("corrupt-nan-pose", "degs")["error"].as_str().unwrap();
    assert!(err.contains("transforms_train.json"), "{err}");
    let err = get("corrupt-missing-frame", "rgb")["error"]
        .as_str()
        .unwrap();
    assert!(
        err.contains("does not exist") && err.contains(".png"),
        "{err}"
    );

    let report = fs::read_to_string(dir.join("report.md")).unwrap();
    for want in [
        "## fps",
        "## noise_hz",
        "## gap_fraction",
        "## corrupt",
        "no figure is NaN",
    ] {
        assert!(report.contains(want), "{want}:\n{report}");
    }
    for chart in ["stress-fps", "stress-noise_hz", "stress-gap_fraction"] {
        let img = scene::image_io::read_image(dir.join(format!("{chart}.png"))).unwrap();
        assert_eq!((img.width, img.height), (960, 640));
        assert!(
            fs::read_to_string(dir.join(format!("{chart}.svg")))
                .unwrap()
                .contains("<svg")
        );
    }
    assert!(!dir.join("stress-corrupt.png").exists());
    // LPIPS as `degs eval` gives it (fetched at first use): 0 for the fake renders, which
    // are the test frames, above 0 for the 2D baselines; a chart of it per stress
    let clean = get("clean", "degs");
    if clean["lpips"].is_null() {
        let note = clean["lpips_note"].as_str().unwrap_or_default();
        assert!(
            std::env::var("DEGS_SKIP_LPIPS").is_ok_and(|s| s == "1"),
            "no LPIPS ({note}); opt out with DEGS_SKIP_LPIPS=1"
        );
        eprintln!("SKIPPED: the stress's LPIPS ({note}) and DEGS_SKIP_LPIPS=1");
    } else {
        assert_eq!(clean["lpips"].as_f64(), Some(0.0), "{clean}");
        for b in ["nearest_lpips", "blend_lpips", "events_lpips"] {
            assert!(clean[b].as_f64().unwrap() > 1e-3, "{b}: {clean}");
        }
        let svg = fs::read_to_string(dir.join("stress-fps-lpips.svg")).unwrap();
        assert!(svg.contains("test LPIPS (VGG; lower is better)"));
        assert!(report.contains("| DEGS LPIPS |"), "{report}");
    }

    // a second run finds everything cached and writes the same results
    let again = f.degs(&["stress", p.to_str().unwrap(), "-q"]);
    assert!(again.status.success(), "{}", stderr(&again));
    let log2 = fs::read_to_string(&f.log).unwrap();
    assert_eq!(
        log2.lines().count(),
        log.lines().count(),
        "nothing ran again"
    );
    let rec2: Value = serde_json::from_slice(&fs::read(dir.join("stress.json")).unwrap()).unwrap();
    assert_eq!(rec2["results"].as_array().unwrap().len(), 14);

    // `degs gc` keeps the transformed scenes the runs read (gap and two corruptions)
    let gc = f.degs(&["gc"]);
    assert!(gc.status.success(), "{}", stderr(&gc));
    let kept = fs::read_dir(f.cache.join("cache").join("stress-scene"))
        .unwrap()
        .count();
    assert_eq!(kept, 3);
}
