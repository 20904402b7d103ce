//! Which Gaussians carry a moving object's depth at the train frames, and whether they
//! keep their shape over time (issue #30): a diagnostic for a model trained on a
//! synthetic scene (`degs synth`: `gt/train/depth_*.exr` and `object_*.png`).
//!
//! ```text
//! cargo run --release -p degs-gaussians --example depth_carriers -- SCENE MODEL_DIR [OBJECT_ID]
//! ```
//!
//! `MODEL_DIR` holds `model.json` (a warm-up's cache folder, or `deform`'s); `OBJECT_ID`
//! is the object's value in the object images (`k + 1` for `synth.json`'s `objects[k]`;
//! default 3, the presets' first moving object). Prints, per train frame, the median
//! signed relative depth error over the object's pixels of the render by every Gaussian,
//! by those with a trajectory alone (with and without the field's deltas) and by those
//! without one; then the per-Gaussian depth error (quartiles) of the opaque Gaussians
//! whose centre projects onto the object and lies within 30 % of its true depth; and
//! first, for the object's opaque trajectory Gaussians at the middle frame that live
//! over the whole recording, how the distances to their 8 nearest change between the
//! first frame, the last and the middle (1 = rigid). And per train frame the depth spread
//! of the render (`raster::reference::depth_spread`: how far apart the depths blended into
//! a pixel lie, relative) on the object's pixels and on the still objects' (ids 1–2, the
//! presets' floor and wall: a layer in front or behind that averages to the right depth).

mod common;

use common::{fail, quartiles};
use gaussians::model::Model;
use gaussians::{Rasterizer, Splats, TileRasterizer};

struct Frame {
    depth: Vec<f32>,
    object: Vec<u16>,
    camera: scene::Camera,
    time: f32,
}

fn main() {
    let (args, root, sc, model) = common::open("depth_carriers SCENE MODEL_DIR [OBJECT_ID]");
    let id: u16 = args.get(2).map_or(3, |s| {
        s.parse()
            .unwrap_or_else(|_| fail(format!("OBJECT_ID {s}: not a number")))
    });
    let (w, h) = (
        sc.train.camera.width as usize,
        sc.train.camera.height as usize,
    );
    let frames: Vec<Frame> = (sc.train.frames.iter().enumerate())
        .map(|(k, f)| {
            let dp = root.join(format!("gt/train/depth_{k:04}.exr"));
            let op = root.join(format!("gt/train/object_{k:04}.png"));
            let (_, _, depth) = scene::image_io::read_exr_depth(&dp)
                .unwrap_or_else(|e| fail(format!("{}: {e}", dp.display())));
            let (_, _, object) = synth::gt::read_object_png(&op)
                .unwrap_or_else(|e| fail(format!("{}: {e}", op.display())));
            Frame {
                depth,
                object,
                camera: sc.camera(f),
                time: f.time as f32,
            }
        })
        .collect();
    let n = model.splats.len();
    let traj: Vec<bool> = (0..n)
        .map(|i| (model.splats.motion.get(i)).is_some_and(gaussians::motion::has_trajectory))
        .collect();
    let no_field = Model {
        splats: model.splats.clone(),
        field: None,
        info: gaussians::model::ModelInfo {
            has_field: false,
            ..model.info.clone()
        },
    };
    println!(
        "{n} Gaussians, {} with a trajectory; field: {}; object {id}",
        traj.iter().filter(|&&t| t).count(),
        model.field.is_some()
    );
    // The pixel an object Gaussian projects to, and its relative depth error there.
    let on_object = |f: &Frame, s: &Splats, i: usize| -> Option<f64> {
        let x = glam::Vec3::from(s.means[i]).as_dvec3();
        let (px, z) = f.camera.project_world(x)?;
        let (u, v) = (px.x.round(), px.y.round());
        if u < 0.0 || v < 0.0 || u >= w as f64 || v >= h as f64 {
            return None;
        }
        let p = v as usize * w + u as usize;
        let e = z / f.depth[p] as f64 - 1.0;
        (f.object[p] == id && f.depth[p] > 0.0 && e.abs() < 0.3).then_some(e)
    };
    let opaque = |s: &Splats, i: usize| s.opacity_logits[i] > 0.0;

    let mid = &frames[frames.len() / 2];
    let (first, last) = (&frames[0], &frames[frames.len() - 1]);
    let (sm, s0, s1) = (
        model.at(mid.time),
        model.at(first.time),
        model.at(last.time),
    );
    let ids: Vec<usize> = (0..n)
        .filter(|&i| traj[i] && opaque(&sm, i) && on_object(mid, &sm, i).is_some())
        .filter(|&i| {
            let life = model.splats.life.get(i).copied();
            [first.time, last.time]
                .iter()
                .all(|&t| life.is_none_or(|l| gaussians::motion::alive(l, t)))
        })
        .collect();
    let dist = |s: &Splats, a: usize, b: usize| {
        f64::from(glam::Vec3::from(s.means[a]).distance(glam::Vec3::from(s.means[b])))
    };
    let (mut first_last, mut first_mid) = (Vec::new(), Vec::new());
    for &a in &ids {
        let mut near: Vec<(f64, usize)> = (ids.iter().filter(|&&b| b != a))
            .map(|&b| (dist(&sm, a, b), b))
            .collect();
        near.sort_by(|x, y| x.0.total_cmp(&y.0));
        for &(dm, b) in near.iter().take(8) {
            first_last.push(dist(&s0, a, b) / dist(&s1, a, b));
            first_mid.push(dist(&s0, a, b) / dm);
        }
    }
    let [a, b, c] = quartiles(first_last);
    let [d, e, f] = quartiles(first_mid);
    println!(
        "{} opaque trajectory Gaussians on the object at the middle frame living throughout; their 8 nearest's \
         distances, first frame / last (quartiles): {a:.3} {b:.3} {c:.3}; first / middle: {d:.3} {e:.3} {f:.3}",
        ids.len()
    );

    println!(
        "frame: rendered depth error, median over the object's pixels (α ≥ 0.3) | per Gaussian, quartiles"
    );
    for (k, fr) in frames.iter().enumerate() {
        let all = model.at(fr.time);
        let bare = no_field.at(fr.time);
        let render = |s: &Splats, keep: &dyn Fn(usize) -> bool| -> String {
            let mut s = s.clone();
            for i in (0..n).filter(|&i| !keep(i)) {
                s.opacity_logits[i] = -40.0;
            }
            let r = TileRasterizer
                .render(&s, &fr.camera, model.info.sh_degree, model.info.background)
                .0;
            let errs: Vec<f64> = (0..w * h)
                .filter(|&p| fr.object[p] == id && fr.depth[p] > 0.0 && r.alpha[p] >= 0.3)
                .map(|p| f64::from(r.depth[p] / r.alpha[p]) / f64::from(fr.depth[p]) - 1.0)
                .collect();
            format!("{:+.1} %", 100.0 * quartiles(errs)[1])
        };
        let per_gaussian = |keep: &dyn Fn(usize) -> bool| -> String {
            let errs: Vec<f64> = (0..n)
                .filter(|&i| keep(i) && opaque(&all, i))
                .filter_map(|i| on_object(fr, &all, i))
                .collect();
            let count = errs.len();
            let q = quartiles(errs).map(|v| 100.0 * v);
            format!("{count} at {:+.1} {:+.1} {:+.1} %", q[0], q[1], q[2])
        };
        // How far apart the depths blended into a pixel lie (relative), on the object and
        // on the still pixels.
        let spread = gaussians::raster::reference::depth_spread(
            &gaussians::raster::reference::Gaussians64::from(&all),
            &fr.camera,
        );
        let (mut on, mut off) = (Vec::new(), Vec::new());
        for (&o, &v) in fr.object.iter().zip(&spread) {
            match o {
                o if o == id => on.push(v),
                1..=2 => off.push(v),
                _ => {}
            }
        }
        let (on, off) = (quartiles(on), quartiles(off));
        println!(
            "{k}: depth spread (quartiles, %) on the object {:.1} {:.1} {:.1}, on the still \
             surfaces {:.1} {:.1} {:.1}",
            100.0 * on[0],
            100.0 * on[1],
            100.0 * on[2],
            100.0 * off[0],
            100.0 * off[1],
            100.0 * off[2]
        );
        println!(
            "{k}: all {}, trajectories {}, trajectories without the field {}, the others {} \
             | trajectories {}, the others {}",
            render(&all, &|_| true),
            render(&all, &|i| traj[i]),
            render(&bare, &|i| traj[i]),
            render(&all, &|i| !traj[i]),
            per_gaussian(&|i| traj[i]),
            per_gaussian(&|i| !traj[i]),
        );
    }
}
