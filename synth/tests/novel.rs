//! The novel-view camera of synthetic scenes: displaced from the recorded path by the
//! chord of its angle, aimed at the path's target, and with ground-truth flow that
//! matches its own motion.

use glam::{DVec2, DVec3};
use synth::{SynthConfig, SynthWorld};

fn config(preset: &str) -> SynthConfig {
    SynthConfig {
        width: 48,
        height: 40,
        frame_supersample: 1,
        ..SynthConfig::preset(preset).unwrap()
    }
}

#[test]
fn the_novel_camera_is_the_recorded_one_rotated_about_the_target_and_looks_at_it() {
    for angle in [15.0f64, -30.0, 90.0] {
        let cfg = SynthConfig {
            novel_angle_deg: angle,
            ..config("rigid")
        };
        let w = SynthWorld::new(&cfg).unwrap();
        let target = cfg.camera.target;
        let k = w.intrinsics();
        for &t in &cfg.test_times() {
            let rec = w.camera_at(t).cam_to_world.translation;
            let nov = w.novel_camera_at(t);
            let c = nov.cam_to_world.translation;
            // rotation about the vertical axis through the target: same height, same
            // distance from the axis, chord 2·r·sin(θ/2) between the centres
            let r = DVec2::new(rec.x - target.x, rec.z - target.z).length();
            let r_nov = DVec2::new(c.x - target.x, c.z - target.z).length();
            let chord = 2.0 * r * (angle.to_radians() / 2.0).sin().abs();
            assert!((c.y - rec.y).abs() < 1e-12, "{angle}° t={t}");
            assert!((r_nov - r).abs() < 1e-12, "{angle}° t={t}");
            assert!(
                ((c - rec).length() - chord).abs() < 1e-12,
                "{angle}° t={t}: moved {} not {chord}",
                (c - rec).length()
            );
            assert!(chord > 0.8, "{angle}° t={t}: chord {chord}");
            // counter-clockwise seen from +Y for a positive angle
            let turn = DVec2::new(rec.x - target.x, rec.z - target.z)
                .perp_dot(DVec2::new(c.x - target.x, c.z - target.z));
            assert_eq!(turn.signum(), -angle.signum(), "{angle}° t={t}");
            // the target projects to the principal point, in front of the camera
            let (px, depth) = nov.project_world(target).unwrap();
            let centre = DVec2::new(k.cx, k.cy);
            assert!((px - centre).length() < 1e-9, "{angle}° t={t}: {px}");
            assert!((depth - (target - c).length()).abs() < 1e-9);
            // upright: the camera's x axis stays horizontal
            let right = nov.cam_to_world.rotation * DVec3::X;
            assert!(right.y.abs() < 1e-12, "{angle}° t={t}: {right}");
        }
    }
}

#[test]
fn no_train_camera_sees_the_scene_from_a_novel_centre() {
    // 15° (the default) puts every novel centre over half a scene unit from every
    // centre the recorded camera passes through (measured 0.566 on the rigid preset).
    let cfg = config("rigid");
    assert_eq!(cfg.novel_angle_deg, 15.0);
    let w = SynthWorld::new(&cfg).unwrap();
    let path: Vec<DVec3> = cfg
        .render_times()
        .iter()
        .map(|&s| w.camera_at(s).cam_to_world.translation)
        .collect();
    let nearest = cfg
        .novel_times()
        .iter()
        .map(|&t| {
            let c = w.novel_camera_at(t).cam_to_world.translation;
            path.iter()
                .map(|p| (*p - c).length())
                .fold(f64::MAX, f64::min)
        })
        .fold(f64::MAX, f64::min);
    eprintln!("nearest recorded centre to a novel one: {nearest:.4}");
    assert!(nearest > 0.5, "{nearest}");
    let off = SynthConfig {
        novel_angle_deg: 0.0,
        ..cfg.clone()
    };
    assert!(off.novel_times().is_empty());
    assert_eq!(cfg.novel_times(), cfg.test_times());
}

#[test]
fn novel_flow_is_the_motion_of_static_points_seen_by_the_moving_novel_camera() {
    // Every object of the static preset is still: the flow a novel frame records is
    // the projection of the point at the pixel's depth moving under the novel camera's
    // own motion (the rotated path, look-at rotation), checked by central differences.
    let cfg = config("static");
    let w = SynthWorld::new(&cfg).unwrap();
    let dt = 1e-5;
    let mut checked = 0;
    for &t in &[0.2, 0.55, 0.9] {
        let r = w.render_novel_frame(t);
        let cam = w.novel_camera_at(t);
        for y in (1..40).step_by(5) {
            for x in (1..48).step_by(5) {
                let i = y * 48 + x;
                let px = DVec2::new(x as f64, y as f64);
                let depth = r.depth[i] as f64;
                assert!(depth > 0.0, "t={t} {px}: nothing hit");
                let p = cam.unproject_world(px, depth);
                let at = |s: f64| w.novel_camera_at(s).project_world(p).unwrap().0;
                let fd = (at(t + dt) - at(t - dt)) / (2.0 * dt);
                let an = DVec2::new(r.flow_u[i] as f64, r.flow_v[i] as f64);
                // the render stores f32 flow and depth
                assert!(
                    (fd - an).length() < 1e-4 * fd.length().max(1.0),
                    "t={t} {px}: analytic {an} vs fd {fd}"
                );
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 3 * 8 * 10);
}

#[test]
fn the_novel_angle_is_validated() {
    use stagekit::Settings;
    for bad in [91.0, -120.0, f64::NAN] {
        let cfg = SynthConfig {
            novel_angle_deg: bad,
            ..SynthConfig::default()
        };
        let e = cfg.validate().unwrap_err();
        assert!(e.contains("novel_angle_deg"), "{e}");
    }
}

/// Co-visibility: from a novel camera (almost) on the recorded path, at a train view's
/// time, nearly every pixel was seen (it aims at the path's target, not as the train
/// camera sways, so a sliver at one edge falls outside every train view); from 45° off
/// the path much less, and still more than the background.
#[test]
fn covisibility_is_full_at_a_train_camera_and_partial_off_the_path() {
    let cfg = |angle: f64| synth::SynthConfig {
        width: 32,
        height: 24,
        novel_angle_deg: angle,
        ..synth::SynthConfig::preset("rigid").unwrap()
    };
    let fraction = |angle: f64, t: f64| {
        let c = cfg(angle);
        let world = synth::SynthWorld::new(&c).unwrap();
        let seen = synth::covis::novel_covisible(&world, t, &c.train_times());
        seen.iter().filter(|&&s| s).count() as f64 / seen.len() as f64
    };
    let t0 = cfg(1e-4).train_times()[2];
    let near = fraction(1e-4, t0);
    let far = fraction(45.0, t0);
    eprintln!("co-visible: on the path {near:.3}, 45° off it {far:.3}");
    assert!(near > 0.9, "on the path: {near}");
    assert!(
        far < near - 0.05 && far > 0.2,
        "45° off the path: {far} (on it {near})"
    );
}
