//! `evflow pretrain`: pretraining on synthetic scenes ([`crate::pretrain::run`]) with a
//! progress bar on a terminal.

use super::args::read_toml;
use crate::pretrain::PretrainSettings;
use clap::Args;
use std::io::IsTerminal;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct PretrainArgs {
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Settings (TOML, keys of evflow::pretrain::PretrainSettings).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Base width C of the network (overrides the config).
    #[arg(long)]
    pub base: Option<usize>,
    /// Training iterations (overrides the config).
    #[arg(long)]
    pub iterations: Option<usize>,
}

impl PretrainArgs {
    /// Pretrain into `--out` and write the resolved settings beside the weights.
    pub fn run(&self) -> anyhow::Result<()> {
        let out = &self.out;
        let mut s = match &self.config {
            Some(p) => read_toml::<PretrainSettings>(p)?,
            None => PretrainSettings::default(),
        };
        if let Some(b) = self.base {
            s.base = b;
        }
        if let Some(i) = self.iterations {
            s.iterations = i;
        }
        let terminal = std::io::stderr().is_terminal();
        let bar = indicatif::ProgressBar::new(0);
        if !terminal {
            bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
        }
        let r = crate::pretrain::run(&s, out, &mut |k, n, loss| {
            bar.set_length(n as u64);
            bar.set_position(k as u64);
            bar.set_message(format!("loss {loss:.4}"));
            if !terminal && (k % 25 == 0 || k == n) {
                eprintln!("evflow: pretrain step {k}/{n} loss {loss:.4}");
            }
        })?;
        bar.finish_and_clear();
        let text = toml::to_string(&s)?;
        scene::atomic::write_bytes_atomic(&out.join("settings.toml"), text.as_bytes())?;
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
