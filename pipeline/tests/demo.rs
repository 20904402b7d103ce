//! `degs demo` on a tiny synthetic scene with fake stage binaries.

mod common;
use common::{Fixture, stderr, stdout};
use std::fs;
use std::path::Path;
use std::process::Output;

const TINY: [&str; 10] = [
    "--set",
    "width=24",
    "--set",
    "height=16",
    "--set",
    "duration=0.25",
    "--set",
    "render_rate_hz=200",
    "--set",
    "supersample=1",
];

fn demo(f: &Fixture, out: &Path, reports: &Path) -> Output {
    let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_degs"));
    c.args(["demo", "--out", out.to_str().unwrap(), "--stages"])
        .arg(&f.stages)
        .args(TINY)
        .env("DEGS_FAKE_LOG", &f.log)
        .env("DEGS_FAKE_REPORTS", reports)
        .env("DEGS_LPIPS", "off")
        .env_remove("DEGS_FAKE_SLEEP")
        .env_remove("DEGS_FAKE_MEET");
    c.output().unwrap()
}

fn reports(f: &Fixture) -> std::path::PathBuf {
    let dir = f.dir.path().join("reports");
    fs::create_dir_all(&dir).unwrap();
    for (stage, json) in [
        (
            "gaussians",
            r#"{"test": {"psnr_mean": 27.5, "ssim_mean": 0.91}, "novel": {"psnr_mean": 21.25}, "gaussians": 4200}"#,
        ),
        (
            "evflow",
            r#"{"flow_epe_px_s": 12.5, "flow_err_px": 0.8, "flow_outliers": 0.02, "warp_gain": 1.7}"#,
        ),
        (
            "assoc",
            r#"{"bound_fraction_mean": 0.625, "gaussians": 4200}"#,
        ),
    ] {
        fs::write(dir.join(format!("{stage}.json")), json).unwrap();
    }
    dir
}

fn row(table: &str, stage: &str) -> String {
    table
        .lines()
        .find(|l| l.starts_with(&format!("{stage} ")))
        .unwrap_or_else(|| panic!("no {stage} row in\n{table}"))
        .to_string()
}

#[test]
fn demo_runs_every_built_stage_and_summarises_it() {
    let f = Fixture::new();
    fs::remove_file(f.stages.join("deform")).unwrap();
    let reports = reports(&f);
    let out = f.dir.path().join("demo-out");
    let o = demo(&f, &out, &reports);
    assert!(o.status.success(), "{}", stderr(&o));
    let (table, err) = (stdout(&o), stderr(&o));
    assert!(
        err.contains(
            "reduced for speed: gaussians iterations = 1500 (default 3500), evflow epochs = 1"
        ),
        "{err}"
    );
    let synth = row(&table, "synth");
    assert!(synth.contains(" ran "), "{table}");
    assert!(synth.contains("test frames 8, novel views 8"), "{synth}");
    let g = row(&table, "gaussians");
    assert!(g.contains(" ran ") && g.contains(" no "), "{g}");
    assert!(
        g.contains("test PSNR 27.50 dB, SSIM 0.9100, novel PSNR 21.25 dB, Gaussians 4200"),
        "{g}"
    );
    let e = row(&table, "evflow");
    assert!(
        e.contains("EPE 12.50 px/s, EPE 0.8000 px, outliers 2.00%, warp gain 1.70"),
        "{e}"
    );
    assert!(row(&table, "assoc").contains("bound 62.50%"), "{table}");
    let d = row(&table, "deform");
    assert!(
        d.contains("unavailable")
            && d.contains("not built yet")
            && d.contains("cargo build --release -p degs-deform"),
        "{d}"
    );
    // renders are the test images and novel views here, so eval gives the PSNR cap
    // and SSIM 1 on both splits
    assert!(
        table.contains("test PSNR/SSIM:  100.00 dB / 1.0000, LPIPS off (DEGS_LPIPS=off)"),
        "{table}"
    );
    assert!(
        table.contains(
            "novel PSNR/SSIM: 100.00 dB / 1.0000, LPIPS off (DEGS_LPIPS=off) (views off the path)"
        ),
        "{table}"
    );
    assert!(table.contains("flow EPE:        12.500 px/s"), "{table}");
    let renders = table
        .lines()
        .find(|l| l.starts_with("renders:"))
        .unwrap()
        .to_string();
    assert!(renders.contains("/cache/gaussians/") && renders.contains("/renders"));
    for file in ["demo.toml", "summary.json", "events_preview.png"] {
        assert!(out.join(file).is_file(), "{file}");
    }
    assert!(out.join("runs/demo/metrics.json").is_file());
    // the stages got the demo's reduced settings through the experiment file
    let exp = fs::read_to_string(out.join("demo.toml")).unwrap();
    assert!(exp.contains("[gaussians]\niterations = 1500"), "{exp}");
    let settings = |s: &str| fs::read_to_string(out.join(format!("runs/demo/{s}.settings.toml")));
    assert_eq!(settings("gaussians").unwrap().trim(), "iterations = 1500");
    assert_eq!(settings("evflow").unwrap().trim(), "epochs = 1");
    let mut started = f.started();
    started.sort();
    assert_eq!(started, ["assoc", "evflow", "gaussians"]);
    let summary: serde_json::Value =
        serde_json::from_slice(&fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["psnr"], 100.0);
    assert_eq!(summary["novel_psnr"], 100.0);
    assert_eq!(summary["lpips_note"], "LPIPS off (DEGS_LPIPS=off)");
    assert_eq!(summary["stages"][2]["figures"][0][1], 27.5);
    // its charts: the warm-up point against time, size and Gaussians, the flow point
    let charts: Vec<&str> = summary["charts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap().rsplit('/').next().unwrap())
        .collect();
    assert_eq!(charts.len(), 10, "{charts:?}");
    assert!(
        charts.contains(&"rigid-psnr-vs-time.png") && charts.contains(&"rigid-epe-vs-locm.svg")
    );
    assert!(
        table.contains(&format!(
            "charts:          {}",
            out.join("charts").display()
        )),
        "{table}"
    );
    let json: serde_json::Value =
        serde_json::from_slice(&fs::read(out.join("charts/chart.json")).unwrap()).unwrap();
    assert_eq!(json["models"][0]["psnr"], 27.5);
    assert_eq!(json["models"][0]["gaussians"], 4200);
    assert_eq!(json["flows"][0]["epe_px_s"], 12.5);

    // the second demo reuses everything
    let o = demo(&f, &out, &reports);
    assert!(o.status.success(), "{}", stderr(&o));
    let table = stdout(&o);
    for stage in ["synth", "evflow", "gaussians", "assoc"] {
        let r = row(&table, stage);
        assert!(r.contains(" cached ") && r.contains(" yes "), "{r}");
    }
    assert!(row(&table, "gaussians").contains("test PSNR 27.50 dB"));
    assert_eq!(f.started().len(), 3, "no stage ran again");
}

#[test]
fn demo_without_evflow_says_how_to_build_it_and_skips_what_needs_it() {
    let f = Fixture::new();
    fs::remove_file(f.stages.join("evflow")).unwrap();
    let reports = reports(&f);
    let out = f.dir.path().join("demo-out");
    let o = demo(&f, &out, &reports);
    assert!(o.status.success(), "{}", stderr(&o));
    let table = stdout(&o);
    let e = row(&table, "evflow");
    assert!(
        e.contains("unavailable") && e.contains("cargo build --release -p degs-evflow"),
        "{e}"
    );
    assert!(row(&table, "gaussians").contains(" ran "), "{table}");
    assert!(row(&table, "assoc").contains(" ran "), "{table}");
    let d = row(&table, "deform");
    assert!(d.contains("skipped") && d.contains("evflow"), "{d}");
    assert!(!table.contains("flow EPE:"), "{table}");
}
