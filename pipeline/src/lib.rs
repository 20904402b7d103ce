//! degs, the command: its command line ([`cli`]), what each sub-command does
//! ([`commands`]) and the demo ([`demo`]). The runner core lives in the `runner` crate,
//! sweeps and stress runs in `studies`, charts in `charts` (docs/DESIGN.md §2, §4).
//!
//! The `degs` binary is a thin layer over [`cli`] and [`commands`].

pub mod cli;
pub mod commands;
pub mod demo;
