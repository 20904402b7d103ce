//! `synth`: the synthetic-scene stages the runner (`degs`) starts as processes: `synth
//! scene` writes the scene of a settings file (the first node of an experiment with
//! `[scene] synth = …`), `synth stress` applies a stress transform to a scene (`degs
//! stress`). Thin CLI over [`synth::scene_dir`] and [`synth::transform`]; people use
//! `degs synth --preset NAME`.

use clap::{Parser, Subcommand};
use scene::atomic::OutputRule;
use stagekit::{SettingsArgs, exit_on_error, settings};
use std::path::PathBuf;
use std::process::ExitCode;
use synth::SynthConfig;
use synth::transform::SceneTransform;

/// Synthetic scenes with ground truth, and stress transforms of scenes (the runner's
/// stages; `degs synth --preset NAME --out DIR` is the command for people).
#[derive(Parser)]
#[command(name = "synth", version)]
struct Cli {
    #[command(subcommand)]
    verb: Verb,
}

#[derive(Subcommand)]
enum Verb {
    /// Write the synthetic scene of a settings file (every key of `degs config show`'s
    /// `[scene.settings]`): frames, events, ground truth, novel views.
    Scene {
        /// Settings file (TOML; keys not given take the defaults).
        #[arg(long)]
        config: PathBuf,
        /// Output scene directory (appears complete or not at all).
        #[arg(long)]
        out: PathBuf,
        /// Replace an earlier scene written by degs synth at OUT.
        #[arg(long)]
        force: bool,
    },
    /// Apply a stress transform (fewer frames, noise, hot pixels, a wrong contrast
    /// threshold, a gap, a burst, a corrupt file) to a scene: `degs stress` does this.
    Stress {
        /// The scene to transform.
        #[arg(long)]
        scene: PathBuf,
        /// The transform's settings (TOML).
        #[arg(long)]
        config: PathBuf,
        /// Output scene directory (appears complete or not at all).
        #[arg(long)]
        out: PathBuf,
    },
    /// The settings of `synth scene`: `--defaults` prints them as TOML, `--check FILE`
    /// checks a settings file.
    Settings(SettingsArgs),
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.verb {
        Verb::Settings(a) => Ok(stagekit::verb::run::<SynthConfig>(
            &a,
            stagekit::verb::no_files,
        )?),
        Verb::Scene { config, out, force } => {
            let cfg: SynthConfig = settings::read_file(&config)?;
            let rule = OutputRule::new(synth::SYNTH_COMMAND)
                .force(force)
                .source(&config);
            let s = synth::write_synthetic_scene_with(&cfg, &out, &rule)?;
            eprintln!("synth: {} -> {}", s.line(), out.display());
            Ok(ExitCode::SUCCESS)
        }
        Verb::Stress { scene, config, out } => {
            let text = std::fs::read_to_string(&config)
                .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", config.display()))?;
            let t: SceneTransform = toml::from_str(&text).map_err(|e| {
                anyhow::anyhow!("{}: {}", config.display(), settings::toml_error(&text, &e))
            })?;
            let s = synth::transform::apply(&scene, &out, &t)?;
            eprintln!(
                "synth: stress: {} of {} train frames, {} of {} events -> {}",
                s.train_frames,
                s.train_frames_before,
                s.events,
                s.events_before,
                out.display()
            );
            Ok(ExitCode::SUCCESS)
        }
    }
}

fn main() -> ExitCode {
    exit_on_error("synth", || run(Cli::parse()))
}
