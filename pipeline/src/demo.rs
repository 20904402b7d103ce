//! `degs demo`: synthesise the default scene, write a small experiment file for it,
//! run every stage that is built through the runner, and end with a summary table
//! (stage, time, cached?, key figures), an event preview and summary.json.

use anyhow::{Context as _, Result};
use runner::context::Context;
use runner::experiment::Experiment;
use runner::process::fmt_kib;
use runner::progress::Progress;
use runner::record::{Action, RunRecord};
use runner::run::{self, RunOptions};
use runner::stages;
use scene::events::EventStream;
use scene::image_io::{Image, write_png};
use scene::manifest::Scene;
use serde::Serialize;
use serde_json::Value;
use std::path::{Path, PathBuf};
use synth::SynthConfig;

/// Side of the demo's square scene when the user sets no size (small enough that the
/// whole demo runs in minutes on two cores).
pub(crate) const DEMO_SIZE: u32 = 96;
/// Warm-up iterations of the demo (the stage default is the paper's 3500).
pub(crate) const DEMO_GAUSSIANS_ITERATIONS: u32 = 1500;
/// LoCM epochs of the demo (the stage default trains until the CM loss stops improving).
pub(crate) const DEMO_EVFLOW_EPOCHS: usize = 1;
/// Joint iterations of the demo (the stage default is 2000 to 6000 by the frame rate).
pub(crate) const DEMO_DEFORM_ITERATIONS: u32 = 600;

/// What the demo runs.
#[derive(Clone, Debug)]
pub struct DemoOptions {
    pub scene: SynthConfig,
    /// `[gaussians] iterations`; None leaves the stage default.
    pub gaussians_iterations: Option<u32>,
    /// `[evflow] epochs`; None leaves the stage default.
    pub evflow_epochs: Option<usize>,
    /// `[deform] iterations`; None leaves the stage default.
    pub deform_iterations: Option<u32>,
    pub jobs: usize,
}

/// What the demo produced.
#[derive(Clone, Debug, Serialize)]
pub struct DemoSummary {
    pub out: PathBuf,
    pub experiment_file: PathBuf,
    pub scene: Option<PathBuf>,
    pub events: Option<usize>,
    pub preview: Option<PathBuf>,
    pub stages: Vec<DemoStage>,
    /// Test-frame PSNR/SSIM/LPIPS of the final renders (`degs eval`).
    pub psnr: Option<f64>,
    pub ssim: Option<f64>,
    pub lpips: Option<f64>,
    /// The same on the novel views (`degs eval`; None when the scene or the renders
    /// have none).
    pub novel_psnr: Option<f64>,
    pub novel_ssim: Option<f64>,
    pub novel_lpips: Option<f64>,
    /// Why there is no LPIPS (`DEGS_LPIPS=off`, or no weights).
    pub lpips_note: Option<String>,
    /// Per-event flow EPE against the scene's ground truth (`degs eval`), px/s.
    pub flow_epe: Option<f64>,
    pub renders: Option<PathBuf>,
    pub metrics: Option<PathBuf>,
    /// The charts of the run (`degs chart`: its warm-up and joint points against
    /// time, size, Gaussians; flow error against LoCM time) and their numbers.
    pub charts: Vec<PathBuf>,
    /// The final model along the recorded path in slow motion (`degs render`):
    /// `video/preview.gif` and its frames; None when it could not be made (said then).
    pub video: Option<PathBuf>,
    pub wall_s: f64,
    /// What the stages say a user must know about the result (`warning (STAGE): …`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct DemoStage {
    pub stage: String,
    pub action: String,
    pub cached: bool,
    /// Seconds it took (when it was built, if cached now).
    pub seconds: Option<f64>,
    pub peak_rss_kib: Option<u64>,
    pub output: Option<PathBuf>,
    /// Key figures from its report.json: (label, value, unit).
    pub figures: Vec<(String, f64, String)>,
    pub note: Option<String>,
}

/// The demo's experiment: the scene and the reduced stage settings.
pub(crate) fn demo_experiment(opts: &DemoOptions) -> Experiment {
    let mut exp = Experiment::synthetic("demo", opts.scene.clone());
    if let Some(n) = opts.gaussians_iterations {
        let t = exp.stages.entry("gaussians".into()).or_default();
        t.insert("iterations".into(), toml::Value::Integer(n.into()));
    }
    if let Some(n) = opts.evflow_epochs {
        let t = exp.stages.entry("evflow".into()).or_default();
        t.insert("epochs".into(), toml::Value::Integer(n as i64));
    }
    if let Some(n) = opts.deform_iterations {
        let t = exp.stages.entry("deform".into()).or_default();
        t.insert("iterations".into(), toml::Value::Integer(n.into()));
    }
    exp
}

/// One line saying what the demo runs and what it reduced for speed.
pub fn describe(opts: &DemoOptions, experiment_file: &Path) -> String {
    let c = &opts.scene;
    let mut reduced = Vec::new();
    if let Some(n) = opts.gaussians_iterations {
        reduced.push(format!("gaussians iterations = {n} (default 3500)"));
    }
    if let Some(n) = opts.evflow_epochs {
        reduced.push(format!(
            "evflow epochs = {n} (default: until the CM loss stops improving)"
        ));
    }
    if let Some(n) = opts.deform_iterations {
        reduced.push(format!(
            "deform iterations = {n} (default 2000–6000 by the frame rate)"
        ));
    }
    format!(
        "degs demo: synthetic `{}` scene {}x{}, {} s, train frames at {} fps, {} test frames; {}; \
         experiment file {} (run it with full settings: `degs demo --full`)",
        c.preset,
        c.width,
        c.height,
        c.duration,
        c.train_fps,
        c.test_frames,
        if reduced.is_empty() {
            "stage defaults".to_string()
        } else {
            format!("reduced for speed: {}", reduced.join(", "))
        },
        experiment_file.display()
    )
}

/// Run the demo into `ctx.cache.root`.
pub fn demo(opts: &DemoOptions, ctx: &Context, progress: &Progress) -> Result<DemoSummary> {
    let out = ctx.cache.root.clone();
    std::fs::create_dir_all(&out).with_context(|| format!("{}: cannot create", out.display()))?;
    let file = out.join("demo.toml");
    scene::atomic::write_bytes_atomic(&file, demo_experiment(opts).to_toml().as_bytes())?;
    let exp = Experiment::load(&file)?;
    eprintln!("{}", describe(opts, &file));
    let run_opts = RunOptions {
        jobs: opts.jobs,
        ..Default::default()
    };
    let record = run::run(&exp, ctx, &run_opts, progress)?;
    let scene_dir = record
        .stages
        .first()
        .filter(|s| s.action.has_output())
        .and_then(|s| s.entry.clone());
    let (mut events, mut preview) = (None, None);
    if let Some(dir) = &scene_dir {
        let scene = Scene::open(dir)?;
        let ev = scene.load_events()?;
        events = Some(ev.len());
        let path = out.join("events_preview.png");
        write_png(&path, &event_preview(&ev))?;
        preview = Some(path);
    }
    let run_dir = ctx.cache.run_dir("demo");
    let metrics = match runner::eval::eval_run(&run_dir, ctx, &Progress::new(true)) {
        Ok(m) => Some(m),
        Err(e) => {
            // The summary then has no evaluation figures: say why.
            progress.note(&format!("no evaluation: {e:#}"));
            None
        }
    };
    let renders = stages::render_stages().find_map(|s| {
        record
            .stage(s.name)
            .filter(|r| r.action.has_output())
            .and_then(|r| r.entry.as_ref())
            .zip(s.renders)
            .map(|(e, dir)| e.join(dir))
            .filter(|r| r.is_dir())
    });
    let charts = charts::write_charts(std::slice::from_ref(&record), &out.join("charts"))
        .unwrap_or_else(|e| {
            eprintln!("[degs] demo: no charts: {e:#}");
            Vec::new()
        });
    let req = runner::video::VideoRequest {
        path: "recorded".into(),
        fps: None,
        playback_fps: None,
    };
    let video = match runner::video::render_run(&run_dir, ctx, &req, &Progress::new(true)) {
        Ok((dir, _)) => Some(dir.join("preview.gif")),
        Err(e) => {
            progress.note(&format!("no preview video: {e:#}"));
            None
        }
    };
    let summary = DemoSummary {
        out: out.clone(),
        experiment_file: file,
        scene: scene_dir,
        events,
        preview,
        stages: stage_rows(&record),
        psnr: metrics.as_ref().and_then(|m| m.psnr_mean),
        ssim: metrics.as_ref().and_then(|m| m.ssim_mean),
        lpips: metrics.as_ref().and_then(|m| m.lpips_mean),
        novel_psnr: metrics.as_ref().and_then(|m| m.novel_psnr_mean),
        novel_ssim: metrics.as_ref().and_then(|m| m.novel_ssim_mean),
        novel_lpips: metrics.as_ref().and_then(|m| m.novel_lpips_mean),
        lpips_note: metrics.as_ref().and_then(|m| m.lpips_note.clone()),
        flow_epe: metrics.as_ref().and_then(|m| m.flow_epe),
        renders,
        metrics: metrics.map(|_| run_dir.join("metrics.json")),
        charts,
        video,
        wall_s: record.wall_s,
        warnings: runner::record::warning_lines(&record.stages),
    };
    scene::atomic::write_json_atomic(&out.join("summary.json"), &summary)?;
    Ok(summary)
}

fn stage_rows(record: &RunRecord) -> Vec<DemoStage> {
    record
        .stages
        .iter()
        .map(|s| {
            let entry = s.entry.as_deref().filter(|_| s.action.has_output());
            DemoStage {
                stage: s.stage.clone(),
                action: s.action.as_str().to_string(),
                cached: s.action == Action::Cached,
                seconds: s
                    .action
                    .has_output()
                    .then(|| s.built_wall_s.unwrap_or(s.wall_s)),
                peak_rss_kib: s.peak_rss_kib,
                output: entry.map(Path::to_path_buf),
                figures: entry
                    .map(|e| report_figures(&s.stage, e))
                    .unwrap_or_default(),
                note: s.error.clone(),
            }
        })
        .collect()
}

/// A number at a `/`-separated path of a JSON value.
fn at(v: &Value, path: &str) -> Option<f64> {
    path.split('/')
        .try_fold(v, |v, k| v.get(k))
        .and_then(Value::as_f64)
        .filter(|x| x.is_finite())
}

/// The key figures of a stage's `report.json` (label, value, unit).
pub(crate) fn report_figures(stage: &str, dir: &Path) -> Vec<(String, f64, String)> {
    let Some(v) = std::fs::read(dir.join("report.json"))
        .ok()
        .and_then(|b| serde_json::from_slice::<Value>(&b).ok())
    else {
        return vec![];
    };
    stages::figures(stage)
        .iter()
        .filter_map(|f| {
            at(&v, f.path).map(|x| (f.label.to_string(), x * f.scale, f.unit.to_string()))
        })
        .collect()
}

/// Events of one window around the middle of the recording, coloured by polarity
/// (red positive, blue negative; the later event wins) on white.
pub(crate) fn event_preview(ev: &EventStream) -> Image {
    let (w, h) = (ev.width.max(1), ev.height.max(1));
    let mut img = Image::new(w, h, 3);
    img.data.iter_mut().for_each(|v| *v = 1.0);
    let (Some(&t0), Some(&t1)) = (ev.t.first(), ev.t.last()) else {
        return img;
    };
    let span = ((t1 - t0) / 16.0).clamp(1e-4, 0.05);
    let mid = 0.5 * (t0 + t1);
    let win = ev.window(mid - span / 2.0, mid + span / 2.0);
    for i in 0..win.t.len() {
        let (x, y) = (win.x[i] as usize, win.y[i] as usize);
        if x >= w as usize || y >= h as usize {
            continue;
        }
        let rgb = if win.p[i] > 0 {
            [0.85, 0.1, 0.1]
        } else {
            [0.1, 0.25, 0.9]
        };
        let o = (y * w as usize + x) * 3;
        img.data[o..o + 3].copy_from_slice(&rgb);
    }
    img
}

fn fmt_figure((label, v, unit): &(String, f64, String)) -> String {
    // counts print as integers; percentages and measurements keep their decimals
    let num = if unit.is_empty() && v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{}", *v as i64)
    } else if v.abs() >= 100.0 {
        format!("{v:.1}")
    } else if v.abs() >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.4}")
    };
    match unit.as_str() {
        "" => format!("{label} {num}"),
        "%" => format!("{label} {num}%"),
        u => format!("{label} {num} {u}"),
    }
}

/// The summary table printed at the end of the demo.
pub fn format_summary(s: &DemoSummary) -> String {
    let mut t = format!(
        "\n{:<10} {:<12} {:>8} {:>7} {:>10}  {}\n",
        "stage", "status", "time s", "cached", "peak mem", "key figures"
    );
    for r in &s.stages {
        let mut text = r
            .figures
            .iter()
            .map(fmt_figure)
            .collect::<Vec<_>>()
            .join(", ");
        if let Some(note) = &r.note {
            if !text.is_empty() {
                text += "; ";
            }
            text += note;
        }
        t += &format!(
            "{:<10} {:<12} {:>8} {:>7} {:>10}  {}\n",
            r.stage,
            r.action,
            r.seconds.map_or("-".into(), |x| format!("{x:.2}")),
            if r.cached { "yes" } else { "no" },
            fmt_kib(r.peak_rss_kib),
            text
        );
    }
    t += "\n";
    let mut line = |label: &str, value: String| t += &format!("{label:<17}{value}\n");
    line("experiment:", s.experiment_file.display().to_string());
    if let Some(scene) = &s.scene {
        line("scene:", scene.display().to_string());
    }
    if let Some(n) = s.events {
        line("events:", n.to_string());
    }
    if let Some(p) = &s.preview {
        line("event preview:", p.display().to_string());
    }
    for r in s.stages.iter().filter(|r| r.stage != stages::SYNTH) {
        if let Some(o) = &r.output {
            line(&format!("{}:", r.stage), o.display().to_string());
        }
    }
    if let Some(r) = &s.renders {
        line(
            "renders:",
            format!("{} (test frames; novel views in novel/)", r.display()),
        );
    }
    let lpips = |l: Option<f64>| match (l, &s.lpips_note) {
        (Some(l), _) => format!(", LPIPS {l:.4}"),
        (None, Some(note)) => format!(", {note}"),
        (None, None) => String::new(),
    };
    if let (Some(p), Some(q)) = (s.psnr, s.ssim) {
        line(
            "test PSNR/SSIM:",
            format!("{p:.2} dB / {q:.4}{}", lpips(s.lpips)),
        );
    }
    if let (Some(p), Some(q)) = (s.novel_psnr, s.novel_ssim) {
        line(
            "novel PSNR/SSIM:",
            format!(
                "{p:.2} dB / {q:.4}{} (views off the path)",
                lpips(s.novel_lpips)
            ),
        );
    }
    if let Some(e) = s.flow_epe {
        line("flow EPE:", format!("{e:.3} px/s (per event, vs gt)"));
    }
    if let Some(m) = &s.metrics {
        line("metrics:", m.display().to_string());
    }
    if let Some(png) = s
        .charts
        .iter()
        .find(|c| c.extension().is_some_and(|e| e == "png"))
    {
        let dir = png.parent().unwrap_or(Path::new("."));
        let n = s
            .charts
            .iter()
            .filter(|c| c.extension().is_some_and(|e| e == "png"))
            .count();
        line(
            "charts:",
            format!("{} ({n} PNG + SVG, chart.json, chart.csv)", dir.display()),
        );
    }
    if let Some(v) = &s.video {
        line(
            "preview video:",
            format!(
                "{} (slow motion along the recorded path; `degs render demo --cache {} --path \
                 orbit` swings the view about the scene)",
                v.display(),
                s.out.display()
            ),
        );
    }
    line("summary:", s.out.join("summary.json").display().to_string());
    line(
        "run record:",
        s.out.join("runs/demo/run.json").display().to_string(),
    );
    line("wall time:", format!("{:.2} s", s.wall_s));
    for w in &s.warnings {
        t += &format!("\n{w}\n");
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preview_colours_events_by_polarity() {
        let ev = EventStream {
            width: 4,
            height: 2,
            t: vec![0.0, 0.5, 0.5, 1.0],
            x: vec![0, 1, 2, 3],
            y: vec![0, 1, 1, 0],
            p: vec![1, 1, -1, -1],
        };
        let img = event_preview(&ev);
        assert_eq!((img.width, img.height), (4, 2));
        let px = |x: usize, y: usize| &img.data[(y * 4 + x) * 3..(y * 4 + x) * 3 + 3];
        assert_eq!(px(1, 1), &[0.85, 0.1, 0.1]); // in the middle window, positive
        assert_eq!(px(2, 1), &[0.1, 0.25, 0.9]); // negative
        assert_eq!(px(0, 0), &[1.0, 1.0, 1.0]); // outside the window
        assert_eq!(px(3, 0), &[1.0, 1.0, 1.0]);
    }

    #[test]
    fn empty_stream_gives_a_blank_preview() {
        let ev = EventStream {
            width: 3,
            height: 3,
            t: vec![],
            x: vec![],
            y: vec![],
            p: vec![],
        };
        assert!(event_preview(&ev).data.iter().all(|&v| v == 1.0));
    }

    #[test]
    fn key_figures_come_from_each_stage_report() {
        let d = tempfile::tempdir().unwrap();
        let write = |s: &str| std::fs::write(d.path().join("report.json"), s).unwrap();
        write(r#"{"test": {"psnr_mean": 27.5, "ssim_mean": 0.91}, "gaussians": 4200}"#);
        let g = report_figures("gaussians", d.path());
        assert_eq!(
            g.iter().map(fmt_figure).collect::<Vec<_>>(),
            ["test PSNR 27.50 dB", "SSIM 0.9100", "Gaussians 4200"]
        );
        write(r#"{"bound_fraction_mean": 0.625, "gaussians": 800}"#);
        let a = report_figures("assoc", d.path());
        assert_eq!(fmt_figure(&a[0]), "bound 62.50%");
        write(r#"{"flow_epe_px_s": 12.25, "flow_err_px": null, "warp_gain": 1.5}"#);
        let e = report_figures("evflow", d.path());
        assert_eq!(e.len(), 2);
        assert_eq!(fmt_figure(&e[0]), "EPE 12.25 px/s");
        write("not json");
        assert!(report_figures("evflow", d.path()).is_empty());
    }
}
