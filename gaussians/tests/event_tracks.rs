//! Tracks chained through event images (issue #30, `tracks.event_steps`): on a synthetic
//! scene whose objects move too far between frames for Lucas–Kanade, against where the
//! tracked surface point truly is in each frame (the scene's analytic motion).

use gaussians::tracks::events::{EventSource, between};
use gaussians::tracks::lk::{Grey, Pyramid};
use gaussians::tracks::{Frame, TrackSettings, track_from};
use glam::{DVec2, Vec2};

struct Outcome {
    /// Links (a moving pixel of the middle frame, another frame) tracked within 1.5 px
    /// of the truth, and tracked but further off.
    right: usize,
    wrong: usize,
    /// Links that could have been followed (the point is visible in that frame).
    visible: usize,
    /// Distances of the tracked links from the truth, pixels.
    errors: Vec<f64>,
}

fn measure(preset: &str, size: u32, steps: usize) -> Outcome {
    let mut cfg = synth::SynthConfig::preset(preset).unwrap();
    (cfg.width, cfg.height) = (size, size);
    let world = synth::SynthWorld::new(&cfg).unwrap();
    let times = cfg.train_times();
    let cams: Vec<scene::Camera> = times.iter().map(|&t| world.camera_at(t)).collect();
    let (w, h) = (size as usize, size as usize);
    let grey: Vec<Grey> = (times.iter())
        .map(|&t| Grey {
            width: w,
            height: h,
            data: synth::sim::luminance(&world.render_frame(t).rgb),
        })
        .collect();
    let (events, _) = synth::scene_dir::simulate_scene(&world).unwrap();
    let src = EventSource {
        events: events.as_slice(),
        seconds: &times,
        contrast: cfg.events.threshold_pos as f32,
        srgb: false,
        steps,
    };
    let images = between(&grey, &src);
    let st = TrackSettings::default();
    let (t_first, t_last) = (times[0], *times.last().unwrap());
    let frames: Vec<Frame> = (cams.iter().zip(&times).zip(grey).zip(images))
        .map(|(((camera, &t), g), b)| Frame {
            camera,
            time: (t - t_first) / (t_last - t_first),
            pyramid: Pyramid::new(g, st.levels as usize),
            between: (b.into_iter())
                .map(|g| Pyramid::new(g, st.levels as usize))
                .collect(),
        })
        .collect();
    let mid = times.len() / 2;
    let mut out = Outcome {
        right: 0,
        wrong: 0,
        visible: 0,
        errors: vec![],
    };
    for y in (0..h).step_by(2) {
        for x in (0..w).step_by(2) {
            let px = DVec2::new(x as f64, y as f64);
            let Some(hit) = world.cast(times[mid], px) else {
                continue;
            };
            if !cfg.objects[hit.object].moves() {
                continue;
            }
            let track = track_from(&frames, mid, Vec2::new(x as f32 + 0.5, y as f32 + 0.5), &st);
            for (k, q) in track.iter().enumerate().filter(|(k, _)| *k != mid) {
                let at = world.material_to_world(hit.object, hit.local, times[k]);
                let Some((truth, depth)) = cams[k].project_world(at) else {
                    continue;
                };
                // Visible: the ray through the true pixel meets this surface point.
                let seen = world.cast(times[k], truth).is_some_and(|o| {
                    o.object == hit.object && (o.depth - depth).abs() < 0.02 * depth
                });
                if !seen {
                    continue;
                }
                out.visible += 1;
                let Some(q) = q else { continue };
                let q = gaussians::tracks::camera_pixel(*q);
                out.errors.push(q.distance(truth));
                if q.distance(truth) < 1.5 {
                    out.right += 1;
                } else {
                    out.wrong += 1;
                }
            }
        }
    }
    out
}

/// Sorted errors' quantile.
fn quantile(sorted: &[f64], f: f64) -> f64 {
    sorted[((f * sorted.len() as f64) as usize).min(sorted.len() - 1)]
}

#[test]
fn event_images_carry_tracks_across_motion_the_frames_alone_lose() {
    // `fast` at 96²: the ball and box turn by up to a half-turn between frames. Measured
    // (links of the middle frame's moving pixels within 1.5 px, of 1678 visible): frames
    // alone 160 (133 more tracked further off); 1 event image per interval 461, 2: 621,
    // 4: 634, 8: 554 (each link's error adds up along the chain).
    let frames_alone = measure("fast", 96, 0);
    let mut events = measure("fast", 96, 2);
    assert!(
        events.right >= 3 * frames_alone.right,
        "with event images {} links within 1.5 px, frames alone {}",
        events.right,
        frames_alone.right
    );
    assert!(
        events.right > events.wrong,
        "{} right, {} wrong",
        events.right,
        events.wrong
    );
    events.errors.sort_by(f64::total_cmp);
    let p50 = quantile(&events.errors, 0.5);
    assert!(p50 < 1.2, "median error of the tracked links {p50:.2} px");
}

#[test]
fn an_event_image_is_the_two_sided_log_blend_of_its_frames_and_events() {
    // Two 2×1 linear frames, C = 0.2, two event images in the interval [1, 4] s (at 2 s
    // and 3 s). Pixel 0: two ON events at 1.5 s and 2.5 s; pixel 1: one OFF event at
    // 3.5 s (and one at 4.5 s, after the interval, which must not count).
    let frame = |a: f32, b: f32| Grey {
        width: 2,
        height: 1,
        data: vec![a, b],
    };
    let grey = [frame(0.2, 0.6), frame(0.3, 0.5)];
    let mut ev = scene::EventStream::new(2, 1);
    for (t, x, p) in [(1.5, 0, 1), (2.5, 0, 1), (3.5, 1, -1), (4.5, 1, -1)] {
        ev.push(t, x, 0, p);
    }
    let (c, eps) = (0.2f64, 1e-3f64);
    for srgb in [false, true] {
        let src = EventSource {
            events: ev.as_slice(),
            seconds: &[1.0, 4.0],
            contrast: c as f32,
            srgb,
            steps: 2,
        };
        let out = between(&grey, &src);
        assert_eq!(out.len(), 2);
        assert!(out[1].is_empty(), "nothing after the last frame");
        assert_eq!(out[0].len(), 2);
        let lin = |v: f32| {
            if srgb {
                scene::image_io::srgb_to_linear(v) as f64
            } else {
                v as f64
            }
        };
        let enc = |v: f64| {
            if srgb {
                scene::image_io::linear_to_srgb(v as f32) as f64
            } else {
                v
            }
        };
        // Signed counts from t_a to each image's time, and over the whole interval.
        let left = [[1.0, 0.0], [2.0, 0.0]];
        let total = [2.0, -1.0];
        for (j, img) in out[0].iter().enumerate() {
            let s = (j + 1) as f64 / 3.0;
            for p in 0..2 {
                let (la, lb) = (
                    (lin(grey[0].data[p]) + eps).ln(),
                    (lin(grey[1].data[p]) + eps).ln(),
                );
                let l = (1.0 - s) * (la + c * left[j][p]) + s * (lb - c * (total[p] - left[j][p]));
                let want = enc((l.exp() - eps).clamp(0.0, 1.0));
                let got = img.data[p] as f64;
                assert!(
                    (got - want).abs() < 1e-5,
                    "srgb {srgb}, image {j}, pixel {p}: {got} vs {want}"
                );
            }
        }
    }
}
