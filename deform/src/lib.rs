//! `deform` — the joint training stage of degs (DEGS §3.4–3.5, DESIGN §5).
pub mod camera_path;
pub mod event_counts;
pub mod event_image;
pub mod flow;
pub mod lie;
pub mod motion_loss;
pub mod posenet;
pub mod real;
pub mod schedule;

#[cfg(test)]
mod tests;
