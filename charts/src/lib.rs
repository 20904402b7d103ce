//! `degs chart RUNS…`: accuracy against cost across runs, from their run records
//! (`runs/<name>/run.json`) and the reports of the cache entries they used.
//!
//! One point per rendering cache entry (a warm-up shared by several experiments is
//! one point): its test PSNR against
//! - the total wall time of the stages it needed (the scene's generation left out),
//!   cached stages counted at what they cost when they were built (the entry
//!   manifest's `wall_s`, carried into the run record as `built_wall_s`);
//! - the bytes on disk of its model files, and its Gaussian count;
//!
//! and one point per flow entry: its EPE against ground truth over its LoCM
//! fine-tuning time (the evflow report's `finetune` phase). Points are grouped by
//! scene (figures of different scenes do not compare); per scene the Pareto front is
//! drawn and the 2D baselines are horizontal lines. [`draw`] makes the images; the
//! numbers go to `chart.json` and `chart.csv` beside them.
//!
//! [`curve`]: LoCM budget curves (JSON lines from `evflow`'s `locm_budget` example, for
//! recordings that are not scenes of a run, such as the real ECD slice), drawn by
//! [`curve_draw`] as EPE ÷ zero-flow EPE against LoCM time.

pub mod curve;
pub mod curve_draw;
pub mod draw;
mod labels;
pub mod legend;

use anyhow::{Context, Result};
use runner::record::RunRecord;
use runner::stages;
use serde::Serialize;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// How a model was trained, told apart on the charts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// The RGB warm-up (`gaussians`).
    RgbWarmup,
    /// `deform` with the event and motion terms off (γ1 = γ2 = 0): RGB only.
    RgbJoint,
    /// `deform` with event and/or motion supervision.
    Degs,
}

impl Method {
    pub fn label(self) -> &'static str {
        match self {
            Method::RgbWarmup => "RGB-only warm-up (gaussians)",
            Method::RgbJoint => "RGB-only joint (deform, no event/motion loss)",
            Method::Degs => "DEGS (deform, events)",
        }
    }
}

/// One rendering cache entry.
#[derive(Clone, Debug, Serialize)]
pub struct ModelPoint {
    pub scene: String,
    pub stage: String,
    pub key: String,
    pub experiments: Vec<String>,
    pub method: Method,
    pub psnr: f64,
    pub ssim: Option<f64>,
    /// `test.lpips_mean` of the report, when the stage computes it.
    pub lpips: Option<f64>,
    pub novel_psnr: Option<f64>,
    /// Wall time of this stage and every stage it needs, seconds.
    pub total_s: f64,
    /// Bytes of its model files (everything but renders, depth maps, report, settings).
    pub model_bytes: u64,
    pub gaussians: Option<u64>,
}

/// One flow cache entry with ground truth.
#[derive(Clone, Debug, Serialize)]
pub struct FlowPoint {
    pub scene: String,
    pub key: String,
    pub experiments: Vec<String>,
    pub epe_px_s: f64,
    /// LoCM fine-tuning time, seconds (0 when the stage did not fine-tune).
    pub locm_s: f64,
    pub mode: Option<String>,
}

/// A 2D baseline's test PSNR (and LPIPS, when the report has it) on a scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Baseline {
    pub scene: String,
    pub name: String,
    pub psnr: f64,
    pub lpips: Option<f64>,
}

/// Everything charted.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ChartData {
    pub models: Vec<ModelPoint>,
    pub flows: Vec<FlowPoint>,
    pub baselines: Vec<Baseline>,
}

/// Indices of the Pareto front of `(cost, value)` points where lower cost and higher
/// value are better, ordered by cost: a point is on it when no other point costs at
/// most as much and scores at least as well with one of the two strictly better.
pub(crate) fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..points.len())
        .filter(|&i| points[i].0.is_finite() && points[i].1.is_finite())
        .collect();
    // by cost, the better value first among equal costs
    idx.sort_by(|&a, &b| {
        let (pa, pb) = (points[a], points[b]);
        pa.0.total_cmp(&pb.0).then(pb.1.total_cmp(&pa.1))
    });
    let mut front = Vec::new();
    let mut best = f64::NEG_INFINITY;
    for i in idx {
        if points[i].1 > best {
            front.push(i);
            best = points[i].1;
        }
    }
    front
}

fn read_json(path: &Path) -> Option<Value> {
    std::fs::read(path)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
}

fn num(v: &Value, path: &str) -> Option<f64> {
    path.split('/')
        .try_fold(v, |v, k| v.get(k))
        .and_then(Value::as_f64)
        .filter(|x| x.is_finite())
}

/// Bytes of the model files of a stage's output directory.
pub(crate) fn model_bytes(entry: &Path) -> u64 {
    const NOT_MODEL: [&str; 4] = [
        "report.json",
        "settings.toml",
        runner::cache::MANIFEST,
        "log",
    ];
    runner::cache::list_files(entry)
        .unwrap_or_default()
        .iter()
        .filter(|rel| {
            let first = rel
                .components()
                .next()
                .map(|c| c.as_os_str().to_string_lossy());
            !matches!(first.as_deref(), Some("renders" | "depth"))
                && !NOT_MODEL.iter().any(|n| rel.as_os_str() == *n)
        })
        .filter_map(|rel| std::fs::metadata(entry.join(rel)).ok())
        .map(|m| m.len())
        .sum()
}

/// The stage `name` and every external stage it needs (not the scene).
fn needed(name: &str) -> Vec<&'static str> {
    let mut out: Vec<&'static str> = Vec::new();
    let mut todo = vec![name];
    while let Some(n) = todo.pop() {
        if let Some(s) = stages::find(n)
            && !out.contains(&s.name)
        {
            out.push(s.name);
            todo.extend(s.inputs.iter().map(|i| i.node));
        }
    }
    out
}

/// A name for a run's scene: the synthetic preset, or the scene directory's name.
fn scene_label(run: &RunRecord) -> (String, String) {
    let Some(first) = run.stages.first() else {
        return ("?".into(), String::new());
    };
    let key = first.key.clone().unwrap_or_default();
    let label = match first.settings.get("preset").and_then(Value::as_str) {
        Some(p) => p.to_string(),
        None => first
            .entry
            .as_deref()
            .and_then(Path::file_name)
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_else(|| "scene".into()),
    };
    (label, key)
}

/// Collect the points of every run record (duplicates by cache entry merged).
pub fn collect(runs: &[RunRecord]) -> ChartData {
    // scene key → label; two scenes of one preset get the key's start appended
    let mut labels: BTreeMap<String, String> = BTreeMap::new();
    for r in runs {
        let (label, key) = scene_label(r);
        labels.entry(key).or_insert(label);
    }
    let mut count: BTreeMap<String, usize> = BTreeMap::new();
    for l in labels.values() {
        *count.entry(l.clone()).or_default() += 1;
    }
    for (k, l) in labels.iter_mut() {
        if count[l.as_str()] > 1 {
            *l = format!("{l}-{}", &k[..k.len().min(6)]);
        }
    }
    let mut data = ChartData::default();
    for r in runs {
        let scene = labels[&scene_label(r).1].clone();
        let built = |stage: &str| {
            r.stage(stage)
                .filter(|s| s.action.has_output())
                .map(|s| s.built_wall_s.unwrap_or(s.wall_s))
        };
        for s in r.stages.iter().filter(|s| s.action.has_output()) {
            let (Some(entry), Some(key)) = (&s.entry, &s.key) else {
                continue;
            };
            let Some(report) = read_json(&entry.join("report.json")) else {
                continue;
            };
            let def = stages::find(&s.stage);
            if def.is_some_and(|d| d.renders.is_some()) {
                if let Some(p) = data
                    .models
                    .iter_mut()
                    .find(|p| p.stage == s.stage && &p.key == key)
                {
                    p.experiments.push(r.experiment.clone());
                    continue;
                }
                let Some(psnr) = num(&report, "test/psnr_mean") else {
                    continue;
                };
                let gamma = |k: &str| num(&report, &format!("settings/schedule/{k}"));
                let motion_off = gamma("gamma2_max") == Some(0.0)
                    || report.pointer("/settings/schedule/motion") == Some(&"off".into());
                let method = match s.stage.as_str() {
                    "gaussians" => Method::RgbWarmup,
                    _ if gamma("gamma1") == Some(0.0) && motion_off => Method::RgbJoint,
                    _ => Method::Degs,
                };
                data.models.push(ModelPoint {
                    scene: scene.clone(),
                    stage: s.stage.clone(),
                    key: key.clone(),
                    experiments: vec![r.experiment.clone()],
                    method,
                    psnr,
                    ssim: num(&report, "test/ssim_mean"),
                    lpips: num(&report, "test/lpips_mean"),
                    novel_psnr: num(&report, "novel/psnr_mean"),
                    total_s: needed(&s.stage).iter().filter_map(|n| built(n)).sum(),
                    model_bytes: model_bytes(entry),
                    gaussians: num(&report, "gaussians").map(|g| g as u64),
                });
            }
            if def.is_some_and(|d| d.event_flow.is_some()) {
                if let Some(p) = data.flows.iter_mut().find(|p| &p.key == key) {
                    p.experiments.push(r.experiment.clone());
                    continue;
                }
                let Some(epe) = num(&report, "flow_epe_px_s") else {
                    continue;
                };
                data.flows.push(FlowPoint {
                    scene: scene.clone(),
                    key: key.clone(),
                    experiments: vec![r.experiment.clone()],
                    epe_px_s: epe,
                    locm_s: locm_seconds(&report).or(built(&s.stage)).unwrap_or(0.0),
                    mode: report
                        .pointer("/finetune/mode")
                        .or(report.pointer("/settings/mode"))
                        .and_then(Value::as_str)
                        .map(str::to_string),
                });
            }
            if s.stage == "deform" && !data.baselines.iter().any(|b| b.scene == scene) {
                for (name, key) in [
                    ("nearest frame", "nearest"),
                    ("linear blend", "blend"),
                    ("event pseudo image", "events"),
                ] {
                    if let Some(psnr) = num(&report, &format!("baselines/{key}/psnr_mean")) {
                        let lpips = num(&report, &format!("baselines/{key}/lpips_mean"));
                        let (scene, name) = (scene.clone(), name.to_string());
                        data.baselines.push(Baseline {
                            scene,
                            name,
                            psnr,
                            lpips,
                        });
                    }
                }
            }
        }
    }
    data
}

/// Seconds of the `finetune` phase of an evflow report (`phases`: [[name, s], …]);
/// 0 when it lists phases but none is fine-tuning; None without phases.
fn locm_seconds(report: &Value) -> Option<f64> {
    let phases = report.get("phases")?.as_array()?;
    let t = phases
        .iter()
        .filter_map(|p| Some((p.get(0)?.as_str()?, p.get(1)?.as_f64()?)))
        .filter(|(n, _)| *n == "finetune")
        .map(|(_, s)| s)
        .sum();
    Some(t)
}

/// The charted numbers as CSV, one row per point (models, then flows, then baselines).
pub(crate) fn to_csv(d: &ChartData) -> String {
    let opt = |v: Option<f64>| v.map_or(String::new(), |x| format!("{x}"));
    let mut s = String::from(
        "kind,scene,stage,key,method,experiments,psnr_db,ssim,lpips,novel_psnr_db,total_s,\
         model_bytes,gaussians,epe_px_s,locm_s\n",
    );
    for p in &d.models {
        s += &format!(
            "model,{},{},{},{:?},{},{},{},{},{},{},{},{},,\n",
            p.scene,
            p.stage,
            p.key,
            p.method,
            p.experiments.join(" "),
            p.psnr,
            opt(p.ssim),
            opt(p.lpips),
            opt(p.novel_psnr),
            p.total_s,
            p.model_bytes,
            p.gaussians.map_or(String::new(), |g| g.to_string()),
        );
    }
    for f in &d.flows {
        s += &format!(
            "flow,{},evflow,{},{},{},,,,,,,,{},{}\n",
            f.scene,
            f.key,
            f.mode.as_deref().unwrap_or(""),
            f.experiments.join(" "),
            f.epe_px_s,
            f.locm_s
        );
    }
    for b in &d.baselines {
        s += &format!(
            "baseline,{},,,{},,{},,{},,,,,,\n",
            b.scene,
            b.name,
            b.psnr,
            opt(b.lpips)
        );
    }
    s
}

/// Collect the points of `runs`, write every chart (PNG and SVG) and chart.json /
/// chart.csv into `out`; the paths written.
pub fn write_charts(runs: &[RunRecord], out: &Path) -> Result<Vec<PathBuf>> {
    let data = collect(runs);
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let mut written = draw::draw_all(&data, out)?;
    let json = out.join("chart.json");
    scene::atomic::write_json_atomic(&json, &data)?;
    let csv = out.join("chart.csv");
    scene::atomic::write_bytes_atomic(&csv, to_csv(&data).as_bytes())?;
    written.extend([json, csv]);
    Ok(written)
}

#[cfg(test)]
mod curve_tests;
#[cfg(test)]
mod tests;
