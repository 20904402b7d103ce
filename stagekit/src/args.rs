//! The flags every stage shares, flattened into each stage's command line
//! (`#[command(flatten)]`), so that they read and behave the same in every binary.

use std::path::PathBuf;

/// Where a stage writes, whether it may replace what it wrote before, and its settings
/// file: every stage's `--out`, `--force` and `--config`.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct OutputArgs {
    /// Output directory (written under a temporary name, renamed when complete)
    #[arg(long)]
    pub out: PathBuf,
    /// Replace an earlier output of this command at OUT (never a folder that holds an
    /// input, nor one some other program wrote)
    #[arg(long)]
    pub force: bool,
    /// Settings file (TOML with the stage's settings, `STAGE settings --defaults`); flags
    /// override it; the resolved settings are written to OUT/settings.toml
    #[arg(long)]
    pub config: Option<PathBuf>,
}

/// A stage that reads a scene directory: `--scene` and the [`OutputArgs`].
#[derive(Clone, Debug, Default, clap::Args)]
pub struct StageArgs {
    /// Scene directory (transforms_train.json, transforms_test.json, images/, events)
    #[arg(long)]
    pub scene: PathBuf,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// The flags every training stage adds: `--iterations` and `--seed`.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct TrainingArgs {
    /// Training iterations (the default is the stage's setting `iterations`)
    #[arg(long)]
    pub iterations: Option<u32>,
    /// Seed of every random choice of the training (initialisation, sampling, order)
    #[arg(long)]
    pub seed: Option<u64>,
}

impl StageArgs {
    /// `--scene SCENE --out OUT` (for callers that build a stage's arguments in code).
    pub fn new(scene: impl Into<PathBuf>, out: impl Into<PathBuf>) -> StageArgs {
        StageArgs {
            scene: scene.into(),
            output: OutputArgs {
                out: out.into(),
                ..OutputArgs::default()
            },
        }
    }

    /// The same with `--config CONFIG`.
    pub fn with_config(mut self, config: impl Into<PathBuf>) -> StageArgs {
        self.output.config = Some(config.into());
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        stage: StageArgs,
        #[command(flatten)]
        training: TrainingArgs,
    }

    #[test]
    fn the_shared_flags_parse_into_their_fields() {
        let c = Cli::parse_from([
            "x",
            "--scene",
            "s",
            "--out",
            "o",
            "--force",
            "--config",
            "c.toml",
            "--iterations",
            "7",
            "--seed",
            "3",
        ]);
        assert_eq!(c.stage.scene, PathBuf::from("s"));
        assert_eq!(c.stage.output.out, PathBuf::from("o"));
        assert!(c.stage.output.force);
        assert_eq!(c.stage.output.config, Some(PathBuf::from("c.toml")));
        assert_eq!((c.training.iterations, c.training.seed), (Some(7), Some(3)));
        let bare = Cli::parse_from(["x", "--scene", "s", "--out", "o"]);
        assert!(!bare.stage.output.force && bare.stage.output.config.is_none());
        assert_eq!((bare.training.iterations, bare.training.seed), (None, None));
        assert!(
            Cli::try_parse_from(["x", "--out", "o"]).is_err(),
            "--scene is required"
        );
    }
}
