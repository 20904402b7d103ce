//! The stage graph and its resolution into cache keys.
//!
//! ```text
//! synth (or a scene dir) ──► evflow ─────────────────────┐
//!          │          └────► gaussians ──► assoc ──► deform
//!          └───────────────────────────────┴───────────┘
//! ```
//! A stage's key is blake3 of its name, the hash of its binary, its canonical
//! settings and the keys of its inputs (docs/DESIGN.md §4).

use crate::cache::{BinaryHashes, Cache, dir_fingerprint};
use crate::canon;
use crate::context::Context;
use crate::experiment::{Experiment, SceneSource};
use crate::stages::{self, STAGES};
use anyhow::Result;
use std::path::PathBuf;
use toml::Table;

/// What a node is.
#[derive(Clone, Debug)]
pub enum NodeKind {
    /// An existing scene directory: no stage runs, its key is a fingerprint.
    SceneDir(PathBuf),
    /// A synthetic scene, written by `synth scene` (the `synth` binary).
    Synth,
    /// An external stage binary.
    External,
    /// A finished stage's output read as it is (the inputs of the evaluation that
    /// `degs eval` runs over a finished run): no stage runs, nothing is reported.
    Given(PathBuf),
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

pub fn key_of(stage: &str, binary_hash: &str, settings: &Table, inputs: &[(&str, &str)]) -> String {
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
    let mut nodes = Vec::with_capacity(STAGES.len() + 1);
    nodes.push(match &exp.scene {
        SceneSource::Dir(dir) => Node {
            stage: stages::SCENE.into(),
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
            let binary = ctx.stage_binary(stages::SYNTH);
            let binary_hash = match &binary {
                Some(b) => Some(hashes.hash(b)?),
                None => None,
            };
            let key = binary_hash
                .as_ref()
                .map(|bh| key_of(stages::SYNTH, bh, &settings, &[]));
            Node {
                stage: stages::SYNTH.into(),
                kind: NodeKind::Synth,
                verb: Some("scene"),
                unavailable: binary.is_none().then(|| {
                    stages::not_built(stages::SYNTH, "degs-synth", ctx.stage_dir.as_deref())
                }),
                binary,
                binary_hash,
                settings,
                inputs: vec![],
                key,
            }
        }
    });
    for def in STAGES {
        let inputs: Vec<Input> = def
            .inputs
            .iter()
            .map(|input| Input {
                flag: input.flag,
                node: stages::node_index(input.node).unwrap_or(0),
            })
            .collect();
        let settings = exp.settings(def.name);
        let binary = ctx.stage_binary(def.binary);
        let binary_hash = match &binary {
            Some(b) => Some(hashes.hash(b)?),
            None => None,
        };
        let blocked = inputs
            .iter()
            .find(|i| nodes[i.node].key.is_none())
            .map(|i| format!("needs {}, which is not built yet", nodes[i.node].stage));
        let unavailable = match (&binary, blocked) {
            (None, _) => Some(def.not_built_message(ctx.stage_dir.as_deref())),
            (Some(_), b) => b,
        };
        let key = match (&binary, &binary_hash, &unavailable) {
            (Some(bin), Some(bh), None) => {
                // The stage's own check of its table; the files outside the graph it
                // names (evflow's base weights) enter the key by content.
                let files = exp.check_stage(def.name, bin)?;
                let file_hashes = files
                    .iter()
                    .map(|(name, path)| Ok((name.as_str(), hashes.hash(path)?)))
                    .collect::<Result<Vec<_>>>()?;
                let mut in_keys: Vec<(&str, &str)> = inputs
                    .iter()
                    .map(|i| (i.flag, nodes[i.node].key.as_deref().unwrap_or("")))
                    .collect();
                in_keys.extend(file_hashes.iter().map(|(n, h)| (*n, h.as_str())));
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
pub(crate) fn descendants(nodes: &[Node], i: usize) -> Vec<bool> {
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
pub(crate) fn output_dir(nodes: &[Node], i: usize, cache: &Cache) -> Option<PathBuf> {
    match &nodes[i].kind {
        NodeKind::SceneDir(d) | NodeKind::Given(d) => Some(d.clone()),
        _ => nodes[i]
            .key
            .as_ref()
            .map(|k| cache.entry(&nodes[i].stage, k)),
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

    /// The synth stage's key follows the `synth` binary, not the `degs` binary that
    /// runs it: two different `degs` executables give the same key, a rebuilt `synth`
    /// another.
    #[test]
    fn synth_key_follows_the_synth_binary() {
        let dir = tempfile::tempdir().unwrap();
        let exp = Experiment::parse(
            "name = \"a\"\n[scene]\nsynth = \"rigid\"\n",
            &dir.path().join("a.toml"),
        )
        .unwrap();
        let bin = dir.path().join("bin");
        std::fs::create_dir_all(&bin).unwrap();
        let key = |degs: &[u8], synth: &[u8]| {
            use std::os::unix::fs::PermissionsExt;
            let (d, s) = (dir.path().join("degs"), bin.join("synth"));
            std::fs::write(&d, degs).unwrap();
            std::fs::write(&s, synth).unwrap();
            std::fs::set_permissions(&s, std::fs::Permissions::from_mode(0o755)).unwrap();
            let ctx = Context {
                cache: Cache::new(dir.path().join("c")),
                stage_dir: Some(bin.clone()),
                degs: d,
            };
            let nodes = resolve(&exp, &ctx, &mut BinaryHashes::default()).unwrap();
            let synth = nodes.iter().find(|n| n.stage == stages::SYNTH).unwrap();
            (
                synth.key.clone().unwrap(),
                synth.binary_hash.clone().unwrap(),
            )
        };
        let (k1, h1) = key(b"one build", b"synth one");
        let (k2, _) = key(b"another build of the runner", b"synth one");
        let (k3, h3) = key(b"one build", b"synth two");
        assert_eq!(k1, k2);
        assert_ne!(k1, k3);
        assert_ne!(h1, h3);
        // the binary's content hash (the last call left "synth two" there)
        assert_eq!(h3, crate::cache::hash_file(&bin.join("synth")).unwrap());
    }
}
