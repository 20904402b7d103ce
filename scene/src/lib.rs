//! `scene` — the shared data layer of degs (docs/DESIGN.md §2–§3): camera model, scene
//! manifest, event streams and their readers/writers, image and EXR helpers, image
//! metrics (PSNR, SSIM) and the losses built on them, atomic outputs, errors, the
//! evaluation figures' file format and the scene checks. Synthetic scenes live in the
//! `synth` crate, the plumbing every binary shares in `stagekit`.

pub mod atomic;
pub mod camera;
pub mod check;
pub mod depth_prior;
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
pub mod real;
pub use formats::{ReadOptions, read_events, write_evs};
pub use image_io::Image;
pub use manifest::{EventsRef, Frame, Manifest, Scene};
