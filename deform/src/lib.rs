//! `deform` — the joint training stage of degs (DEGS §3.4–3.5, DESIGN §5).
pub mod camera_path;
pub mod flow;
pub mod lie;
pub mod posenet;
pub mod real;

#[cfg(test)]
mod tests;
