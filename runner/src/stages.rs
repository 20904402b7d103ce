//! The stage registry: every external stage, in run order, with everything `degs`
//! knows about it. The graph, the experiment file's tables, `degs config show`, the
//! demo's summary and `degs eval` all derive from [`STAGES`]: adding a stage is adding
//! one entry there. A stage's settings are not here: `degs` asks its binary
//! (`STAGE settings`, [`crate::settings`]).
//!
//! Node 0 of the graph is the scene: a directory (`[scene] dir`, node name `scene`) or
//! written by the `synth` binary's `synth scene` (node name `synth`).

use anyhow::{Result, bail};
use std::path::Path;

/// Node name of the scene when it is a directory.
pub const SCENE: &str = "scene";
/// Node name (and `degs` sub-command) of the scene when it is synthesised.
pub const SYNTH: &str = "synth";
/// The key figures of the synthesised scene's `report.json`.
pub(crate) const SYNTH_FIGURES: &[Figure] = &[
    Figure::plain("train_frames", "train frames"),
    Figure::plain("test_frames", "test frames"),
    Figure::plain("novel_frames", "novel views"),
    Figure::plain("events", "events"),
];

/// One external stage.
pub struct Stage {
    /// The experiment table `[name]`, the cache directory `cache/<name>/`, the node name.
    pub name: &'static str,
    /// Its executable, looked up in `--stages DIR`, else next to `degs`, else on `PATH`.
    pub binary: &'static str,
    /// The sub-command given before the flags (`evflow finetune`).
    pub verb: Option<&'static str>,
    /// What it reads: the output directories of earlier nodes.
    pub inputs: &'static [Input],
    /// The cargo package that builds the binary (for "how to build it" messages).
    pub package: &'static str,
    /// Sub-directory holding its renders of the scene's test frames, if it writes them
    /// (its renders of the novel views, when the scene has them, in `novel/` under it).
    /// `degs eval` and the demo use the last stage in run order that has them.
    pub renders: Option<&'static str>,
    /// Sub-directory holding per-event flow files (`*.evflow`), if it writes them.
    pub event_flow: Option<&'static str>,
    /// The key figures of its `report.json`, for the demo's summary.
    pub figures: &'static [Figure],
}

/// An input of a stage: the output directory of node `node`, passed as `flag DIR`.
pub struct Input {
    pub node: &'static str,
    pub flag: &'static str,
}

/// A number at `path` (`/`-separated) of a `report.json`, shown as `label`, times
/// `scale`, in `unit`.
pub struct Figure {
    pub path: &'static str,
    pub label: &'static str,
    pub scale: f64,
    pub unit: &'static str,
}

impl Figure {
    pub const fn new(path: &'static str, label: &'static str, unit: &'static str) -> Figure {
        Figure {
            path,
            label,
            scale: 1.0,
            unit,
        }
    }
    pub const fn plain(path: &'static str, label: &'static str) -> Figure {
        Figure::new(path, label, "")
    }
    pub const fn percent(path: &'static str, label: &'static str) -> Figure {
        Figure {
            path,
            label,
            scale: 100.0,
            unit: "%",
        }
    }
}

const SCENE_INPUT: Input = Input {
    node: SCENE,
    flag: "--scene",
};

/// The external stages in run order; every input names the scene or an earlier stage.
pub const STAGES: &[Stage] = &[
    Stage {
        name: "evflow",
        binary: "evflow",
        verb: Some("finetune"),
        inputs: &[SCENE_INPUT],
        package: "degs-evflow",
        renders: None,
        event_flow: Some("flow"),
        figures: &[
            Figure::new("flow_epe_px_s", "EPE", "px/s"),
            Figure::new("flow_err_px", "EPE", "px"),
            Figure::percent("flow_outliers", "outliers"),
            Figure::plain("warp_gain", "warp gain"),
        ],
    },
    Stage {
        name: "gaussians",
        binary: "gaussians",
        verb: Some("train"),
        inputs: &[SCENE_INPUT],
        package: "degs-gaussians",
        renders: Some("renders"),
        event_flow: None,
        figures: &[
            Figure::new("test/psnr_mean", "test PSNR", "dB"),
            Figure::plain("test/ssim_mean", "SSIM"),
            Figure::new("novel/psnr_mean", "novel PSNR", "dB"),
            Figure::plain("gaussians", "Gaussians"),
        ],
    },
    Stage {
        name: "assoc",
        binary: "assoc",
        verb: None,
        inputs: &[
            SCENE_INPUT,
            Input {
                node: "gaussians",
                flag: "--model",
            },
        ],
        package: "degs-assoc",
        renders: None,
        event_flow: None,
        figures: &[
            Figure::percent("bound_fraction_mean", "bound"),
            Figure::plain("gaussians", "of Gaussians"),
        ],
    },
    Stage {
        name: "deform",
        binary: "deform",
        verb: Some("train"),
        inputs: &[
            SCENE_INPUT,
            Input {
                node: "gaussians",
                flag: "--model",
            },
            Input {
                node: "evflow",
                flag: "--flows",
            },
            Input {
                node: "assoc",
                flag: "--assoc",
            },
        ],
        package: "degs-deform",
        renders: Some("renders"),
        event_flow: None,
        figures: &[
            Figure::new("test/psnr_mean", "test PSNR", "dB"),
            Figure::plain("test/ssim_mean", "SSIM"),
            Figure::new("novel/psnr_mean", "novel PSNR", "dB"),
            Figure::new("baselines/blend/psnr_mean", "linear blend", "dB"),
            Figure::new("baselines/events/psnr_mean", "event pseudo image", "dB"),
            Figure::new("camera/corrected/rotation_deg_mean", "camera error", "°"),
        ],
    },
];

impl Stage {
    /// How it is invoked: `evflow finetune`, `assoc`.
    pub fn invocation(&self) -> String {
        match self.verb {
            Some(v) => format!("{} {v}", self.binary),
            None => self.binary.to_string(),
        }
    }

    /// Why it cannot run when its binary is missing, and how to build it.
    pub(crate) fn not_built_message(&self, stage_dir: Option<&Path>) -> String {
        not_built(self.binary, self.package, stage_dir)
    }
}

/// Why a node cannot run when its binary `binary` (of cargo package `package`) is not
/// found (only in `stage_dir` when given, else next to degs or on `PATH`), and how to
/// build it.
pub fn not_built(binary: &str, package: &str, stage_dir: Option<&Path>) -> String {
    let place = match stage_dir {
        Some(d) => format!("in {}", d.display()),
        None => "next to degs or on PATH".into(),
    };
    format!(
        "not built yet: no `{binary}` binary {place} (build it with `cargo build --release -p \
         {package}`)"
    )
}

/// The stage named `name`.
pub fn find(name: &str) -> Option<&'static Stage> {
    STAGES.iter().find(|s| s.name == name)
}

/// Stages that render the test frames, the last in run order first.
pub fn render_stages() -> impl Iterator<Item = &'static Stage> {
    STAGES.iter().rev().filter(|s| s.renders.is_some())
}

/// The key figures of node `name`'s report (the scene's for `synth`).
pub fn figures(name: &str) -> &'static [Figure] {
    match find(name) {
        Some(s) => s.figures,
        None if name == SYNTH => SYNTH_FIGURES,
        None => &[],
    }
}

/// Every node name, in run order (`synth` for the scene).
pub(crate) fn node_names() -> Vec<&'static str> {
    std::iter::once(SYNTH)
        .chain(STAGES.iter().map(|s| s.name))
        .collect()
}

/// Index of a node by name (`scene` and `synth` are node 0; stage `i` is node `i + 1`).
pub(crate) fn node_index(name: &str) -> Option<usize> {
    if name == SCENE || name == SYNTH {
        return Some(0);
    }
    STAGES.iter().position(|s| s.name == name).map(|i| i + 1)
}

/// Parse a user-given stage name (for `--until` / `--force`).
pub fn parse_stage(name: &str) -> Result<usize> {
    match node_index(name) {
        Some(i) => Ok(i),
        None => bail!(
            "unknown stage {name:?} (stages: {})",
            node_names().join(", ")
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stage_names() {
        assert_eq!(parse_stage("scene").unwrap(), 0);
        assert_eq!(parse_stage("deform").unwrap(), 4);
        assert!(parse_stage("deformx").is_err());
    }

    #[test]
    fn names_are_unique_and_inputs_name_earlier_nodes() {
        for (i, s) in STAGES.iter().enumerate() {
            for input in s.inputs {
                let n = node_index(input.node).unwrap_or(usize::MAX);
                assert!(
                    n <= i,
                    "{} reads {}, not an earlier node",
                    s.name,
                    input.node
                );
            }
            assert_eq!(STAGES.iter().filter(|t| t.name == s.name).count(), 1);
            // a stage's name is also an experiment table and a node name
            assert!(![SCENE, SYNTH, "name"].contains(&s.name), "{}", s.name);
        }
    }

    #[test]
    fn render_stages_come_last_first() {
        let names: Vec<&str> = render_stages().map(|s| s.name).collect();
        assert_eq!(names, ["deform", "gaussians"]);
    }
}
