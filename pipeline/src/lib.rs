//! degs: experiment files, the staged runner with its content-addressed cache
//! (DESIGN §4), status / gc / plan, synthetic scenes, evaluation and the demo.
//!
//! The `degs` binary is a thin clap layer over these modules; tests and other tools
//! can call them directly.

pub mod cache;
pub mod canon;
pub mod defaults;
pub mod demo;
pub mod eval;
pub mod experiment;
pub mod graph;
pub mod process;
pub mod progress;
pub mod record;
pub mod runner;
pub mod status;
pub mod synth;
