//! `synth` — everything synthetic in degs, in one place (docs/DESIGN.md §2–§3):
//!
//! - the analytic world ([`world`]): textured planes, boxes and ellipsoids moving
//!   rigidly or not, rendered by ray casting with exact depth, optical flow and object
//!   ids; its settings ([`config`], [`SynthConfig`], read and written as [`keys`]
//!   describes) and the named [`presets`];
//! - the event simulator ([`sim`], ESIM style), on its own (any luminance frames, no
//!   neural network) and over a directory of frames ([`frames`], `evflow simulate`);
//! - the writers of synthetic scene directories: the full one with events and ground
//!   truth ([`scene_dir`], `degs synth`) and the RGB-only one ([`rgb`],
//!   `gaussians synth-rgb`); the ground-truth file formats ([`gt`]) they write and the
//!   evaluation tools read.
//!
//! - the stress transforms of `degs stress` ([`transform`]): a scene directory made
//!   worse after the fact (fewer frames, noise, hot pixels, a wrong contrast threshold,
//!   a gap, a burst, a corrupt file).
//!
//! The `synth` binary runs the scene writer and the transform as the runner's stages.
//!
//! It builds on `scene` (camera, manifest, event streams, images, atomic files) and
//! on nothing else of degs.

pub mod config;
pub mod covis;
pub mod frames;
mod geometry;
pub mod gt;
pub mod keys;
pub mod presets;
pub mod rgb;
pub mod scene_dir;
pub mod sim;
pub mod texture;
pub mod transform;
pub mod world;

pub use config::{
    CameraPath, Deform, Light, Motion, ObjectSpec, Pattern, Shape, SynthConfig, Texture,
};
pub use presets::PRESETS;
pub use rgb::write_rgb_synthetic_scene;
pub use scene_dir::{
    SYNTH_COMMAND, Summary, simulate_scene, write_synthetic_scene, write_synthetic_scene_with,
};
pub use sim::{SimConfig, Simulator, luminance};
pub use world::{Hit, Render, SynthWorld};
