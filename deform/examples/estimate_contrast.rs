//! The contrast threshold of a scene directory estimated from its train frames and
//! events, as `deform train` does (`deform::contrast`), with the estimate's settings
//! given as `key=value` arguments:
//!
//! `cargo run --release -p degs-deform --example estimate_contrast -- SCENE_DIR
//! [black_level=0.02] [min_log_change=0.2] [saturation=0.99] [log_eps=0]`

use deform::contrast::{EstimateSettings, estimate_contrast};
use deform::event_image::srgb_to_linear;
use gaussians::stage::load_views;
use scene::manifest::Scene;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = args
        .next()
        .ok_or("usage: estimate_contrast SCENE_DIR [key=value …]")?;
    let (mut s, mut log_eps) = (EstimateSettings::default(), 0.0);
    for a in args {
        let (k, v) = a
            .split_once('=')
            .ok_or(format!("{a}: expected key=value"))?;
        let v: f64 = v.parse().map_err(|e| format!("{a}: {e}"))?;
        match k {
            "black_level" => s.black_level = v,
            "min_log_change" => s.min_log_change = v,
            "saturation" => s.saturation = v,
            "log_eps" => log_eps = v,
            _ => return Err(format!("unknown setting {k}").into()),
        }
    }
    let scene = Scene::open(std::path::Path::new(&dir))?;
    let views = load_views(&scene, &scene.train)?;
    let srgb = scene.train.frames_srgb();
    let linear: Vec<Vec<f32>> = views
        .iter()
        .map(|v| {
            v.rgb
                .iter()
                .map(|&c| if srgb { srgb_to_linear(c) } else { c })
                .collect()
        })
        .collect();
    let times: Vec<f64> = scene.train.frames.iter().map(|f| f.timestamp).collect();
    let events = scene.load_events()?;
    let e = estimate_contrast(&linear, 3, &times, &events.as_slice(), log_eps, &s)?;
    println!(
        "manifest C {:.4}; estimate C {:.4}, bootstrap std {:?}, 95 % {:?}, C+ {:?}, C- {:?}, \
         {} pixel-intervals, {} inliers, median |residual| {:.2} events",
        scene.contrast_threshold(),
        e.c,
        e.std,
        e.ci95,
        e.c_pos,
        e.c_neg,
        e.pixels,
        e.inliers,
        e.residual_mad
    );
    Ok(())
}
