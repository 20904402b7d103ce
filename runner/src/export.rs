//! `degs export RUN`: the run's last model (the joint training's, else the warm-up's) as
//! a PLY sequence, by `gaussians export` run as a cached node over the run's scene and
//! model ([`crate::external`]); the files are then linked into `runs/<name>/export/`
//! (hard links: no second copy, and they outlive `degs gc` of the cache entry).

use crate::context::Context;
use crate::external::{self, External, Given};
use crate::progress::Progress;
use crate::record::RunRecord;
use crate::stages;
use anyhow::{Context as _, Result, bail};
use std::path::{Path, PathBuf};
use toml::{Table, Value};

/// The export's node name and cache directory.
pub const STAGE: &str = "export";

/// Export the run in `run_dir` at the frames' times (or `fps` over the recording);
/// returns the folder the files are in (`runs/<name>/export/`) and the stage whose
/// model was exported.
pub fn export_run(
    run_dir: &Path,
    ctx: &Context,
    fps: Option<f64>,
    progress: &Progress,
) -> Result<(PathBuf, &'static str)> {
    let mut settings = Table::new();
    if let Some(f) = fps {
        check_fps(f)?;
        settings.insert("fps".into(), Value::Float(f));
    }
    let ext = External {
        what: "the export",
        stage: STAGE,
        binary: "gaussians",
        package: "degs-gaussians",
        verb: Some("export"),
        settings,
    };
    on_last_model(run_dir, ctx, ext, progress)
}

/// `--fps f` must be a positive rate.
pub(crate) fn check_fps(f: f64) -> Result<()> {
    if !(f.is_finite() && f > 0.0) {
        bail!("--fps {f}: give a positive number of frames per second");
    }
    Ok(())
}

/// Run `ext` (a `gaussians` verb taking `--scene` and `--model`) as a cached node on the
/// run's last model (the joint training's, else the warm-up's) and link its files into
/// `runs/<name>/<ext.stage>/`; that folder and the model's stage.
pub(crate) fn on_last_model(
    run_dir: &Path,
    ctx: &Context,
    ext: External,
    progress: &Progress,
) -> Result<(PathBuf, &'static str)> {
    let record = RunRecord::read(&run_dir.join("run.json"))?;
    let scene = external::scene_of(&record)
        .with_context(|| format!("{}: the run has no scene", run_dir.display()))?;
    let (stage, model) = stages::render_stages()
        .find_map(|s| {
            let out = external::output_of(&record, s.name)?;
            out.0.join("model.json").is_file().then_some((s.name, out))
        })
        .with_context(|| format!("{}: the run has no model", run_dir.display()))?;
    let given = |flag: &'static str, name: &str, (entry, key): (PathBuf, String)| Given {
        flag,
        name: name.to_string(),
        entry,
        key,
    };
    let inputs = vec![
        given("--scene", stages::SCENE, scene),
        given("--model", stage, model),
    ];
    let where_ = (record.experiment.as_str(), record.cache_root.clone());
    let node = ext.stage;
    let done = external::run_external(&ext, inputs, where_, ctx, progress)?;
    let entry = done.entry.unwrap_or_default();
    let to = run_dir.join(node);
    link_files(&entry, &to)?;
    Ok((to, stage))
}

/// Make `to` hold exactly the files of `from` and of its folders (hard links, a copy
/// across file systems), atomically; the cache's manifest and the stage's output marker
/// stay out. An earlier output there is replaced, a folder `degs` did not write is
/// refused.
fn link_files(from: &Path, to: &Path) -> Result<()> {
    let rule = scene::atomic::OutputRule::new("degs export")
        .force(true)
        .source(from);
    let dir = scene::atomic::AtomicDir::new(to, &rule)?;
    link_tree(from, dir.path(), true)?;
    dir.commit()?;
    Ok(())
}

fn link_tree(from: &Path, to: &Path, top: bool) -> Result<()> {
    for e in std::fs::read_dir(from).with_context(|| format!("{}", from.display()))? {
        let e = e?;
        let name = e.file_name();
        let own = [scene::atomic::ENTRY_MANIFEST, scene::atomic::OUTPUT_MARKER];
        if top && own.iter().any(|o| name == *o) {
            continue;
        }
        let (src, dest) = (e.path(), to.join(&name));
        if src.is_dir() {
            std::fs::create_dir_all(&dest)
                .with_context(|| format!("{}: cannot create", dest.display()))?;
            link_tree(&src, &dest, false)?;
        } else if src.is_file() && std::fs::hard_link(&src, &dest).is_err() {
            std::fs::copy(&src, &dest)
                .with_context(|| format!("{}: cannot write", dest.display()))?;
        }
    }
    Ok(())
}
