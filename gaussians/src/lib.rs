//! gaussians
pub mod densify;
pub mod field;
pub mod metrics;
pub mod model;
pub use scene::optim;
pub mod ply;
pub mod progress;
pub mod raster;
pub mod stage;
pub mod train;
