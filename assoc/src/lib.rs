//! `assoc` — ties 2D events to the 3D Gaussians that caused them (DEGS §3.3, DESIGN §5
//! "Association"): events near a frame time t0 are lifted to 3D through the depth
//! rendered at t0, a k-d tree (kiddo) is built over the lifted points, and every
//! Gaussian (deformed to t0) binds to its k nearest points within a radius, weighted by
//! normalised inverse distance. The result is a compact CSR table ([`Bindings`]); many
//! frames are stored together in an `assoc.bin` file ([`file`]).

pub mod bind;
pub mod file;
pub mod frame;
pub mod settings;
pub mod stage;
pub mod unproject;

pub use bind::{Bindings, bind_nearest, footprint_radii};
pub use file::{FrameBindings, read_assoc, read_assoc_for, write_assoc};
pub use frame::{FrameError, FrameStats, associate_alive, associate_frame};
pub use settings::AssocSettings;
pub use unproject::{LiftedEvents, lift_events};
