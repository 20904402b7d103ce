//! How far a warm-up's aligned depth priors (`depth_prior.safetensors`) lie from a
//! synthetic scene's true depth (`gt/train/depth_NNNN.exr`), on the moving objects'
//! pixels and on the still ones (`gt/train/object_NNNN.png`: object `k + 1` is
//! `synth.json`'s `objects[k]`), each split by the distance to the nearest pixel of
//! another object (the outline, where a network's depth blends with what is behind).
//!
//! ```text
//! cargo run --release -p degs-gaussians --example prior_error -- SCENE WARMUP_DIR
//! ```
//!
//! The moving objects are those `synth.json` says move. Prints the median relative error
//! (%) per frame and over all frames, and the signed median error 2 px or more inside
//! each moving object per frame (what one scale per object and frame would remove).

mod common;

use common::median;
use std::path::Path;

fn main() -> scene::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        eprintln!("usage: prior_error SCENE WARMUP_DIR");
        std::process::exit(2);
    }
    let root = Path::new(&args[0]);
    let text = std::fs::read_to_string(root.join("synth.json")).expect("synth.json");
    let cfg: synth::SynthConfig = serde_json::from_str(&text).expect("synth settings");
    let moving_ids: Vec<u16> = (cfg.objects.iter().enumerate())
        .filter(|(_, o)| o.moves())
        .map(|(k, _)| k as u16 + 1)
        .collect();
    let sc = scene::Scene::open(root)?;
    let k = &sc.train.camera;
    let (w, h) = (k.width as usize, k.height as usize);
    let n = sc.train.frames.len();
    let path = Path::new(&args[1]).join(gaussians::tracks::file::PRIORS_FILE);
    let maps = gaussians::tracks::file::read_priors(&path, n, w, h)?;
    // (moving, band) → relative errors; bands: 0 on the outline (1 px), 1 within 3 px,
    // 2 farther.
    let mut all = vec![Vec::new(); 6];
    // Per moving object and frame: the signed relative errors 2 px or more inside it.
    let mut signed = vec![vec![Vec::new(); n]; moving_ids.len()];
    println!("frame  moving_in  moving_edge  still_in  (median |z_prior − z| / z, %)");
    for (f, map) in maps.iter().enumerate() {
        let Some(map) = map else {
            println!("{f:5}  no map");
            continue;
        };
        let (_, _, z) =
            scene::image_io::read_exr_depth(root.join(format!("gt/train/depth_{f:04}.exr")))?;
        let (_, _, ids) =
            synth::gt::read_object_png(root.join(format!("gt/train/object_{f:04}.png")))
                .expect("object image");
        let id = |x: usize, y: usize| ids[y * w + x];
        let mut frame = vec![Vec::new(); 6];
        for y in 0..h {
            for x in 0..w {
                let (t, p) = (z[y * w + x] as f64, map.z[y * w + x] as f64);
                if !(t > 0.0 && p > 0.0) {
                    continue;
                }
                let me = id(x, y);
                let mut edge = 4;
                for r in 1..=3usize {
                    let other = (y.saturating_sub(r)..(y + r + 1).min(h))
                        .flat_map(|yy| {
                            (x.saturating_sub(r)..(x + r + 1).min(w)).map(move |xx| (xx, yy))
                        })
                        .any(|(xx, yy)| id(xx, yy) != me);
                    if other {
                        edge = r;
                        break;
                    }
                }
                let band = if edge == 1 {
                    0
                } else if edge <= 3 {
                    1
                } else {
                    2
                };
                let moving = moving_ids.contains(&me);
                let slot = if moving { band } else { 3 + band };
                frame[slot].push((p - t).abs() / t);
                if let Some(o) = moving_ids
                    .iter()
                    .position(|&m| m == me)
                    .filter(|_| band > 0)
                {
                    signed[o][f].push(p / t - 1.0);
                }
            }
        }
        println!(
            "{f:5}  {:9.2}  {:11.2}  {:8.2}   (pixels {} {} {})",
            100.0 * median(frame[2].clone()),
            100.0 * median(frame[0].iter().chain(&frame[1]).copied().collect()),
            100.0 * median(frame[5].clone()),
            frame[2].len(),
            frame[0].len() + frame[1].len(),
            frame[5].len()
        );
        for (a, b) in all.iter_mut().zip(frame) {
            a.extend(b);
        }
    }
    println!("signed median error 2 px or more inside each moving object, per frame, %:");
    for (o, frames) in signed.iter().enumerate() {
        let name = &cfg.objects[moving_ids[o] as usize - 1].name;
        let row: Vec<String> = (frames.iter())
            .map(|v| match v.len() {
                0..10 => "    -".to_string(),
                _ => format!("{:+5.1}", 100.0 * median(v.clone())),
            })
            .collect();
        println!("  {name:8} {}", row.join(" "));
    }
    let names = [
        "moving, outline",
        "moving, 2-3 px in",
        "moving, inside",
        "still, outline",
        "still, 2-3 px in",
        "still, inside",
    ];
    for (name, v) in names.iter().zip(&all) {
        println!(
            "{name:18} median {:6.2} %  p90 {:6.2} %  ({} pixels)",
            100.0 * median(v.clone()),
            100.0 * {
                let mut s = v.clone();
                s.sort_by(f64::total_cmp);
                s.get(s.len() * 9 / 10).copied().unwrap_or(f64::NAN)
            },
            v.len()
        );
    }
    Ok(())
}
