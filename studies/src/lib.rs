//! What degs builds on its runner to compare settings (docs/DESIGN.md §4): sweeps (a grid
//! of experiments over one base, [`sweep`], run by [`sweep_run`]) and stress runs (one
//! experiment over transformed copies of its scene, [`stress`]).

pub mod stress;
pub mod sweep;
pub mod sweep_run;
