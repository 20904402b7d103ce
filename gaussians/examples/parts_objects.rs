//! What each rigid part of a model holds (issue #30, `tracks.parts`): a diagnostic for a
//! model trained on a synthetic scene (`degs synth`: `gt/train/depth_*.exr` and
//! `object_*.png`).
//!
//! ```text
//! cargo run --release -p degs-gaussians --example parts_objects -- SCENE MODEL_DIR
//! ```
//!
//! Per part and train frame: how many of its opaque members project onto each object
//! id (`k + 1` for `synth.json`'s `objects[k]`; a member behind the visible surface by
//! more than 30 % counts as `hidden`), and the median signed relative depth error of
//! those on the part's main object. Then the same for the moving Gaussians in no part.

mod common;

use common::fail;
use std::collections::BTreeMap;

fn main() {
    let (_, root, sc, model) = common::open("parts_objects SCENE MODEL_DIR");
    let (w, h) = (
        sc.train.camera.width as usize,
        sc.train.camera.height as usize,
    );
    let s = &model.splats;
    let n = s.len();
    let moving = |i: usize| {
        s.motion
            .get(i)
            .is_some_and(gaussians::motion::has_trajectory)
    };
    let group = |i: usize| -> Option<u32> {
        match s.part.get(i) {
            Some(&p) if p != gaussians::parts::NO_PART => Some(p),
            _ => moving(i).then_some(u32::MAX),
        }
    };
    println!("{n} Gaussians, {} parts", s.parts.len());
    for (k, f) in sc.train.frames.iter().enumerate() {
        let dp = root.join(format!("gt/train/depth_{k:04}.exr"));
        let op = root.join(format!("gt/train/object_{k:04}.png"));
        let (_, _, depth) =
            scene::image_io::read_exr_depth(&dp).unwrap_or_else(|e| fail(format!("{e}")));
        let (_, _, object) =
            synth::gt::read_object_png(&op).unwrap_or_else(|e| fail(format!("{e}")));
        let cam = sc.camera(f);
        let at = model.at(f.time as f32);
        // group → (object → count), (object → depth errors)
        let mut counts: BTreeMap<u32, BTreeMap<String, usize>> = BTreeMap::new();
        let mut errors: BTreeMap<(u32, u16), Vec<f64>> = BTreeMap::new();
        for i in 0..n {
            let Some(g) = group(i) else { continue };
            if at.opacity_logits[i] < 0.0 {
                continue;
            }
            let x = glam::Vec3::from(at.means[i]).as_dvec3();
            let Some((px, z)) = cam.project_world(x) else {
                continue;
            };
            let (u, v) = (px.x.round(), px.y.round());
            if u < 0.0 || v < 0.0 || u >= w as f64 || v >= h as f64 {
                *counts
                    .entry(g)
                    .or_default()
                    .entry("outside".into())
                    .or_default() += 1;
                continue;
            }
            let p = v as usize * w + u as usize;
            let e = z / depth[p] as f64 - 1.0;
            let key = if e > 0.3 {
                "hidden".to_string()
            } else {
                format!("{}", object[p])
            };
            *counts.entry(g).or_default().entry(key).or_default() += 1;
            if e <= 0.3 {
                errors.entry((g, object[p])).or_default().push(e);
            }
        }
        println!("frame {k} (t = {:.3})", f.time);
        for (g, c) in &counts {
            let name = if *g == u32::MAX {
                "no part".to_string()
            } else {
                format!("part {g}")
            };
            let main = c
                .iter()
                .filter_map(|(o, n)| o.parse::<u16>().ok().map(|o| (o, *n)))
                .max_by_key(|(_, n)| *n)
                .map(|(o, _)| o);
            let med = main.and_then(|o| errors.get(&(*g, o))).map(|e| {
                let mut e = e.clone();
                e.sort_by(f64::total_cmp);
                100.0 * e[e.len() / 2]
            });
            println!(
                "  {name:8}: {c:?}; depth on object {:?}: {:+.1} %",
                main.unwrap_or(0),
                med.unwrap_or(f64::NAN)
            );
        }
    }
}
