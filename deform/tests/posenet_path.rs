//! The PoseNet corrects a camera path that the train poses cannot tell: the camera
//! bumps off the straight line between every two train frames (zero at the frames,
//! [`fixture::BUMP`] halfway), the events come from the true path, and the scene is
//! right (the warm-up model is the one the frames were rendered from). After the joint
//! training, in which `L_event` moves only the camera (a PoseNet warm-up longer than
//! the run, no motion loss), the corrected camera at the held-out time draws the scene
//! closer to where the true camera sees it than the interpolated one: under half its
//! image error, for each of four training seeds.
//!
//! The image error, not the centre distance, is what the events determine here: the
//! scene is one plane, on which a small turn and a sideways step move the image alike,
//! so the PoseNet may take up the bump partly as a turn (measured, learning rate 0.01
//! decaying to 0.001: image error 2.37 → 0.38–0.59 px over seeds 0–3, centre distance
//! 0.30 → 0.21 with 3.8–4.3° of turn; with the rasterizer's sums in lane order instead
//! of a shuffle tree, 0.82–0.93 px). At a constant rate the last iterate was a random
//! draw around that optimum (0.51–2.16 px over the same seeds, lane order; one seed's
//! outcome changed with the rounding of the sums): the decay is what this test guards.

mod fixture;

use deform::stage::TrainArgs;
use fixture::{BUMP, Variant, build};

#[test]
fn the_posenet_moves_the_camera_toward_the_true_path() {
    let fx = build(Variant::BumpedPath);
    for seed in 0..4 {
        let settings = format!(
            "iterations = 4000\nlog_every = 100\nrebind_every = 1000\nseed = {seed}\n\
             posenet_warmup = 100000\ndensify = false\nposenet_lr = 0.01\n\
             posenet_lr_final = 0.001\ncontrast = \"given\"\n[schedule]\ngamma2_max = 0.0\n"
        );
        let (o, _) = fx
            .train_with(&format!("out{seed}"), &settings, TrainArgs::default())
            .unwrap();
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(o.out.join("report.json")).unwrap())
                .unwrap();
        let cam = &r["camera"];
        let f = |which: &str, key: &str| cam[which][key].as_f64().unwrap();
        let (interpolated, corrected) = (
            f("interpolated", "image_px_mean"),
            f("corrected", "image_px_mean"),
        );
        eprintln!(
            "seed {seed}: image error interpolated {interpolated:.3} px, corrected \
             {corrected:.3} px (centre {:.3}, turn {:.2}°)",
            f("corrected", "position_mean"),
            f("corrected", "rotation_deg_mean")
        );
        // The straight line misses the bump's top by exactly its height, 2.4 px on the
        // plane (24 px per unit at its depth).
        assert!((f("interpolated", "position_mean") - BUMP).abs() < 1e-9);
        assert!((interpolated - 2.4).abs() < 0.05, "{interpolated}");
        assert!(
            corrected < 0.5 * interpolated,
            "seed {seed}: the PoseNet did not move the camera toward the true path: \
             {corrected} px vs {interpolated} px"
        );
    }
}
