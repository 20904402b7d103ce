//! `degs demo` and `degs stress` over the real stage binaries at a tiny size (the
//! runner tests use fake stages that copy the test images, so every score there is
//! 100 dB): the demo's reported test PSNR against one computed here from its renders
//! and the scene's test images, and the stress report's "below RGB-only" verdict
//! against the figures in its own record.

use degs_tests::{TINY_STAGES, Workspace, bin_dir, binary, stderr};
use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// Mean PSNR (dB) over the test frames of `renders/NNNN.png` against the scene's
/// `images/test_NNNN.png`, on 8-bit levels of images the `image` crate decodes.
fn psnr_of_renders(renders: &Path, scene: &Path) -> f64 {
    let levels = |p: &Path| -> Vec<f64> {
        let img = image::open(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        img.to_rgb32f()
            .as_raw()
            .iter()
            .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as f64)
            .collect()
    };
    let mut sum = 0.0;
    let mut n = 0;
    while scene.join(format!("images/test_{n:04}.png")).is_file() {
        let a = levels(&scene.join(format!("images/test_{n:04}.png")));
        let b = levels(&renders.join(format!("{n:04}.png")));
        assert_eq!(a.len(), b.len());
        let mse = a.iter().zip(&b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64;
        sum += 10.0 * (255.0f64.powi(2) / mse).log10();
        n += 1;
    }
    assert!(n > 0, "no test images in {}", scene.display());
    sum / n as f64
}

#[test]
fn the_real_demo_reports_what_its_renders_score() {
    let w = Workspace::new();
    let out = w.dir.path().join("demo");
    let run = || {
        Command::new(binary("degs"))
            .args(["demo", "--out", out.to_str().unwrap(), "--stages"])
            .arg(bin_dir())
            .args([
                "--set",
                "width=24",
                "--set",
                "height=24",
                "--set",
                "duration=0.25",
            ])
            .args(["--set", "render_rate_hz=200", "--set", "supersample=1"])
            .args(["--set", "test_frames=2"])
            .args([
                "--iterations",
                "120",
                "--epochs",
                "1",
                "--deform-iterations",
                "20",
            ])
            .args(["-j", "1"])
            .env_remove("DEGS_CACHE")
            .env("DEGS_LPIPS", "off")
            .output()
            .unwrap()
    };
    let o = run();
    assert!(o.status.success(), "{}", stderr(&o));
    let s: Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    for st in s["stages"].as_array().unwrap() {
        assert_eq!(st["action"], "ran", "{st}");
    }
    let psnr = s["psnr"].as_f64().unwrap();
    let renders = Path::new(s["renders"].as_str().unwrap());
    let scene = Path::new(s["scene"].as_str().unwrap());
    let want = psnr_of_renders(renders, scene);
    assert!(want.is_finite() && want < 60.0, "real renders: {want} dB");
    assert!(
        (psnr - want).abs() < 1e-6,
        "summary {psnr} dB, renders {want} dB"
    );
    let printed = String::from_utf8_lossy(&o.stdout).to_string() + &stderr(&o);
    assert!(printed.contains(&format!("{psnr:.2} dB")), "{printed}");
    // A second demo builds nothing.
    let o = run();
    assert!(o.status.success(), "{}", stderr(&o));
    let s: Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    for st in s["stages"].as_array().unwrap() {
        assert_eq!(st["action"], "cached", "{st}");
    }
}

#[test]
fn a_real_stress_run_says_where_degs_is_below_rgb_only_as_its_figures_do() {
    let w = Workspace::new();
    let stages = TINY_STAGES.replace("\n[", "\n[base.");
    let file = w.dir.path().join("st.toml");
    std::fs::write(
        &file,
        format!(
            "name = \"st\"\n[base]\nname = \"b\"\n[base.scene]\nsynth = \"rigid\"\n\
             [base.scene.settings]\nwidth = 24\nheight = 24\nduration = 0.25\n\
             render_rate_hz = 200\nsupersample = 1\ntest_frames = 2\n\
             {stages}\n[stresses]\nfps = [4]\n"
        ),
    )
    .unwrap();
    let o = w.degs(&["stress", file.to_str().unwrap(), "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let dir = w.cache.join("runs/st");
    let rec: Value =
        serde_json::from_slice(&std::fs::read(dir.join("stress.json")).unwrap()).unwrap();
    let results = rec["results"].as_array().unwrap();
    assert_eq!(results.len(), 4, "{rec}");
    let psnr = |variant: &str, method: &str| {
        let r = results
            .iter()
            .find(|r| r["variant"] == variant && r["method"] == method)
            .unwrap_or_else(|| panic!("{variant} {method}"));
        assert_eq!(r["status"], "ok", "{r}");
        assert!(r["non_finite"].as_array().unwrap().is_empty(), "{r}");
        let p = r["psnr"].as_f64().unwrap();
        assert!(p.is_finite() && p < 60.0, "{r}");
        p
    };
    let report = std::fs::read_to_string(dir.join("report.md")).unwrap();
    let below: Vec<&str> = ["clean", "fps-4"]
        .into_iter()
        .filter(|v| psnr(v, "degs") < psnr(v, "rgb"))
        .collect();
    if below.is_empty() {
        assert!(
            report.contains("DEGS is not below RGB-only at any level."),
            "{report}"
        );
    } else {
        assert!(
            report.contains("**DEGS falls below RGB-only at:**"),
            "{report}"
        );
        for v in &below {
            let (d, g) = (psnr(v, "degs"), psnr(v, "rgb"));
            assert!(
                report.contains(&format!("({d:.2} < {g:.2} dB)")),
                "{v}:\n{report}"
            );
        }
    }
    assert!(report.contains("no figure is NaN"), "{report}");
}
