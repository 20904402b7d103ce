//! The `evflow` command line: each command's arguments (clap) and what it runs. The
//! binary (`main.rs`) only parses and dispatches to these.
//!
//! - [`args`]: arguments shared by the flow commands (where the events come from, the
//!   settings and weights) and reading a TOML settings file;
//! - [`flow`]: `finetune`, `predict` and `eval` (the pipeline's `evflow` stage);
//! - [`simulate`]: frames → events;
//! - [`pretrain`]: pretraining on synthetic scenes.

pub mod args;
pub mod flow;
pub mod pretrain;
pub mod simulate;
