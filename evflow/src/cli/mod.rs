//! The `evflow` command line: each command's arguments (clap) and what it runs. The
//! binary (`main.rs`) only parses and dispatches to these.
//!
//! - [`args`]: arguments shared by the flow commands (where the events come from, the
//!   settings and weights, resolved with `stagekit::settings`);
//! - [`flow`]: `finetune`, `predict` and `eval` (the pipeline's `evflow` stage);
//! - [`simulate`]: frames → events;
//! - [`pretrain`]: pretraining on synthetic scenes.

pub mod args;
pub mod flow;
pub mod pretrain;
pub mod simulate;

/// The `evflow` command with the defaults of the settings that flags override shown in
/// their help (from `FlowSettings` and `PretrainSettings`: [`stagekit::show_defaults`]),
/// and that of `--max-flow` (not a setting: the shipped networks' value).
pub fn show_defaults(cmd: clap::Command) -> clap::Command {
    use stagekit::{show_defaults, with_default};
    let max_flow = |c: clap::Command| {
        c.mut_arg("max_flow", |a| {
            with_default(a, crate::net::io::DEFAULT_MAX_FLOW)
        })
    };
    cmd.mut_subcommand("finetune", |c| {
        max_flow(show_defaults::<crate::settings::FlowSettings>(
            c,
            flow::FINETUNE_SETTING_FLAGS,
        ))
    })
    .mut_subcommand("predict", max_flow)
    .mut_subcommand("pretrain", |c| {
        show_defaults::<crate::pretrain::PretrainSettings>(c, pretrain::PRETRAIN_SETTING_FLAGS)
    })
}
