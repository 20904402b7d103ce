//! `degs sweep`: run every experiment of a sweep through the runner, one after the
//! other, so that a stage common to several experiments is computed by the first and
//! found in the cache by the others; `runs/<sweep>/sweep.json` lists the experiments,
//! their run records and which experiment built each cache entry.
//!
//! Each experiment is written to `runs/<sweep>/<experiment>.toml` (a plain experiment
//! file: `degs run`, `status` and `plan` take it). Interrupting and re-running resumes:
//! finished stages are cached, an interrupted one leaves only a temp dir.

use crate::sweep::Sweep;
use anyhow::{Context as _, Result};
use runner::context::Context;
use runner::experiment::Experiment;
use runner::progress::Progress;
use runner::record::{Action, RunRecord};
use runner::run::{self, RunOptions};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// `runs/<sweep>/sweep.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SweepRecord {
    pub sweep: String,
    pub sweep_file: PathBuf,
    /// "running", "ok" or "failed" (a stage failed in some experiment).
    pub status: String,
    /// Axis key → its values, in axis order.
    pub axes: Vec<(String, Vec<serde_json::Value>)>,
    pub experiments: Vec<SweepExperiment>,
    /// Every cache entry the sweep used, once: which experiments used it and which
    /// one ran it in this invocation (None: it was cached already).
    pub entries: Vec<SharedEntry>,
    /// Stage processes this invocation started (a finished sweep re-run: 0).
    pub stages_run: usize,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SweepExperiment {
    pub name: String,
    /// Axis key → value.
    pub values: BTreeMap<String, serde_json::Value>,
    pub experiment_file: PathBuf,
    pub run_record: PathBuf,
    /// None until its run starts.
    pub status: Option<String>,
    /// Stage → what happened to it in this run (ran, cached, failed…).
    pub stages: BTreeMap<String, String>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SharedEntry {
    pub stage: String,
    pub key: String,
    pub used_by: Vec<String>,
    pub ran_in: Option<String>,
    /// Wall time of the run that built it, seconds.
    pub built_wall_s: Option<f64>,
}

/// Write each experiment's file under `runs/<sweep>/`; return them with their axis
/// values.
pub fn write_experiments(
    sweep: &Sweep,
    ctx: &Context,
) -> Result<Vec<(Experiment, BTreeMap<String, serde_json::Value>)>> {
    sweep.check_stages(ctx)?;
    write_points(&sweep.name, sweep.expand()?, ctx)
}

/// Write each point's experiment to `runs/<name>/<experiment>.toml`; return them with
/// their axis values.
pub(crate) fn write_points(
    name: &str,
    points: Vec<crate::sweep::Point>,
    ctx: &Context,
) -> Result<Vec<(Experiment, BTreeMap<String, serde_json::Value>)>> {
    let dir = ctx.cache.run_dir(name);
    std::fs::create_dir_all(&dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let mut out = Vec::new();
    for p in points {
        let file = dir.join(format!("{}.toml", p.experiment.name));
        let mut exp = p.experiment;
        scene::atomic::write_bytes_atomic(&file, exp.to_toml().as_bytes())?;
        exp.file = Some(file);
        let values = p
            .values
            .into_iter()
            .map(|(k, v)| (k, serde_json::to_value(v).unwrap_or_default()))
            .collect();
        out.push((exp, values));
    }
    Ok(out)
}

/// Run the sweep; sweep.json is rewritten after every experiment. A failed stage is
/// recorded (and the next experiments still run), not returned as an error.
pub fn run(
    sweep: &Sweep,
    ctx: &Context,
    opts: &RunOptions,
    progress: &Progress,
) -> Result<SweepRecord> {
    let exps = write_experiments(sweep, ctx)?;
    let axes = sweep
        .axes
        .iter()
        .map(|a| {
            let vals = a
                .values
                .iter()
                .map(|v| serde_json::to_value(v).unwrap_or_default());
            (a.key.clone(), vals.collect())
        })
        .collect();
    run_experiments(sweep, axes, &exps, ctx, opts, progress)
}

/// Run `exps` (written under `runs/<sweep>/`, each with its axis values), `-J` of them
/// at a time (`opts.experiments`; a stage two experiments share is built once: the
/// second waits on its cache entry's lock), and keep `runs/<sweep>/sweep.json` current: [`run`]'s loop, also used by
/// `degs stress` for its variants.
pub(crate) fn run_experiments(
    sweep: &Sweep,
    axes: Vec<(String, Vec<serde_json::Value>)>,
    exps: &[(Experiment, BTreeMap<String, serde_json::Value>)],
    ctx: &Context,
    opts: &RunOptions,
    progress: &Progress,
) -> Result<SweepRecord> {
    let dir = ctx.cache.run_dir(&sweep.name);
    let mut record = SweepRecord {
        sweep: sweep.name.clone(),
        sweep_file: sweep.file.clone(),
        status: "running".into(),
        axes,
        experiments: exps
            .iter()
            .map(|(e, values)| SweepExperiment {
                name: e.name.clone(),
                values: values.clone(),
                experiment_file: e.file.clone().unwrap_or_default(),
                run_record: ctx.cache.run_record(&e.name),
                status: None,
                stages: BTreeMap::new(),
            })
            .collect(),
        entries: Vec::new(),
        stages_run: 0,
    };
    let path = dir.join("sweep.json");
    scene::atomic::write_json_atomic(&path, &record)?;
    let at_once = opts.experiments.clamp(1, exps.len().max(1));
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut first_error = None;
    std::thread::scope(|scope| -> Result<()> {
        let (tx, rx) = std::sync::mpsc::channel();
        for _ in 0..at_once {
            let (tx, next) = (tx.clone(), &next);
            scope.spawn(move || {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                    let Some((exp, _)) = exps.get(i) else { break };
                    progress.note(&format!(
                        "sweep {}: experiment {}/{}: {}",
                        sweep.name,
                        i + 1,
                        exps.len(),
                        exp.name
                    ));
                    if tx.send((i, run::run(exp, ctx, opts, progress))).is_err() {
                        break;
                    }
                }
            });
        }
        drop(tx);
        for (i, run) in rx {
            match run {
                Ok(run) => note_run(&mut record, i, &run),
                Err(e) => {
                    let e = e.context(format!("experiment {}", exps[i].0.name));
                    first_error.get_or_insert(e);
                }
            }
            scene::atomic::write_json_atomic(&path, &record)?;
        }
        Ok(())
    })?;
    if let Some(e) = first_error {
        return Err(e);
    }
    let failed = record
        .experiments
        .iter()
        .any(|e| e.status.as_deref() != Some("ok"));
    record.status = if failed { "failed" } else { "ok" }.into();
    scene::atomic::write_json_atomic(&path, &record)?;
    Ok(record)
}

/// Fold experiment `i`'s run record into the sweep record.
fn note_run(record: &mut SweepRecord, i: usize, run: &RunRecord) {
    let name = run.experiment.clone();
    let e = &mut record.experiments[i];
    e.status = Some(run.status.clone());
    e.stages = run
        .stages
        .iter()
        .map(|s| (s.stage.clone(), s.action.as_str().to_string()))
        .collect();
    for s in run.stages.iter().filter(|s| s.action.has_output()) {
        let Some(key) = s.key.clone() else { continue };
        let ran = matches!(s.action, Action::Ran | Action::Rebuilt);
        record.stages_run += usize::from(ran);
        let pos = record
            .entries
            .iter()
            .position(|x| x.stage == s.stage && x.key == key);
        let entry = match pos {
            Some(p) => &mut record.entries[p],
            None => {
                record.entries.push(SharedEntry {
                    stage: s.stage.clone(),
                    key,
                    used_by: Vec::new(),
                    ran_in: None,
                    built_wall_s: s.built_wall_s,
                });
                record.entries.last_mut().expect("just pushed")
            }
        };
        entry.used_by.push(name.clone());
        if ran {
            entry.ran_in = Some(name.clone());
        }
    }
}

/// The one-line-per-experiment table `degs sweep` prints at the end.
pub fn format_summary(r: &SweepRecord) -> String {
    let mut s = String::new();
    for e in &r.experiments {
        let ran: Vec<&str> = e
            .stages
            .iter()
            .filter(|(_, a)| *a == "ran" || *a == "rebuilt")
            .map(|(st, _)| st.as_str())
            .collect();
        s += &format!(
            "{:<48} {:<8} ran: {}\n",
            e.name,
            e.status.as_deref().unwrap_or("not run"),
            if ran.is_empty() {
                "nothing (all cached)".to_string()
            } else {
                ran.join(", ")
            }
        );
    }
    let shared = r.entries.iter().filter(|e| e.used_by.len() > 1).count();
    s += &format!(
        "{} experiments, {} cache entries ({} shared by several), {} stage runs\n",
        r.experiments.len(),
        r.entries.len(),
        shared,
        r.stages_run
    );
    s
}
