//! `evflow pretrain`: pretraining on synthetic scenes ([`crate::pretrain::run`]) with a
//! progress display.

use crate::pretrain::PretrainSettings;
use clap::Args;
use stagekit::Progress;
use stagekit::settings::{resolve, write_resolved};

#[derive(Args, Debug)]
pub struct PretrainArgs {
    #[command(flatten)]
    pub output: stagekit::OutputArgs,
    /// Base width C of the network (overrides the config).
    #[arg(long)]
    pub base: Option<usize>,
    /// Training iterations (overrides the config).
    #[arg(long)]
    pub iterations: Option<usize>,
}

/// The flags of [`PretrainArgs`] that override a setting, each with its key in
/// [`PretrainSettings`] (their `--help` shows its default).
pub(crate) const PRETRAIN_SETTING_FLAGS: &[(&str, &str)] =
    &[("base", "base"), ("iterations", "iterations")];

impl PretrainArgs {
    /// Pretrain into `--out` and write the resolved settings beside the weights.
    pub fn run(&self) -> anyhow::Result<()> {
        let out = &self.output.out;
        let s = resolve(self.output.config.as_deref(), |s: &mut PretrainSettings| {
            s.base = self.base.unwrap_or(s.base);
            s.iterations = self.iterations.unwrap_or(s.iterations);
        })?;
        let progress = Progress::new("pretrain", s.iterations as u64);
        let r = crate::pretrain::run(&s, out, self.output.force, &mut |k, _, loss| {
            progress.set(k as u64, || format!("loss {loss:.4}"));
        })?;
        progress.finish();
        write_resolved(out, &s)?;
        eprintln!(
            "evflow: pretrained {} params in {:.1} s ({:.3} s/step) -> {}",
            r.params,
            r.train_s,
            r.step_s,
            out.display()
        );
        Ok(())
    }
}
