//! `gaussians`: a dynamic 3D Gaussian model (canonical [`Splats`] + deformation
//! [`field`] + per-Gaussian trajectories, [`motion`]), its differentiable CPU
//! [`raster`]izer and the RGB warm-up that trains it ([`train`], run as a stage by
//! [`stage`]).
//!
//! The core types other crates build on are re-exported here: [`Splats`] /
//! [`Gaussian`] (the parameters), [`SplatGrads`] (their gradients), the [`Rasterizer`]
//! trait, the [`RenderedImage`] it returns and the CPU [`TileRasterizer`].

pub mod densify;
pub mod evaluation;
pub mod export;
pub mod field;
pub mod model;
pub mod motion;
pub mod parts;
pub use stagekit::optim;
pub mod ply;
pub mod preview;
pub mod progress;
pub mod raster;
pub mod splats;
pub mod stage;
pub mod tracks;
pub mod train;
pub mod trajectory;
pub mod video;

pub use raster::{Planes, Rasterizer, RenderedImage, TileRasterizer};
pub use splats::{Gaussian, SplatGrads, Splats};
