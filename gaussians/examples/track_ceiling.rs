//! What limits the tracks on a fast-moving object (issue #30, `fast`): the links from the
//! middle train frame to the next, per moving object, against where the surface point
//! under each start pixel truly goes (the scene's analytic motion), chained through the
//! event images between the two frames as the tracks init does, and through the images
//! the renderer draws at those same times (what perfect event images would be).
//!
//! ```text
//! cargo run --release -p degs-gaussians --example track_ceiling -- [PRESET] [FPS] [SIZE] [STEPS] [SCENE]
//! ```
//!
//! (`fast`, 8, 96 and 2 event images per interval unless given.) First each moving object
//! followed as one rigid body ([`part_motion`]) from its true surface points at the
//! middle frame through the whole recording (with `SCENE`, a `degs synth` directory of
//! the same scene, through its frames, cameras and events as the init reads them). Then, Per object, as right / wrong / lost (within 1.5 px of
//! the truth at the next frame; every second pixel of the object at the middle frame that
//! stays visible): Lucas–Kanade as the init runs it (7×7 window, 3 levels) with its
//! forward–backward check; the same without the check; started at the true displacement
//! of each step; through the rendered images; an affine 15×15 window refined from it
//! through the rendered images; each pixel moved by the affine motion of its tracked
//! neighbours (`tracks::fill::carried`: RANSAC over those within 6 px that passed the
//! forward–backward check); and the init's link where it passed the check, else the
//! neighbours' (what `tracks.fill` does at every link); the object's points moved by its
//! rigid motion found from their brightness ([`part_motion::step`], two pyramid levels)
//! through the event images, and through the rendered images.

use gaussians::tracks::events::{EventSource, between};
use gaussians::tracks::fill;
use gaussians::tracks::lk::{Grey, Pyramid, track_from};
use gaussians::tracks::part_motion::{self, Motion};
use glam::{DVec2, DVec3, Vec2};

type Tally = [usize; 3];

/// Lucas–Kanade through `chain` (the init's window and levels), each step started at
/// `guess(step)`; with `affine`, each step then refined by an affine 15×15 window.
fn follow(chain: &[Pyramid], p: Vec2, guess: &dyn Fn(usize) -> Vec2, affine: bool) -> Option<Vec2> {
    (chain.windows(2).enumerate()).try_fold(p, |q, (j, w)| {
        let r = track_from(&w[0], &w[1], q, guess(j), 3, 1e-5)?;
        match affine {
            true => refine(&w[0].0[0], &w[1].0[0], q, r - q, 7, true),
            false => Some(r),
        }
    })
}

/// Gauss–Newton on a window of radius `r` around `p` in `a`, warped into `b` from the
/// displacement `d0`: a translation, or an affine warp (`affine`), at the finest level.
fn refine(a: &Grey, b: &Grey, p: Vec2, d0: Vec2, r: i32, affine: bool) -> Option<Vec2> {
    let n = if affine { 6 } else { 2 };
    let mut q = [d0.x as f64, d0.y as f64, 0.0, 0.0, 0.0, 0.0];
    for _ in 0..30 {
        let mut m = [[0.0f64; 7]; 6];
        for (u, v) in (-r..=r).flat_map(|j| (-r..=r).map(move |i| (i as f64, j as f64))) {
            let wx = (p.x as f64 + q[0] + (1.0 + q[2]) * u + q[3] * v) as f32;
            let wy = (p.y as f64 + q[1] + q[4] * u + (1.0 + q[5]) * v) as f32;
            let gx = 0.5 * (b.at(wx + 1.0, wy) - b.at(wx - 1.0, wy)) as f64;
            let gy = 0.5 * (b.at(wx, wy + 1.0) - b.at(wx, wy - 1.0)) as f64;
            let e = (b.at(wx, wy) - a.at(p.x + u as f32, p.y + v as f32)) as f64;
            let jr = [gx, gy, gx * u, gx * v, gy * u, gy * v];
            for s in 0..n {
                for t in 0..n {
                    m[s][t] += jr[s] * jr[t];
                }
                m[s][6] -= jr[s] * e;
            }
        }
        let step = solve(&mut m, n)?;
        (0..n).for_each(|s| q[s] += step[s]);
        if step[0].abs() + step[1].abs() < 1e-3 {
            break;
        }
    }
    let d = Vec2::new(q[0] as f32, q[1] as f32);
    (d.is_finite() && d.length() < 40.0).then_some(p + d)
}

/// Gauss–Jordan on the first `n` rows of an augmented system (right side in column 6).
fn solve(m: &mut [[f64; 7]; 6], n: usize) -> Option<[f64; 6]> {
    for c in 0..n {
        m[c][c] += 1e-9;
        let piv = (c..n).max_by(|&a, &b| m[a][c].abs().total_cmp(&m[b][c].abs()))?;
        if m[piv][c].abs() < 1e-12 {
            return None;
        }
        m.swap(c, piv);
        for r in (0..n).filter(|&r| r != c) {
            let f = m[r][c] / m[c][c];
            let row = m[c];
            for (x, y) in m[r].iter_mut().zip(row) {
                *x -= f * y;
            }
        }
    }
    let mut out = [0.0; 6];
    (0..n).for_each(|i| out[i] = m[i][6] / m[i][i]);
    Some(out)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let preset = args.first().map_or("fast", String::as_str);
    let fps: f64 = args.get(1).map_or(8.0, |s| s.parse().expect("FPS"));
    let size: u32 = args.get(2).map_or(96, |s| s.parse().expect("SIZE"));
    let steps: usize = args.get(3).map_or(2, |s| s.parse().expect("STEPS"));
    let mut cfg = synth::SynthConfig::preset(preset).expect("a preset");
    (cfg.width, cfg.height, cfg.train_fps) = (size, size, fps);
    let world = synth::SynthWorld::new(&cfg).expect("the scene");
    let times = cfg.train_times();
    let (w, h) = (size as usize, size as usize);
    let luma = |t: f64| synth::sim::luminance(&world.render_frame(t).rgb);
    let grey = |data: Vec<f32>| Grey {
        width: w,
        height: h,
        data,
    };
    let frames: Vec<Grey> = times.iter().map(|&t| grey(luma(t))).collect();
    let (events, _) = synth::scene_dir::simulate_scene(&world).expect("events");
    let src = EventSource {
        events: events.as_slice(),
        seconds: &times,
        contrast: cfg.events.threshold_pos as f32,
        srgb: false,
        steps,
    };
    let mid = times.len() / 2;
    whole_recording(&world, &cfg, &frames, &src, args.get(4), mid);
    let between = between(&frames, &src).swap_remove(mid);
    let pyr = |g: &Grey| Pyramid::new(grey(g.data.clone()), 3);
    let mut events_chain = vec![pyr(&frames[mid])];
    events_chain.extend(between.iter().map(pyr));
    events_chain.push(pyr(&frames[mid + 1]));
    let n = events_chain.len();
    let ts: Vec<f64> = (0..n)
        .map(|j| times[mid] + (times[mid + 1] - times[mid]) * j as f64 / (n - 1) as f64)
        .collect();
    let rendered: Vec<Pyramid> = ts.iter().map(|&t| Pyramid::new(grey(luma(t)), 3)).collect();
    let backward: Vec<Pyramid> = events_chain.iter().rev().map(|p| pyr(&p.0[0])).collect();
    let zero = |_: usize| Vec2::ZERO;
    // Every pixel's link with the forward–backward check (the neighbours' evidence).
    let checked = |p: Vec2| {
        follow(&events_chain, p, &zero, false)
            .filter(|&q| follow(&backward, q, &zero, false).is_some_and(|b| b.distance(p) < 1.0))
    };
    let pixel = |x: usize, y: usize| Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
    let links: Vec<(Vec2, Vec2)> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter_map(|(x, y)| checked(pixel(x, y)).map(|q| (pixel(x, y), q)))
        .collect();
    println!(
        "{preset} {size}² at {fps} fps, frame {mid} → {}: links right / wrong / lost (1.5 px)",
        mid + 1
    );
    println!(
        "{:<6} {:>7} {:>13} {:>13} {:>13} {:>13} {:>13} {:>13} {:>13} {:>13} {:>13}",
        "object",
        "pixels",
        "init (FB)",
        "no check",
        "true start",
        "rendered",
        "affine 15²",
        "neighbours",
        "FB, else nb.",
        "part (3D)",
        "part, rend."
    );
    for (o, spec) in cfg.objects.iter().enumerate().filter(|(_, s)| s.moves()) {
        let mut rows = [[0usize; 3]; 9];
        let mut count = 0;
        let moved = part_ends(&world, o, &ts, &events_chain, w, h);
        let moved_r = part_ends(&world, o, &ts, &rendered, w, h);
        for (x, y) in (0..h)
            .step_by(2)
            .flat_map(|y| (0..w).step_by(2).map(move |x| (x, y)))
        {
            let Some(hit) = world.cast(times[mid], DVec2::new(x as f64, y as f64)) else {
                continue;
            };
            if hit.object != o {
                continue;
            }
            // The surface point at each image's time, while visible.
            let truth: Option<Vec<Vec2>> = (ts.iter())
                .map(|&t| {
                    let at = world.material_to_world(o, hit.local, t);
                    let (q, z) = world.camera_at(t).project_world(at)?;
                    let seen = (world.cast(t, q))
                        .is_some_and(|s| s.object == o && (s.depth - z).abs() < 0.02 * z);
                    seen.then(|| Vec2::new(q.x as f32 + 0.5, q.y as f32 + 0.5))
                })
                .collect();
            let Some(truth) = truth else { continue };
            count += 1;
            let p = pixel(x, y);
            let end = truth[n - 1];
            let true_step = |j: usize| truth[j + 1] - truth[j];
            let near = fill::carried(&links, p, 6.0, (x * 131 + y) as u64);
            let results = [
                checked(p),
                follow(&events_chain, p, &zero, false),
                follow(&events_chain, p, &true_step, false),
                follow(&rendered, p, &zero, false),
                follow(&rendered, p, &zero, true),
                near,
                checked(p).or(near),
                moved.as_ref().and_then(|m| m(truth[0], hit.local)),
                moved_r.as_ref().and_then(|m| m(truth[0], hit.local)),
            ];
            for (row, r) in rows.iter_mut().zip(results) {
                let k = match r {
                    Some(q) if q.distance(end) < 1.5 => 0,
                    Some(_) => 1,
                    None => 2,
                };
                row[k] += 1;
            }
        }
        let cell = |t: Tally| format!("{}/{}/{}", t[0], t[1], t[2]);
        println!(
            "{:<6} {:>7} {:>13} {:>13} {:>13} {:>13} {:>13} {:>13} {:>13} {:>13} {:>13}",
            spec.name,
            count,
            cell(rows[0]),
            cell(rows[1]),
            cell(rows[2]),
            cell(rows[3]),
            cell(rows[4]),
            cell(rows[5]),
            cell(rows[6]),
            cell(rows[7]),
            cell(rows[8])
        );
    }
}

type Ends<'a> = Box<dyn Fn(Vec2, DVec3) -> Option<Vec2> + 'a>;

/// Object `o`'s rigid motion through `chain` from its true surface points at every pixel
/// of the first image ([`part_motion::step`], image to image); the returned closure gives
/// where the point with material coordinates `local` lands in the last image.
fn part_ends<'a>(
    world: &'a synth::SynthWorld,
    o: usize,
    ts: &[f64],
    chain: &[Pyramid],
    w: usize,
    h: usize,
) -> Option<Ends<'a>> {
    let grey = |g: &Grey| Grey {
        width: g.width,
        height: g.height,
        data: g.data.clone(),
    };
    let chain: Vec<Pyramid> = (chain.iter())
        .map(|p| Pyramid::new(grey(&p.0[0]), part_motion::LEVELS))
        .collect();
    let xs: Vec<DVec3> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter_map(|(x, y)| world.cast(ts[0], DVec2::new(x as f64, y as f64)))
        .filter(|hit| hit.object == o)
        .map(|hit| world.material_to_world(o, hit.local, ts[0]))
        .collect();
    let centroid = xs.iter().sum::<DVec3>() / xs.len().max(1) as f64;
    let mut total = Motion::identity(centroid);
    let cams: Vec<_> = ts.iter().map(|&t| world.camera_at(t)).collect();
    for j in 0..chain.len() - 1 {
        let ys: Vec<DVec3> = xs.iter().map(|&x| total.apply(x)).collect();
        let c = total.apply(centroid);
        let m = part_motion::step(
            &chain[j],
            &chain[j + 1],
            &cams[j],
            &cams[j + 1],
            &ys,
            Motion::identity(c),
        )?;
        total = Motion {
            rot: m.rot * total.rot,
            shift: m.apply(total.apply(centroid)) - centroid,
            centre: centroid,
        };
    }
    let last = cams[chain.len() - 1];
    let t0 = ts[0];
    Some(Box::new(move |_start: Vec2, local: DVec3| {
        let x = world.material_to_world(o, local, t0);
        let (q, _) = last.project_world(total.apply(x))?;
        Some(Vec2::new(q.x as f32 + 0.5, q.y as f32 + 0.5))
    }))
}

/// Each moving object followed as one rigid body ([`part_motion::follow`]) from its true
/// surface points at the middle frame through the whole recording: the median distance
/// (pixels) from where the truth puts them at each train frame, over the points visible
/// there.
fn whole_recording(
    world: &synth::SynthWorld,
    cfg: &synth::SynthConfig,
    frames: &[Grey],
    src: &EventSource,
    scene_dir: Option<&String>,
    mid: usize,
) {
    let (w, h) = (cfg.width as usize, cfg.height as usize);
    let times = cfg.train_times();
    let cams: Vec<scene::Camera> = times.iter().map(|&t| world.camera_at(t)).collect();
    let cam_refs: Vec<&scene::Camera> = cams.iter().collect();
    let copy = |g: &Grey| Grey {
        width: g.width,
        height: g.height,
        data: g.data.clone(),
    };
    let mut seq = part_motion::Sequence::new(
        frames.iter().map(copy).collect(),
        between(frames, src),
        &cam_refs,
    );
    if let Some(dir) = scene_dir {
        // The scene directory's frames, cameras and events, as the init reads them.
        let sc = scene::Scene::open(dir).expect("scene");
        let cams: Vec<scene::Camera> = sc.train.frames.iter().map(|f| sc.camera(f)).collect();
        for (k, c) in cams.iter().enumerate() {
            let d = c
                .cam_to_world
                .centre()
                .distance(world.camera_at(times[k]).cam_to_world.centre());
            if d > 1e-6 {
                println!("camera {k} differs by {d:.2e}");
            }
        }
        let grey: Vec<Grey> = (sc.train.frames.iter())
            .map(|f| {
                let im = scene::image_io::read_image(sc.image_path(f)).expect("image");
                let n = (im.width * im.height) as usize;
                let c = im.channels as usize;
                let data = (0..n)
                    .map(|p| {
                        0.299 * im.data[p * c]
                            + 0.587 * im.data[p * c + 1]
                            + 0.114 * im.data[p * c + 2]
                    })
                    .collect();
                Grey {
                    width: im.width as usize,
                    height: im.height as usize,
                    data,
                }
            })
            .collect();
        let events = sc.load_events().expect("events");
        let seconds: Vec<f64> = sc.train.frames.iter().map(|f| f.timestamp).collect();
        let src = EventSource {
            events: events.as_slice(),
            seconds: &seconds,
            contrast: sc.contrast_threshold() as f32,
            srgb: sc.train.frames_srgb(),
            steps: src.steps,
        };
        let between = between(&grey, &src);
        let refs: Vec<&scene::Camera> = cams.iter().collect();
        seq = part_motion::Sequence::new(grey, between, &refs);
        println!("(through {dir}'s frames, cameras and events)");
    }
    println!("followed as rigid bodies from frame {mid}, median px from the truth per frame:");
    for (o, spec) in cfg.objects.iter().enumerate().filter(|(_, s)| s.moves()) {
        let locals: Vec<DVec3> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter_map(|(x, y)| world.cast(times[mid], DVec2::new(x as f64, y as f64)))
            .filter(|hit| hit.object == o)
            .map(|hit| hit.local)
            .collect();
        let xs: Vec<DVec3> = (locals.iter())
            .map(|&l| world.material_to_world(o, l, times[mid]))
            .collect();
        let Some(motions) = part_motion::follow(&seq, &xs, mid, &|_, m| *m)
            .map(|m| part_motion::at_frames(&seq, &m))
        else {
            println!("{:<6} lost", spec.name);
            continue;
        };
        let cells: Vec<String> = (0..times.len())
            .map(|k| {
                let mut e: Vec<f64> = (locals.iter().zip(&xs))
                    .filter_map(|(&l, &x)| {
                        let truth = world.material_to_world(o, l, times[k]);
                        let (q, z) = cams[k].project_world(truth)?;
                        let hit = world.cast(times[k], q)?;
                        (hit.object == o && (hit.depth - z).abs() < 0.02 * z).then_some(())?;
                        let (p, _) = cams[k].project_world(motions[k].apply(x))?;
                        Some(p.distance(q))
                    })
                    .collect();
                e.sort_by(f64::total_cmp);
                e.get(e.len() / 2).map_or("-".into(), |v| format!("{v:.1}"))
            })
            .collect();
        println!("{:<6} {}", spec.name, cells.join(" "));
    }
}
