//! `scene` — the shared data layer of degs (docs/DESIGN.md §2–§3): camera model, scene
//! manifest, event streams and their readers/writers, image and EXR helpers, image
//! metrics (PSNR, SSIM) and the losses built on them, atomic outputs, Adam, and the
//! plumbing every binary shares (settings files, progress, errors). Synthetic scenes
//! live in the `synth` crate.

pub mod atomic;
pub mod camera;
pub mod check;
pub mod cli;
pub mod error;
pub mod evaluation;
pub mod events;

pub use camera::{Camera, Distortion, Intrinsics, Pose, Trajectory};
pub use error::{Error, IoContext, Result};
pub use events::{EventSlice, EventStream};
pub mod formats;
pub mod image_io;
pub mod manifest;
pub mod metrics;
pub mod optim;
pub mod real;
pub mod report;
pub mod testdata;
pub mod testing;
pub use formats::{ReadOptions, read_events, write_evs};
pub use image_io::Image;
pub use manifest::{EventsRef, Frame, Manifest, Scene};
