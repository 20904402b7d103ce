//! The stage graph and its resolution into cache keys.
//!
//! ```text
//! synth (or a scene dir) ──► evflow ─────────────────────┐
//!          │          └────► gaussians ──► assoc ──► deform
//!          └───────────────────────────────┴───────────┘
//! ```
//! A stage's key is blake3 of its name, the hash of its binary, its canonical
//! settings and the keys of its inputs (DESIGN §4).

use crate::cache::{BinaryHashes, Cache, dir_fingerprint};
use crate::canon;
use crate::experiment::{Experiment, SceneSource};
use anyhow::Result;
use std::path::{Path, PathBuf};
use toml::Table;

/// One stage: its name, the verb its binary takes (`evflow finetune`, `gaussians
/// train`; none for `assoc`) and the inputs it needs as (node name, command-line flag).
pub struct StageDef {
    pub name: &'static str,
    pub verb: Option<&'static str>,
    pub needs: &'static [(&'static str, &'static str)],
    /// The cargo package that builds the binary (for "how to build it" messages).
    pub package: &'static str,
}

/// The external stages in run order (node 0 is the scene: `synth` or a directory).
pub const STAGES: [StageDef; 4] = [
    StageDef {
        name: "evflow",
        verb: Some("finetune"),
        package: "evflow",
        needs: &[("scene", "--scene")],
    },
    StageDef {
        name: "gaussians",
        verb: Some("train"),
        package: "gaussians",
        needs: &[("scene", "--scene")],
    },
    StageDef {
        name: "assoc",
        verb: None,
        package: "assoc",
        needs: &[("scene", "--scene"), ("gaussians", "--model")],
    },
    StageDef {
        name: "deform",
        // Not written yet: set its verb here when the crate lands.
        verb: None,
        package: "deform",
        needs: &[
            ("scene", "--scene"),
            ("gaussians", "--model"),
            ("evflow", "--flows"),
            ("assoc", "--assoc"),
        ],
    },
];

/// Every node name, in run order.
pub const NODE_NAMES: [&str; 5] = ["synth", "evflow", "gaussians", "assoc", "deform"];

/// What a node is.
#[derive(Clone, Debug)]
pub enum NodeKind {
    /// An existing scene directory: no stage runs, its key is a fingerprint.
    SceneDir(PathBuf),
    /// `degs synth` (built in, run as a process of this binary).
    Synth,
    /// An external stage binary.
    External,
}

/// An input of a node.
#[derive(Clone, Debug)]
pub struct Input {
    pub flag: &'static str,
    pub node: usize,
}

/// A resolved node of the graph.
#[derive(Clone, Debug)]
pub struct Node {
    /// "scene" for a directory, else the stage name.
    pub stage: String,
    pub kind: NodeKind,
    /// The sub-command given before the flags (`synth`, `finetune`, `train`).
    pub verb: Option<&'static str>,
    pub binary: Option<PathBuf>,
    pub binary_hash: Option<String>,
    /// Canonical settings (for synth: the whole SynthConfig).
    pub settings: Table,
    pub inputs: Vec<Input>,
    /// None when the binary or an input is not available.
    pub key: Option<String>,
    /// Why the node cannot run (binary missing, or an input's).
    pub unavailable: Option<String>,
}

/// Where to find things.
#[derive(Clone, Debug)]
pub struct Context {
    pub cache: Cache,
    /// Look for stage binaries only here (tests, custom builds).
    pub stage_dir: Option<PathBuf>,
    /// The `degs` executable (runs the built-in synth stage).
    pub degs: PathBuf,
}

impl Context {
    pub fn new(cache: Cache, stage_dir: Option<PathBuf>) -> Result<Context> {
        let degs = std::env::current_exe()?;
        Ok(Context {
            cache,
            stage_dir,
            degs,
        })
    }
}

/// The binary of `stage`: in `stage_dir` when given (only there), else next to the
/// running `degs`, else on `PATH`.
pub fn find_stage_binary(stage: &str, stage_dir: Option<&Path>, degs: &Path) -> Option<PathBuf> {
    let is_exe = |p: &Path| {
        use std::os::unix::fs::PermissionsExt;
        p.metadata()
            .map(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
            .unwrap_or(false)
    };
    if let Some(d) = stage_dir {
        let p = d.join(stage);
        return is_exe(&p).then_some(p);
    }
    let beside = degs.parent().map(|d| d.join(stage));
    if let Some(p) = beside.filter(|p| is_exe(p)) {
        return Some(p);
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join(stage))
        .find(|p| is_exe(p))
}

fn key_of(stage: &str, binary_hash: &str, settings: &Table, inputs: &[(&str, &str)]) -> String {
    let mut h = blake3::Hasher::new();
    for part in [
        "degs-key-v1",
        stage,
        binary_hash,
        &canon::canonical_string(settings),
    ] {
        h.update(part.as_bytes());
        h.update(&[0]);
    }
    for (flag, key) in inputs {
        h.update(flag.as_bytes());
        h.update(&[0]);
        h.update(key.as_bytes());
        h.update(&[0]);
    }
    h.finalize().to_hex()[..32].to_string()
}

/// Resolve the experiment into nodes with keys (hashing binaries as needed).
pub fn resolve(exp: &Experiment, ctx: &Context, hashes: &mut BinaryHashes) -> Result<Vec<Node>> {
    let mut nodes = Vec::with_capacity(5);
    nodes.push(match &exp.scene {
        SceneSource::Dir(dir) => Node {
            stage: "scene".into(),
            kind: NodeKind::SceneDir(dir.clone()),
            verb: None,
            binary: None,
            binary_hash: None,
            settings: Table::new(),
            inputs: vec![],
            key: Some(dir_fingerprint(dir)?),
            unavailable: None,
        },
        SceneSource::Synth(cfg) => {
            let settings = match toml::Value::try_from(cfg.as_ref())? {
                toml::Value::Table(t) => canon::canonical_table(&t),
                _ => Table::new(),
            };
            let binary_hash = hashes.hash(&ctx.degs)?;
            let key = key_of("synth", &binary_hash, &settings, &[]);
            Node {
                stage: "synth".into(),
                kind: NodeKind::Synth,
                verb: Some("synth"),
                binary: Some(ctx.degs.clone()),
                binary_hash: Some(binary_hash),
                settings,
                inputs: vec![],
                key: Some(key),
                unavailable: None,
            }
        }
    });
    for def in &STAGES {
        let inputs: Vec<Input> = def
            .needs
            .iter()
            .map(|(name, flag)| Input {
                flag,
                node: node_index(name),
            })
            .collect();
        let settings = exp.settings(def.name);
        let binary = find_stage_binary(def.name, ctx.stage_dir.as_deref(), &ctx.degs);
        let binary_hash = match &binary {
            Some(b) => Some(hashes.hash(b)?),
            None => None,
        };
        let blocked = inputs
            .iter()
            .find(|i| nodes[i.node].key.is_none())
            .map(|i| format!("needs {}, which is not built yet", nodes[i.node].stage));
        let unavailable = match (&binary, blocked) {
            (None, _) => Some(not_built_message(def, ctx.stage_dir.as_deref())),
            (Some(_), b) => b,
        };
        let key = match (&binary_hash, &unavailable) {
            (Some(bh), None) => {
                let mut in_keys: Vec<(&str, &str)> = inputs
                    .iter()
                    .map(|i| (i.flag, nodes[i.node].key.as_deref().unwrap_or("")))
                    .collect();
                // The flow network's base weights are an input like any other: replacing
                // the shipped file (or pointing `weights` elsewhere) re-runs evflow.
                let weights = match def.name {
                    "evflow" => base_weights_hash(&settings, hashes)?,
                    _ => None,
                };
                if let Some(w) = &weights {
                    in_keys.push(("weights", w));
                }
                Some(key_of(def.name, bh, &settings, &in_keys))
            }
            _ => None,
        };
        nodes.push(Node {
            stage: def.name.into(),
            kind: NodeKind::External,
            verb: def.verb,
            binary,
            binary_hash,
            settings,
            inputs,
            key,
            unavailable,
        });
    }
    Ok(nodes)
}

/// Content hash of the evflow base weights these settings resolve to (`weights = FILE`,
/// else `$EVFLOW_WEIGHTS`, else the shipped file); `None` when none can be found (the
/// stage then fails with its own message).
fn base_weights_hash(settings: &Table, hashes: &mut BinaryHashes) -> Result<Option<String>> {
    let explicit = settings
        .get("weights")
        .and_then(|v| v.as_str())
        .map(std::path::PathBuf::from);
    match evflow::net::io::resolve_weights(explicit.as_deref()) {
        Ok(path) if path.is_file() => Ok(Some(hashes.hash(&path)?)),
        _ => Ok(None),
    }
}

/// Why a stage cannot run when its binary is missing, and how to build it.
pub fn not_built_message(def: &StageDef, stage_dir: Option<&Path>) -> String {
    let place = match stage_dir {
        Some(d) => format!("in {}", d.display()),
        None => "next to degs or on PATH".into(),
    };
    format!(
        "not built yet: no `{}` binary {place} (build it with `cargo build --release -p {}`)",
        def.name, def.package
    )
}

/// The definition of an external stage by name.
pub fn stage_def(name: &str) -> Option<&'static StageDef> {
    STAGES.iter().find(|d| d.name == name)
}

/// Index of a node by name ("scene" and "synth" are node 0).
pub fn node_index(name: &str) -> usize {
    match name {
        "scene" | "synth" => 0,
        other => NODE_NAMES.iter().position(|n| *n == other).unwrap_or(0),
    }
}

/// Parse a user-given stage name (for `--until` / `--force`).
pub fn parse_stage(name: &str) -> Result<usize> {
    if name == "scene" || NODE_NAMES.contains(&name) {
        Ok(node_index(name))
    } else {
        anyhow::bail!("unknown stage {name:?} (stages: {})", NODE_NAMES.join(", "))
    }
}

/// `i` and every node it (transitively) needs.
pub fn ancestors(nodes: &[Node], i: usize) -> Vec<bool> {
    let mut mark = vec![false; nodes.len()];
    let mut stack = vec![i];
    while let Some(n) = stack.pop() {
        if !mark[n] {
            mark[n] = true;
            stack.extend(nodes[n].inputs.iter().map(|x| x.node));
        }
    }
    mark
}

/// `i` and every node that (transitively) needs it.
pub fn descendants(nodes: &[Node], i: usize) -> Vec<bool> {
    let mut mark = vec![false; nodes.len()];
    mark[i] = true;
    for n in 0..nodes.len() {
        if nodes[n].inputs.iter().any(|x| mark[x.node]) {
            mark[n] = true;
        }
    }
    mark
}

/// Output directory of a node: the scene dir, or its cache entry.
pub fn output_dir(nodes: &[Node], i: usize, cache: &Cache) -> Option<PathBuf> {
    match &nodes[i].kind {
        NodeKind::SceneDir(d) => Some(d.clone()),
        _ => nodes[i]
            .key
            .as_ref()
            .map(|k| cache.entry(&nodes[i].stage, k)),
    }
}

/// Path of the settings file a node is run with.
pub fn settings_path(cache: &Cache, exp: &str, stage: &str) -> PathBuf {
    cache.run_dir(exp).join(format!("{stage}.settings.toml"))
}

/// The command line of node `i`, writing to `out` with settings from `config`.
pub fn command(nodes: &[Node], i: usize, cache: &Cache, out: &Path, config: &Path) -> Vec<String> {
    let n = &nodes[i];
    let bin = n
        .binary
        .as_ref()
        .map(|b| b.display().to_string())
        .unwrap_or_else(|| n.stage.clone());
    let mut args = vec![bin];
    if let Some(verb) = n.verb {
        args.push(verb.into());
    }
    for input in &n.inputs {
        args.push(input.flag.into());
        let dir = output_dir(nodes, input.node, cache).unwrap_or_default();
        args.push(dir.display().to_string());
    }
    args.push("--out".into());
    args.push(out.display().to_string());
    args.push("--config".into());
    args.push(config.display().to_string());
    args
}

/// Quote a word for a POSIX shell.
pub fn shell_quote(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:+,@%".contains(c))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_depend_on_every_part() {
        let t: Table = "a = 1".parse().unwrap();
        let base = key_of("s", "b", &t, &[("--scene", "k")]);
        assert_eq!(base.len(), 32);
        assert_eq!(base, key_of("s", "b", &t, &[("--scene", "k")]));
        assert_ne!(base, key_of("s2", "b", &t, &[("--scene", "k")]));
        assert_ne!(base, key_of("s", "b2", &t, &[("--scene", "k")]));
        assert_ne!(base, key_of("s", "b", &Table::new(), &[("--scene", "k")]));
        assert_ne!(base, key_of("s", "b", &t, &[("--scene", "k2")]));
        assert_ne!(base, key_of("s", "b", &t, &[("--model", "k")]));
    }

    #[test]
    fn quoting() {
        assert_eq!(shell_quote("a/b.toml"), "a/b.toml");
        assert_eq!(shell_quote("it's here"), "'it'\\''s here'");
        assert_eq!(shell_quote(""), "''");
    }

    #[test]
    fn stage_names() {
        assert_eq!(parse_stage("scene").unwrap(), 0);
        assert_eq!(parse_stage("deform").unwrap(), 4);
        assert!(parse_stage("deformx").is_err());
    }
}
