//! `degs demo`: synthesise the default scene, run every available stage on it, and
//! end with a summary table, an event preview image and summary.json.

use crate::experiment::Experiment;
use crate::graph::Context;
use crate::progress::Progress;
use crate::record::{Action, RunRecord};
use crate::runner::{self, RunOptions, fmt_kib};
use anyhow::{Context as _, Result};
use scene::events::EventStream;
use scene::image_io::{Image, write_png};
use scene::manifest::Scene;
use scene::synth::SynthConfig;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// What the demo produced.
#[derive(Clone, Debug, Serialize)]
pub struct DemoSummary {
    pub out: PathBuf,
    pub scene: Option<PathBuf>,
    pub events: Option<usize>,
    pub preview: Option<PathBuf>,
    pub stages: Vec<DemoStage>,
    pub psnr: Option<f64>,
    pub ssim: Option<f64>,
    pub wall_s: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct DemoStage {
    pub stage: String,
    pub action: String,
    /// Seconds it took (when it was built, if cached now).
    pub seconds: Option<f64>,
    pub peak_rss_kib: Option<u64>,
    pub output: Option<PathBuf>,
    /// A few figures from its report.json (counts, metrics).
    pub figures: Vec<(String, f64)>,
    pub note: Option<String>,
}

/// Run the demo into `ctx.cache.root`.
pub fn demo(
    cfg: SynthConfig,
    ctx: &Context,
    jobs: usize,
    progress: &Progress,
) -> Result<DemoSummary> {
    let out = ctx.cache.root.clone();
    std::fs::create_dir_all(&out).with_context(|| format!("{}: cannot create", out.display()))?;
    let exp = Experiment::synthetic("demo", cfg);
    scene::atomic::write_bytes_atomic(&out.join("demo.toml"), exp.to_toml().as_bytes())?;
    let opts = RunOptions {
        jobs,
        ..Default::default()
    };
    let record = runner::run(&exp, ctx, &opts, progress)?;
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
    let metrics = crate::eval::eval_run(&ctx.cache.run_dir("demo")).ok();
    let summary = DemoSummary {
        out: out.clone(),
        scene: scene_dir,
        events,
        preview,
        stages: stage_rows(&record),
        psnr: metrics.as_ref().and_then(|m| m.psnr_mean),
        ssim: metrics.as_ref().and_then(|m| m.ssim_mean),
        wall_s: record.wall_s,
    };
    scene::atomic::write_json_atomic(&out.join("summary.json"), &summary)?;
    Ok(summary)
}

fn stage_rows(record: &RunRecord) -> Vec<DemoStage> {
    record
        .stages
        .iter()
        .map(|s| DemoStage {
            stage: s.stage.clone(),
            action: s.action.as_str().to_string(),
            seconds: s
                .action
                .has_output()
                .then(|| s.built_wall_s.unwrap_or(s.wall_s)),
            peak_rss_kib: s.peak_rss_kib,
            output: s.entry.clone().filter(|_| s.action.has_output()),
            figures: s
                .entry
                .as_deref()
                .filter(|_| s.action.has_output())
                .map(report_figures)
                .unwrap_or_default(),
            note: match s.action {
                Action::Unavailable => Some("not available yet".into()),
                _ => s.error.clone(),
            },
        })
        .collect()
}

/// Up to four numeric top-level fields of `dir/report.json` that are counts or metrics.
fn report_figures(dir: &Path) -> Vec<(String, f64)> {
    let Some(v) = std::fs::read(dir.join("report.json"))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
    else {
        return vec![];
    };
    let Some(obj) = v.as_object() else {
        return vec![];
    };
    let wanted = [
        "events",
        "frames",
        "gaussians",
        "count",
        "psnr",
        "ssim",
        "epe",
        "bound",
    ];
    obj.iter()
        .filter(|(k, _)| {
            let k = k.to_ascii_lowercase();
            wanted.iter().any(|w| k.contains(w)) && !k.ends_with("_s")
        })
        .filter_map(|(k, x)| x.as_f64().map(|x| (k.clone(), x)))
        .take(4)
        .collect()
}

/// Events of one window around the middle of the recording, coloured by polarity
/// (red positive, blue negative; the later event wins) on white.
pub fn event_preview(ev: &EventStream) -> Image {
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

/// The summary table printed at the end of the demo.
pub fn format_summary(s: &DemoSummary) -> String {
    let mut t = format!(
        "\n{:<10} {:<12} {:>8} {:>10}  {}\n",
        "stage", "status", "time s", "peak mem", "figures / output"
    );
    for r in &s.stages {
        let figs = r
            .figures
            .iter()
            .map(|(k, v)| format!("{k}={}", fmt_num(*v)))
            .collect::<Vec<_>>()
            .join(" ");
        t += &format!(
            "{:<10} {:<12} {:>8} {:>10}  {}\n",
            r.stage,
            r.action,
            r.seconds.map_or("-".into(), |x| format!("{x:.2}")),
            fmt_kib(r.peak_rss_kib),
            [figs, r.note.clone().unwrap_or_default()].join(" ").trim()
        );
    }
    t += "\n";
    if let Some(scene) = &s.scene {
        t += &format!("scene:          {}\n", scene.display());
    }
    if let Some(n) = s.events {
        t += &format!("events:         {n}\n");
    }
    if let Some(p) = &s.preview {
        t += &format!("event preview:  {}\n", p.display());
    }
    for r in s
        .stages
        .iter()
        .filter(|r| r.output.is_some() && r.stage != "synth")
    {
        t += &format!(
            "{:<15} {}\n",
            format!("{}:", r.stage),
            r.output.as_ref().unwrap().display()
        );
    }
    if let (Some(p), Some(q)) = (s.psnr, s.ssim) {
        t += &format!("test PSNR/SSIM: {p:.2} dB / {q:.4}\n");
    }
    t += &format!(
        "summary:        {}\nrun record:     {}\n",
        s.out.join("summary.json").display(),
        s.out.join("runs/demo/run.json").display()
    );
    t
}

fn fmt_num(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{}", v as i64)
    } else {
        format!("{v:.3}")
    }
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
}
