//! degs: experiment files, the stage registry, the staged runner with its
//! content-addressed cache (docs/DESIGN.md §4), status / gc / plan, synthetic scenes,
//! evaluation, the demo, sweeps (`sweep`, `sweep_run`), batch plans (`plan`) and charts.
//!
//! The `degs` binary is a thin layer over [`cli`] (its command line) and [`commands`]
//! (what each sub-command does); tests and other tools can call the modules directly.

pub mod baselines;
pub mod cache;
pub mod canon;
pub mod chart;
pub mod cli;
pub mod command_line;
pub mod commands;
pub mod config_show;
pub mod context;
pub mod demo;
pub mod eval;
pub mod experiment;
pub mod graph;
pub mod overrides;
pub mod plan;
pub mod process;
pub mod progress;
pub mod record;
pub mod runner;
pub mod settings;
pub mod stages;
pub mod status;
pub mod stress;
pub mod sweep;
pub mod sweep_run;
pub mod synth;
