//! The named presets of [`SynthConfig`] (and its `Default`, the `rigid` preset): one
//! room, four props, four kinds of motion.

use crate::config::{CameraPath, Deform, Motion, ObjectSpec, Pattern, Shape, SynthConfig, Texture};
use crate::sim::SimConfig;
use glam::DVec3;

/// Names accepted by [`SynthConfig::preset`].
pub const PRESETS: &[&str] = &["static", "rigid", "nonrigid", "fast", "moderate"];

impl Default for SynthConfig {
    fn default() -> Self {
        Self::preset("rigid").expect("the rigid preset exists")
    }
}

fn rgb(r: f64, g: f64, b: f64) -> [f64; 3] {
    [r, g, b]
}

/// The room every preset shares: a checkered floor and a blob-textured back wall.
fn room() -> Vec<ObjectSpec> {
    vec![
        ObjectSpec {
            name: "floor".into(),
            shape: Shape::Plane {
                half_size: [6.0, 6.0],
            },
            texture: Texture {
                pattern: Pattern::Checker,
                cell: 0.3,
                colour_a: rgb(0.85, 0.82, 0.75),
                colour_b: rgb(0.12, 0.16, 0.25),
                detail: 0.15,
                seed: 11,
            },
            motion: Motion {
                position: DVec3::new(0.0, -0.6, 0.0),
                rotation_deg: DVec3::new(-90.0, 0.0, 0.0),
                ..Motion::default()
            },
            deform: Deform::default(),
        },
        ObjectSpec {
            name: "wall".into(),
            shape: Shape::Plane {
                half_size: [0.0, 0.0],
            },
            texture: Texture {
                pattern: Pattern::Blobs,
                cell: 0.35,
                colour_a: rgb(0.9, 0.55, 0.25),
                colour_b: rgb(0.08, 0.12, 0.3),
                detail: 0.25,
                seed: 12,
            },
            motion: Motion {
                position: DVec3::new(0.0, 0.0, -3.0),
                ..Motion::default()
            },
            deform: Deform::default(),
        },
    ]
}

/// The foreground objects (box, ball, blob, flag); `moving` scales their motion (0 = still).
fn props(moving: f64, nonrigid: bool) -> Vec<ObjectSpec> {
    vec![
        ObjectSpec {
            name: "box".into(),
            shape: Shape::Cuboid {
                half_size: DVec3::new(0.3, 0.3, 0.3),
            },
            texture: Texture {
                pattern: Pattern::Stripes,
                cell: 0.1,
                colour_a: rgb(0.95, 0.9, 0.2),
                colour_b: rgb(0.05, 0.3, 0.1),
                detail: 0.1,
                seed: 21,
            },
            motion: Motion {
                position: DVec3::new(-0.75, -0.25, 0.2),
                rotation_deg: DVec3::new(10.0, 30.0, 0.0),
                oscillation: DVec3::new(0.3, 0.1, 0.0) * moving,
                oscillation_hz: 0.5,
                spin_axis: DVec3::new(0.3, 1.0, 0.2),
                spin_deg_per_s: 60.0 * moving,
                ..Motion::default()
            },
            deform: Deform::default(),
        },
        ObjectSpec {
            name: "ball".into(),
            shape: Shape::Ellipsoid {
                radii: DVec3::splat(0.35),
            },
            texture: Texture {
                pattern: Pattern::Checker,
                cell: 0.12,
                colour_a: rgb(0.9, 0.2, 0.15),
                colour_b: rgb(0.95, 0.95, 0.9),
                detail: 0.1,
                seed: 31,
            },
            motion: Motion {
                position: DVec3::new(0.75, -0.1, -0.2),
                velocity: DVec3::new(-0.25, 0.0, 0.3) * moving,
                spin_axis: DVec3::new(0.0, 1.0, 0.3),
                spin_deg_per_s: 90.0 * moving,
                ..Motion::default()
            },
            deform: Deform::default(),
        },
        ObjectSpec {
            name: "blob".into(),
            shape: Shape::Ellipsoid {
                radii: DVec3::new(0.3, 0.25, 0.3),
            },
            texture: Texture {
                pattern: Pattern::Blobs,
                cell: 0.12,
                colour_a: rgb(0.2, 0.6, 0.95),
                colour_b: rgb(0.05, 0.05, 0.1),
                detail: 0.1,
                seed: 41,
            },
            motion: Motion {
                position: DVec3::new(0.0, 0.15, -1.0),
                oscillation: DVec3::new(0.0, 0.15, 0.0) * moving,
                oscillation_hz: 0.8,
                spin_axis: DVec3::new(1.0, 0.2, 0.0),
                spin_deg_per_s: 40.0 * moving,
                ..Motion::default()
            },
            deform: Deform {
                scale_amplitude: if nonrigid {
                    DVec3::new(0.3, 0.25, 0.3)
                } else {
                    DVec3::ZERO
                },
                hz: 1.2,
                ..Deform::default()
            },
        },
        ObjectSpec {
            name: "flag".into(),
            shape: Shape::Plane {
                half_size: [0.5, 0.3],
            },
            texture: Texture {
                pattern: Pattern::Stripes,
                cell: 0.08,
                colour_a: rgb(0.95, 0.95, 0.95),
                colour_b: rgb(0.6, 0.05, 0.3),
                detail: 0.1,
                seed: 51,
            },
            motion: Motion {
                position: DVec3::new(0.35, 0.75, -1.8),
                rotation_deg: DVec3::new(0.0, -15.0, 0.0),
                ..Motion::default()
            },
            deform: Deform {
                wave_amplitude: if nonrigid { 0.08 } else { 0.0 },
                wave_length: 0.5,
                wave_hz: 1.0,
                ..Deform::default()
            },
        },
    ]
}

impl SynthConfig {
    /// A named preset (see [`PRESETS`]): `static` (still objects, moving camera),
    /// `rigid` (rigidly moving objects), `nonrigid` (adds a non-uniformly pulsing
    /// ellipsoid and a waving flag), `fast` (nonrigid with 3× faster motion), `moderate`
    /// (nonrigid as a recording looks: lit by a directional light so that turning
    /// surfaces change brightness, RGB frames at 20 fps, events from a sensor with
    /// per-pixel threshold spread σ = 0.02, 0.5 Hz shot noise and a 0.1 ms refractory
    /// period). `None` for other names. Every preset has the same objects (floor, wall, box, ball, blob,
    /// flag: ids 1–6); only their motion differs.
    pub fn preset(name: &str) -> Option<SynthConfig> {
        let (moving, nonrigid, speed) = match name {
            "static" => (0.0, false, 1.0),
            "rigid" => (1.0, false, 1.0),
            "nonrigid" => (1.0, true, 1.0),
            "fast" => (1.0, true, 3.0),
            "moderate" => (1.0, true, 1.0),
            _ => return None,
        };
        let mut objects = room();
        objects.extend(props(moving, nonrigid));
        let mut camera = CameraPath::default();
        if speed != 1.0 {
            camera.sway_hz *= speed;
            camera.turn_hz *= speed;
            for o in &mut objects {
                let m = &mut o.motion;
                m.velocity *= speed;
                m.oscillation_hz *= speed;
                m.spin_deg_per_s *= speed;
                o.deform.hz *= speed;
                o.deform.wave_hz *= speed;
            }
        }
        let mut cfg = SynthConfig {
            preset: name.to_string(),
            width: 128,
            height: 128,
            fov_x_deg: 60.0,
            duration: 1.0,
            train_fps: 8.0,
            test_frames: 8,
            novel_angle_deg: 15.0,
            render_rate_hz: 1000.0,
            blur_subframes: 1,
            exposure_s: 0.01,
            supersample: 2,
            frame_supersample: 8,
            seed: 0,
            background: [0.2, 0.2, 0.2],
            // An ideal sensor: C± = 0.1 everywhere, no refractory period, no noise.
            events: SimConfig {
                threshold_pos: 0.1,
                threshold_neg: 0.1,
                threshold_sigma: 0.0,
                refractory_s: 0.0,
                shot_noise_hz: 0.0,
                hot_pixel_fraction: 0.0,
                hot_pixel_hz: 0.0,
                ..SimConfig::default()
            },
            camera,
            objects,
            light: None,
        };
        if name == "moderate" {
            cfg.light = Some(crate::config::Light::default());
            cfg.train_fps = 20.0;
            cfg.events.threshold_sigma = 0.02;
            cfg.events.shot_noise_hz = 0.5;
            cfg.events.refractory_s = 1e-4;
        }
        Some(cfg)
    }
}
