//! Helpers of the training-loop tests: a small camera arc and settings that train the
//! Gaussians as given.

use gaussians::train::TrainSettings;
use glam::DVec3;
use scene::{Camera, Intrinsics, Pose};

pub const W: usize = 24;
pub const H: usize = 24;

/// `n` cameras on an arc of 1.2 rad at distance 3, looking at the origin.
pub fn cameras(n: usize) -> Vec<Camera> {
    let intr = Intrinsics::from_fov_x(W as u32, H as u32, 0.9);
    (0..n)
        .map(|k| {
            let a = k as f64 / n as f64 * 1.2 - 0.6;
            let eye = DVec3::new(3.0 * a.sin(), 0.4, 3.0 * a.cos());
            Camera {
                intrinsics: intr,
                cam_to_world: Pose::look_at(eye, DVec3::ZERO, DVec3::Y),
            }
        })
        .collect()
}

/// `iterations` steps on the Gaussians as given: no field, no densification, no sizing.
pub fn fixed_gaussians(iterations: u32) -> TrainSettings {
    let mut s = TrainSettings {
        iterations,
        deform: false,
        size: gaussians::train::sizing::SizeSettings {
            tolerance_db: 0.0,
            ..Default::default()
        },
        ..Default::default()
    };
    s.densify.until_iter = 0;
    s
}
