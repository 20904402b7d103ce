//! Test support shared by every crate's tests (a dev-dependency only): the seeded
//! mutation harness that drives each file reader with thousands of damaged copies of a
//! valid file ([`mutate`]), the allocator wrapper that measures how much a reader or a
//! training step allocates ([`alloc`]), and the paths of the project's real recordings
//! ([`testdata`]). It has no dependencies.

pub mod alloc;
pub mod mutate;
pub mod testdata;

pub use alloc::TrackingAlloc;
pub use mutate::{Failure, Mutation, Plan, Problem, Report, fuzz, fuzz_reader};
