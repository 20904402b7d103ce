//! `evflow simulate`: events from a directory of frames ([`synth::frames::simulate_frames`]).

use clap::Args;
use scene::manifest::FrameEncoding;
use std::path::PathBuf;
use synth::sim::SimConfig;

#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Directory with the frames and timestamps.txt.
    #[arg(long)]
    pub frames: PathBuf,
    /// Output event file (.evs).
    #[arg(long)]
    pub out: PathBuf,
    /// Simulator settings (TOML, keys of synth::sim::SimConfig).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Random seed (threshold mismatch, noise).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// How the frames' codes map to intensity: srgb (the PNG convention: decoded to
    /// linear before the log) or linear (codes proportional to intensity, as `degs
    /// synth` writes them)
    #[arg(long, value_enum, default_value_t = Encoding::Srgb)]
    pub frame_encoding: Encoding,
}

/// `--frame-encoding`.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum Encoding {
    Srgb,
    Linear,
}

impl SimulateArgs {
    /// Simulate and write the event file.
    pub fn run(&self) -> anyhow::Result<()> {
        let cfg = stagekit::settings::resolve::<SimConfig>(self.config.as_deref(), |_| {})?;
        let encoding = match self.frame_encoding {
            Encoding::Srgb => FrameEncoding::Srgb,
            Encoding::Linear => FrameEncoding::Linear,
        };
        let s = synth::frames::simulate_frames(&self.frames, &self.out, &cfg, self.seed, encoding)?;
        eprintln!(
            "evflow: {} frames -> {} events ({}x{}) in {:.2} s -> {}",
            s.frames,
            s.events,
            s.width,
            s.height,
            s.seconds,
            self.out.display()
        );
        Ok(())
    }
}
