//! How far the moving Gaussians of a model lie from the truth, per object (issue #30): a
//! diagnostic for a model of a synthetic scene (`degs synth`: `synth.json`), meant for a
//! warm-up stopped right after the tracks init (`[gaussians] iterations = 1`,
//! `static_iterations = 0`, `[gaussians.size] tolerance_db = 0`), to see what the tracks
//! lifted to.
//!
//! ```text
//! cargo run --release -p degs-gaussians --example tracks_truth -- SCENE MODEL_DIR [OUT.png]
//! ```
//!
//! Every Gaussian with a trajectory or in a rigid part is projected into the train
//! frame in the middle of its life; the true surface under its pixel (`SynthWorld::cast`) names the object and
//! its depth. Per object: how many Gaussians project onto it, the fraction in front of
//! its surface by more than 10 %, on it, behind it (and of those on and behind, how many
//! lie within 2 px of another object: an outline), their median signed depth error, and
//! the quartiles of the largest pixel shift their trajectory makes from that middle
//! position over the frames it was fitted to. A Gaussian on a moving object's surface
//! is tied to its material point; at its other frames the pixel distance between the
//! two projections and the signed relative depth error (medians). And the tracks before
//! any lifting (`tracks.safetensors`): the distance (median, and the share over 2 px)
//! from where Lucas–Kanade followed each track to where the true surface point under its
//! middle position goes. `OUT.png`: the middle train frame ×4 with a dot where each
//! moving Gaussian living then projects, red on a still object, green on a moving one.

mod common;

use common::{fail, median, quartiles};
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Default)]
struct Row {
    front: usize,
    on: usize,
    behind: usize,
    /// Of those behind / on, how many lie within 2 px of another object's pixels.
    behind_edge: usize,
    on_edge: usize,
    /// Per observation away from the track's middle one: the distance (px) from where
    /// the true surface point under its middle position projects.
    lk_px: Vec<f64>,
    /// Largest pixel shift of the trajectory from its middle position, per Gaussian.
    shift_px: Vec<f64>,
    depth_at_middle: Vec<f64>,
    px_away: Vec<f64>,
    depth_away: Vec<f64>,
}

fn main() {
    let (args, root, sc, model) = common::open("tracks_truth SCENE MODEL_DIR [OUT.png]");
    let path = root.join("synth.json");
    let text =
        std::fs::read_to_string(&path).unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
    let cfg: synth::SynthConfig =
        serde_json::from_str(&text).unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
    let world = synth::SynthWorld::new(&cfg).unwrap_or_else(|e| fail(e));
    let s = &model.splats;
    let frames = &sc.train.frames;
    let at: Vec<_> = frames.iter().map(|f| model.at(f.time as f32)).collect();
    let mut rows: BTreeMap<usize, Row> = BTreeMap::new();
    let life = |i: usize| s.life.get(i).copied().unwrap_or(gaussians::splats::ALWAYS);
    // The Gaussians with a trajectory, and the members of rigid parts (`tracks.parts`),
    // which move with their part over the whole recording.
    let in_part = |i: usize| {
        s.part
            .get(i)
            .is_some_and(|&p| p != gaussians::parts::NO_PART)
    };
    let movers: Vec<usize> = (0..s.len())
        .filter(|&i| (s.motion.get(i)).is_some_and(gaussians::motion::has_trajectory) || in_part(i))
        .collect();
    for &i in &movers {
        let life = life(i);
        let alive: Vec<usize> = (0..frames.len())
            .filter(|&k| gaussians::motion::alive(life, frames[k].time as f32))
            .collect();
        let Some(&mid) = alive.get(alive.len() / 2) else {
            continue;
        };
        let pos = |k: usize| glam::Vec3::from(at[k].means[i]).as_dvec3();
        let ts = frames[mid].timestamp;
        let cam = world.camera_at(ts);
        let Some((px, z)) = cam.project_world(pos(mid)) else {
            continue;
        };
        let Some(hit) = world.cast(ts, px) else {
            continue;
        };
        let e = z / hit.depth - 1.0;
        let row = rows.entry(hit.object + 1).or_default();
        row.depth_at_middle.push(e);
        let edge = [(2.0, 0.0), (-2.0, 0.0), (0.0, 2.0), (0.0, -2.0)]
            .iter()
            .any(|&(dx, dy)| {
                (world.cast(ts, px + glam::DVec2::new(dx, dy)))
                    .is_none_or(|h| h.object != hit.object)
            });
        match e {
            e if e < -0.1 => row.front += 1,
            e if e > 0.1 => {
                row.behind += 1;
                row.behind_edge += edge as usize;
            }
            _ => {
                row.on += 1;
                row.on_edge += edge as usize;
            }
        }
        // Over the frames its trajectory was fitted to: its life's and one either side.
        let (a, b) = (
            alive[0].saturating_sub(1),
            (alive[alive.len() - 1] + 1).min(frames.len() - 1),
        );
        let shift = (a..=b)
            .filter_map(|k| {
                let c = world.camera_at(frames[k].timestamp);
                Some(
                    c.project_world(pos(k))?
                        .0
                        .distance(c.project_world(pos(mid))?.0),
                )
            })
            .fold(0.0, f64::max);
        row.shift_px.push(shift);
        if e.abs() > 0.1 || !cfg.objects[hit.object].moves() {
            continue;
        }
        for &k in alive.iter().filter(|&&k| k != mid) {
            let ts = frames[k].timestamp;
            let cam = world.camera_at(ts);
            let truth = world.material_to_world(hit.object, hit.local, ts);
            let (Some((q, zq)), Some((p, zp))) =
                (cam.project_world(truth), cam.project_world(pos(k)))
            else {
                continue;
            };
            row.px_away.push(q.distance(p));
            row.depth_away.push(zp / zq - 1.0);
        }
    }
    // The tracks themselves, before any lifting: where the true surface point under a
    // track's middle position goes, against where Lucas–Kanade followed it.
    let file = Path::new(&args[1]).join(gaussians::tracks::file::TRACKS_FILE);
    match gaussians::tracks::file::read(&file, s.len(), frames.len()) {
        Err(e) => eprintln!("no tracks' error from the truth: {e}"),
        Ok((ids, table)) => {
            for &id in &ids {
                let Some(row) = table.get(id as usize) else {
                    continue;
                };
                let seen: Vec<usize> = (0..row.len()).filter(|&k| row[k].is_some()).collect();
                let Some(&mid) = seen.get(seen.len() / 2) else {
                    continue;
                };
                let ts = frames[mid].timestamp;
                let Some(hit) = world.cast(ts, row[mid].expect("seen")) else {
                    continue;
                };
                let r = rows.entry(hit.object + 1).or_default();
                for &k in seen.iter().filter(|&&k| k != mid) {
                    let ts = frames[k].timestamp;
                    let truth = world.material_to_world(hit.object, hit.local, ts);
                    if let Some((q, _)) = world.camera_at(ts).project_world(truth) {
                        r.lk_px.push(q.distance(row[k].expect("seen")));
                    }
                }
            }
        }
    }
    // `OUT.png` (module docs).
    if let Some(out) = args.get(2) {
        let k = frames.len() / 2;
        let f = &frames[k];
        let img = image::open(sc.image_path(f))
            .unwrap_or_else(|e| fail(format!("frame {k}: {e}")))
            .to_rgb8();
        let (w, h) = img.dimensions();
        let mut big =
            image::imageops::resize(&img, 4 * w, 4 * h, image::imageops::FilterType::Nearest);
        let cam = world.camera_at(f.timestamp);
        for &i in movers
            .iter()
            .filter(|&&i| gaussians::motion::alive(life(i), f.time as f32))
        {
            let p = glam::Vec3::from(at[k].means[i]).as_dvec3();
            let Some((px, _)) = cam.project_world(p) else {
                continue;
            };
            let Some(hit) = world.cast(f.timestamp, px) else {
                continue;
            };
            let c = match cfg.objects[hit.object].moves() {
                true => image::Rgb([0, 255, 0]),
                false => image::Rgb([255, 0, 0]),
            };
            let (x, y) = ((4.0 * px.x + 2.0) as i64, (4.0 * px.y + 2.0) as i64);
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (u, v) = (x + dx, y + dy);
                if u >= 0 && v >= 0 && u < 4 * w as i64 && v < 4 * h as i64 {
                    big.put_pixel(u as u32, v as u32, c);
                }
            }
        }
        big.save(out)
            .unwrap_or_else(|e| fail(format!("{out}: {e}")));
    }
    println!(
        "{} Gaussians with a trajectory or in a rigid part ({} in parts); by the object under them at their middle frame:",
        movers.len(),
        movers.iter().filter(|&&i| in_part(i)).count()
    );
    println!(
        "object (moves) | count | in front / on / behind (10 %) | of on, behind: near an edge | depth err at middle, median % | tied: px err away, median | depth err away, median % / median |.| | trajectory's largest shift, px: quartiles | tracks' error from the truth, px: median, > 2 px"
    );
    for (o, r) in &rows {
        let n = r.front + r.on + r.behind;
        let abs: Vec<f64> = r.depth_away.iter().map(|e| e.abs()).collect();
        let [q1, q2, q3] = quartiles(r.shift_px.clone());
        println!(
            "{o} ({}) | {n} | {:.0} / {:.0} / {:.0} % | {} / {} | {:+.1} | {:.2} | {:+.1} / {:.1} | {:.1} {:.1} {:.1} | {:.2}, {:.0} %",
            cfg.objects[o - 1].moves(),
            100.0 * r.front as f64 / n as f64,
            100.0 * r.on as f64 / n as f64,
            100.0 * r.behind as f64 / n as f64,
            r.on_edge,
            r.behind_edge,
            100.0 * median(r.depth_at_middle.clone()),
            median(r.px_away.clone()),
            100.0 * median(r.depth_away.clone()),
            100.0 * median(abs),
            q1,
            q2,
            q3,
            median(r.lk_px.clone()),
            100.0 * r.lk_px.iter().filter(|&&e| e > 2.0).count() as f64
                / r.lk_px.len().max(1) as f64,
        );
    }
}
