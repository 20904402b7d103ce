//! Windows of the moving tracks' trajectories (issue #30, `tracks.window`): the lives
//! tile time, and on a scene whose objects turn and oscillate too fast for one quadratic
//! over the recording, a window's quadratic lifted from true tracks lands where the
//! surface point truly is between the frames (the scene's analytic motion).

use gaussians::splats::ALWAYS;
use gaussians::tracks::init::windows;
use gaussians::tracks::lift::Lifted;
use gaussians::tracks::lk::{Grey, Pyramid};
use gaussians::tracks::{Frame, Handover, TrackSettings, lift_track};
use glam::{DVec2, Vec2};

#[test]
fn the_lives_tile_time_and_each_frame_lies_in_its_own() {
    for n in [2usize, 5, 9, 21] {
        let times: Vec<f64> = (0..n).map(|k| k as f64 / (n - 1) as f64).collect();
        for size in 1..=5 {
            let w = windows(&times, size, Handover::Midway);
            assert_eq!(w.len(), n.div_ceil(size), "n {n}, size {size}");
            assert_eq!(w[0].life[0], ALWAYS[0]);
            assert_eq!(w.last().unwrap().life[1], ALWAYS[1]);
            for (a, b) in w.iter().zip(w.iter().skip(1)) {
                assert_eq!(a.life[1], b.life[0], "lives meet: n {n}, size {size}");
                assert_eq!(a.frames.end, b.frames.start);
            }
            for x in &w {
                assert!(x.frames.contains(&x.reference));
                let mid = 0.5 * (x.frames.start + x.frames.end - 1) as f64;
                assert!((x.reference as f64 - mid).abs() <= 0.5, "{x:?}");
                assert_eq!(x.context.start, x.frames.start.saturating_sub(1));
                assert_eq!(x.context.end, (x.frames.end + 1).min(n));
                for k in x.frames.clone() {
                    let t = times[k] as f32;
                    assert!(t >= x.life[0] && t < x.life[1], "frame {k} in {x:?}");
                }
            }
        }
    }
}

#[test]
fn windows_that_share_their_end_frames_hand_over_at_them() {
    // `handover = "frame"`: each window starts at the previous one's last frame and
    // lives from its first frame's time to its last's, so every frame but a shared one
    // lies in the life of exactly one window that holds it, and a shared frame ends one
    // life and starts the next. Counted here: ⌈(n − 1)/(size − 1)⌉ windows.
    for n in [2usize, 5, 9, 20, 21] {
        let times: Vec<f64> = (0..n)
            .map(|k| (k as f64 / (n - 1) as f64).powf(1.3))
            .collect();
        for size in 2..=5 {
            let w = windows(&times, size, Handover::Frame);
            assert_eq!(w.len(), (n - 1).div_ceil(size - 1), "n {n}, size {size}");
            assert_eq!((w[0].frames.start, w[0].life[0]), (0, ALWAYS[0]));
            assert_eq!(w.last().unwrap().life[1], ALWAYS[1]);
            assert_eq!(w.last().unwrap().frames.end, n);
            for (a, b) in w.iter().zip(w.iter().skip(1)) {
                assert_eq!(a.frames.end - 1, b.frames.start, "n {n}, size {size}");
                assert_eq!(a.life[1], b.life[0]);
                assert_eq!(a.life[1], times[b.frames.start] as f32);
            }
            for x in &w {
                assert!(x.frames.len() >= 2 && x.frames.len() <= size, "{x:?}");
                assert!(x.frames.contains(&x.reference));
                assert_eq!(x.context.start, x.frames.start.saturating_sub(1));
                for k in x.frames.clone() {
                    let t = times[k] as f32;
                    let last = k + 1 == x.frames.end && x.frames.end < n;
                    assert_eq!(t >= x.life[0] && t < x.life[1], !last, "frame {k} in {x:?}");
                }
            }
        }
    }
    // The lives, by hand: 5 frames 0, ¼, ½, ¾, 1 in windows of 3.
    let w = windows(&[0.0, 0.25, 0.5, 0.75, 1.0], 3, Handover::Frame);
    let lives: Vec<_> = w.iter().map(|x| (x.frames.clone(), x.life)).collect();
    assert_eq!(lives, [(0..3, [ALWAYS[0], 0.5]), (2..5, [0.5, ALWAYS[1]])]);
}

#[test]
fn a_window_holds_a_fast_turn_that_one_quadratic_over_the_recording_cannot() {
    // `fast` (8 fps, 9 frames): the box oscillates at 1.5 Hz and turns 180°/s. Tracks
    // of its surface points are their true projections (no tracker error); each is
    // lifted over the whole recording, and over the context of the window of 3 frames
    // around the middle frame (with the true depth as prior), then placed at the time
    // halfway to the next frame, which neither saw.
    let mut cfg = synth::SynthConfig::preset("fast").unwrap();
    (cfg.width, cfg.height) = (96, 96);
    let world = synth::SynthWorld::new(&cfg).unwrap();
    let times = cfg.train_times();
    let (t0, t1) = (times[0], *times.last().unwrap());
    let norm = |t: f64| (t - t0) / (t1 - t0);
    let cams: Vec<scene::Camera> = times.iter().map(|&t| world.camera_at(t)).collect();
    let blank = || {
        let g = Grey {
            width: 96,
            height: 96,
            data: vec![0.0; 96 * 96],
        };
        Pyramid::new(g, 1)
    };
    let frames: Vec<Frame> = (cams.iter().zip(&times))
        .map(|(camera, &t)| Frame {
            camera,
            time: norm(t),
            pyramid: blank(),
            between: Vec::new(),
        })
        .collect();
    let normalised: Vec<f64> = times.iter().map(|&t| norm(t)).collect();
    let win = windows(&normalised, 3, Handover::Midway);
    let mid = times.len() / 2;
    let w = win.iter().find(|w| w.frames.contains(&mid)).unwrap();
    let st = TrackSettings::default();
    // The true depth as each frame's prior (what the lift has on a scene with priors).
    let depths: Vec<Option<gaussians::tracks::depth::Aligned>> = (times.iter())
        .map(|&t| {
            Some(gaussians::tracks::depth::Aligned {
                width: 96,
                height: 96,
                z: world.render(t).depth,
                median_rel_error: 0.0,
                points: 0,
            })
        })
        .collect();
    let box_id = cfg.objects.iter().position(|o| o.name == "box").unwrap();
    // Halfway from the reference frame to the next: inside the window's life.
    let t_half = 0.5 * (times[w.reference] + times[w.reference + 1]);
    let cam_half = world.camera_at(t_half);
    let n_err = |v: &mut Vec<f64>| v.push(f64::INFINITY);
    let (mut whole_err, mut window_err, mut n) = (Vec::new(), Vec::new(), 0);
    for y in (0..96).step_by(2) {
        for x in (0..96).step_by(2) {
            let px = DVec2::new(x as f64, y as f64);
            let Some(hit) = world
                .cast(times[w.reference], px)
                .filter(|h| h.object == box_id)
            else {
                continue;
            };
            let visible = |t: f64, cam: &scene::Camera| -> Option<DVec2> {
                let at = world.material_to_world(box_id, hit.local, t);
                let (q, d) = cam.project_world(at)?;
                let o = world.cast(t, q)?;
                (o.object == box_id && (o.depth - d).abs() < 0.02 * d).then_some(q)
            };
            // Lucas–Kanade coordinates (pixel centres at x + ½), as a tracker gives them.
            let track: Vec<Option<Vec2>> = (times.iter().zip(&cams))
                .map(|(&t, c)| visible(t, c).map(|q| Vec2::new(q.x as f32 + 0.5, q.y as f32 + 0.5)))
                .collect();
            let Some(truth) = visible(t_half, &cam_half) else {
                continue;
            };
            if (w.context.clone()).any(|k| track[k].is_none()) {
                continue;
            }
            n += 1;
            let at_half = |l: Lifted| cam_half.project_world(l.at(norm(t_half) - 0.5));
            match lift_track(&frames, &track, &st, &depths).and_then(at_half) {
                Some((q, _)) => whole_err.push(q.distance(truth)),
                None => n_err(&mut whole_err),
            }
            let masked: Vec<_> = (track.iter().enumerate())
                .map(|(k, p)| p.filter(|_| w.context.contains(&k)))
                .collect();
            match lift_track(&frames, &masked, &st, &depths).and_then(at_half) {
                Some((q, _)) => window_err.push(q.distance(truth)),
                None => n_err(&mut window_err),
            }
        }
    }
    for v in [&mut whole_err, &mut window_err] {
        v.sort_by(f64::total_cmp);
    }
    let q = |v: &[f64], f: f64| v[((f * v.len() as f64) as usize).min(v.len() - 1)];
    eprintln!(
        "{n} box points, error halfway between frames (px): whole p50 {:.2} p90 {:.2}, window p50 {:.2} p90 {:.2}",
        q(&whole_err, 0.5),
        q(&whole_err, 0.9),
        q(&window_err, 0.5),
        q(&window_err, 0.9)
    );
    // Measured: no box point lifts over the whole recording (no quadratic fits its
    // frames within `moving_pixels`); every one lifts in the window, 1.8 px off (p50)
    // halfway between frames 1/8 s apart.
    assert!(n >= 30, "only {n} box points seen through the window");
    assert!(
        q(&whole_err, 0.5) > 3.0,
        "whole recording: p50 {}",
        q(&whole_err, 0.5)
    );
    assert!(
        q(&window_err, 0.9) < 2.5,
        "window: p90 {}",
        q(&window_err, 0.9)
    );
}
