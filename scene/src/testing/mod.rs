//! Test support shared by every crate's tests: the seeded mutation harness that drives
//! each file reader with thousands of damaged copies of a valid file ([`mutate`]), and
//! the allocator wrapper that measures how much a reader allocates ([`alloc`]).
//!
//! It lives in the data layer (not behind a dev-dependency crate) because every crate
//! already depends on `scene`; it has no dependencies and costs nothing when unused.

pub mod alloc;
pub mod mutate;

pub use alloc::TrackingAlloc;
pub use mutate::{Failure, Mutation, Plan, Problem, Report, fuzz, fuzz_reader};
