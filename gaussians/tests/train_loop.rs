//! The training loop on a tiny scene, through a small differentiable test renderer
//! (additive isotropic splats; its gradients are checked here against finite
//! differences), so the loop is tested independently of the tile rasterizer.

use gaussians::train::init::{SH_C0, camera_bounds, camera_extent, random_splats};
use gaussians::train::{TrainSettings, Trainer, View};
use gaussians::{Planes, Rasterizer, RenderedImage, SplatGrads, Splats};
use glam::DVec3;
use scene::Camera;

mod train_common;
use train_common::{H, W, cameras, fixed_gaussians};

struct Additive;

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Projected centre, pixel radius and their derivatives w.r.t. the mean (by central
/// differences of the camera projection: the test renderer only).
fn project(cam: &Camera, m: [f32; 3], ls: [f32; 3]) -> Option<([f32; 2], f32, [[f32; 3]; 2])> {
    let p = DVec3::new(m[0] as f64, m[1] as f64, m[2] as f64);
    let (px, depth) = cam.project_world(p)?;
    if depth < 0.1 {
        return None;
    }
    let s = ((ls[0] + ls[1] + ls[2]) / 3.0).exp();
    let r = (cam.intrinsics.fx * s as f64 / depth) as f32;
    let mut jac = [[0.0f32; 3]; 2];
    for k in 0..3 {
        let mut e = DVec3::ZERO;
        e[k] = 1e-4;
        let (a, _) = cam.project_world(p + e)?;
        let (b, _) = cam.project_world(p - e)?;
        jac[0][k] = ((a.x - b.x) / 2e-4) as f32;
        jac[1][k] = ((a.y - b.y) / 2e-4) as f32;
    }
    Some(([px.x as f32, px.y as f32], r.max(0.3), jac))
}

impl Rasterizer for Additive {
    type State = ();
    fn render(&self, s: &Splats, cam: &Camera, _sh: u32, bg: [f32; 3]) -> (RenderedImage, ()) {
        let mut rgb = vec![0.0f32; 3 * W * H];
        for c in 0..3 {
            rgb[c * W * H..(c + 1) * W * H].fill(bg[c]);
        }
        for i in 0..s.len() {
            let Some((mu, r, _)) = project(cam, s.means[i], s.log_scales[i]) else {
                continue;
            };
            let a = sigmoid(s.opacity_logits[i]);
            let col: [f32; 3] = std::array::from_fn(|c| 0.5 + SH_C0 * s.sh_dc[i][c]);
            for y in 0..H {
                for x in 0..W {
                    let d2 = (x as f32 - mu[0]).powi(2) + (y as f32 - mu[1]).powi(2);
                    let g = a * (-0.5 * d2 / (r * r)).exp();
                    for c in 0..3 {
                        rgb[c * W * H + y * W + x] += g * col[c];
                    }
                }
            }
        }
        (
            RenderedImage {
                width: W,
                height: H,
                rgb,
                depth: vec![0.0; W * H],
                alpha: vec![1.0; W * H],
            },
            (),
        )
    }
    fn backward_view(
        &self,
        s: &Splats,
        cam: &Camera,
        st: &(),
        d: &[f32],
        d_planes: Planes,
    ) -> (SplatGrads, [f64; 6]) {
        let no_planes = d_planes.depth.is_none() && d_planes.alpha.is_none();
        assert!(
            no_planes,
            "the additive test renderer has no depth or alpha"
        );
        (self.backward_rgb(s, cam, st, d), [0.0; 6])
    }
}

impl Additive {
    fn backward_rgb(&self, s: &Splats, cam: &Camera, _: &(), d: &[f32]) -> SplatGrads {
        let n = s.len();
        let mut g = SplatGrads::zeros(n);
        for i in 0..n {
            let Some((mu, r, jac)) = project(cam, s.means[i], s.log_scales[i]) else {
                continue;
            };
            let a = sigmoid(s.opacity_logits[i]);
            let col: [f32; 3] = std::array::from_fn(|c| 0.5 + SH_C0 * s.sh_dc[i][c]);
            let (mut dmu, mut dr, mut da) = ([0.0f32; 2], 0.0f32, 0.0f32);
            for y in 0..H {
                for x in 0..W {
                    let (dx, dy) = (x as f32 - mu[0], y as f32 - mu[1]);
                    let e = (-0.5 * (dx * dx + dy * dy) / (r * r)).exp();
                    let gc: f32 = (0..3).map(|c| d[c * W * H + y * W + x] * col[c]).sum();
                    for c in 0..3 {
                        g.sh_dc[i][c] += d[c * W * H + y * W + x] * a * e * SH_C0;
                    }
                    da += gc * e;
                    dmu[0] += gc * a * e * dx / (r * r);
                    dmu[1] += gc * a * e * dy / (r * r);
                    dr += gc * a * e * (dx * dx + dy * dy) / (r * r * r);
                }
            }
            g.opacity_logits[i] = da * a * (1.0 - a);
            g.means[i] = std::array::from_fn(|k| dmu[0] * jac[0][k] + dmu[1] * jac[1][k]);
            g.log_scales[i] = [dr * r / 3.0; 3];
            g.screen_grad_norm[i] = (dmu[0].powi(2) + dmu[1].powi(2)).sqrt() * W as f32 / 2.0;
            g.radius[i] = 3.0 * r;
        }
        g
    }
}

fn truth() -> Splats {
    let mut s = random_splats(6, DVec3::ZERO, 0.5, 99);
    for (i, o) in s.opacity_logits.iter_mut().enumerate() {
        *o = 1.0 + i as f32 * 0.1;
        s.log_scales[i] = [0.12f32.ln(); 3];
    }
    s
}

#[test]
fn test_renderer_gradients_match_finite_differences() {
    let cam = cameras(3)[1];
    let s = truth();
    let target = Additive.render(&s, &cam, 0, [0.0; 3]).0.rgb;
    let mut p = s.clone();
    p.means[2][0] += 0.05;
    p.opacity_logits[1] -= 0.3;
    let loss = |q: &Splats| -> f64 {
        let r = Additive.render(q, &cam, 0, [0.0; 3]).0.rgb;
        r.iter()
            .zip(&target)
            .map(|(a, b)| 0.5 * ((a - b) as f64).powi(2))
            .sum()
    };
    let r = Additive.render(&p, &cam, 0, [0.0; 3]).0.rgb;
    let d: Vec<f32> = r.iter().zip(&target).map(|(a, b)| a - b).collect();
    let g = Additive.backward(&p, &cam, &(), &d);
    let h = 1e-3f32;
    let mut q = p.clone();
    q.means[2][0] += h;
    let lp = loss(&q);
    q.means[2][0] -= 2.0 * h;
    let fd = (lp - loss(&q)) / (2.0 * h as f64);
    assert!(
        (fd - g.means[2][0] as f64).abs() < 0.02 * fd.abs().max(1e-3),
        "{fd} vs {}",
        g.means[2][0]
    );
    let mut q = p.clone();
    q.opacity_logits[1] += h;
    let lp = loss(&q);
    q.opacity_logits[1] -= 2.0 * h;
    let fd = (lp - loss(&q)) / (2.0 * h as f64);
    assert!((fd - g.opacity_logits[1] as f64).abs() < 0.02 * fd.abs().max(1e-3));
}

#[test]
fn bounds_and_extent_follow_the_cameras() {
    let cams = cameras(5);
    let (c, half) = camera_bounds(&cams);
    assert!(c.length() < 1e-6, "{c}");
    assert!(half > 0.5 && half < 3.0, "{half}");
    let e = camera_extent(&cams);
    assert!(e > 0.0 && e < 3.3);
}

#[test]
fn training_reduces_the_loss_static_and_with_the_field() {
    let cams = cameras(6);
    let gt = truth();
    let views: Vec<View> = cams
        .iter()
        .enumerate()
        .map(|(k, c)| View {
            camera: *c,
            time: k as f32 / 5.0,
            rgb: Additive.render(&gt, c, 0, [0.0; 3]).0.rgb,
        })
        .collect();
    let mut s = TrainSettings {
        iterations: 300,
        static_iterations: 150,
        dssim_weight: 0.2,
        ..Default::default()
    };
    s.field.depth = 2;
    s.field.width = 16;
    s.densify.from_iter = 50;
    s.densify.interval = 50;
    s.densify.max_gaussians = 40;
    s.densify.grad_threshold = 1e-4;
    let (c, half) = camera_bounds(&cams);
    let init = random_splats(12, c, half.min(0.6), 3);
    let mut t = Trainer::new(s, init, camera_extent(&cams));
    let eval = |t: &Trainer| -> f64 {
        views
            .iter()
            .map(|v| {
                let f = t.render(&Additive, &v.camera, v.time);
                f.rgb
                    .iter()
                    .zip(&v.rgb)
                    .map(|(a, b)| (a - b).abs() as f64)
                    .sum::<f64>()
            })
            .sum()
    };
    let before = eval(&t);
    let mut saw_field = false;
    for _ in 0..300 {
        let info = t.step(&Additive, &views);
        assert!(info.loss.is_finite());
        saw_field |= info.field_on;
        assert!(info.gaussians <= 40);
    }
    let after = eval(&t);
    assert!(saw_field);
    assert!(after < 0.75 * before, "L1 {before} → {after}");
    assert!(t.field.params.iter().all(|v| v.is_finite()));
    assert_eq!(t.adam.groups[0].m.len(), 3 * t.splats.len());
}

#[test]
fn dynamic_only_leaves_static_gaussians_undeformed() {
    let mut init = random_splats(8, DVec3::ZERO, 0.5, 5);
    for k in 0..4 {
        init.dynamic[k] = false;
    }
    // A random head (not the default zero head) so the dynamic Gaussians move at once.
    let s = TrainSettings {
        static_iterations: 0,
        dynamic_only: true,
        field: gaussians::field::FieldSettings {
            zero_head_init: false,
            ..Default::default()
        },
        ..Default::default()
    };
    let t = Trainer::new(s, init.clone(), 1.0);
    let (d, _) = t.deformed(0.7);
    for k in 0..8 {
        let moved = d.means[k] != init.means[k];
        assert_eq!(moved, k >= 4, "Gaussian {k}");
    }
    let cams = cameras(2);
    let views: Vec<View> = cams
        .iter()
        .map(|c| View {
            camera: *c,
            time: 0.3,
            rgb: vec![0.5; 3 * W * H],
        })
        .collect();
    let mut t = t;
    let before = t.field.params.clone();
    let info = t.step(&Additive, &views);
    assert!(info.field_on && info.loss.is_finite());
    assert_ne!(before, t.field.params);
}

#[test]
fn run_stops_on_the_flag_and_counts_phases() {
    use std::sync::atomic::{AtomicBool, Ordering};
    let cams = cameras(3);
    let views: Vec<View> = cams
        .iter()
        .map(|c| View {
            camera: *c,
            time: 0.5,
            rgb: Additive.render(&truth(), c, 0, [0.0; 3]).0.rgb,
        })
        .collect();
    // No static split: with every view at one time the field moves nothing, the split
    // (at 1 px by default) would drop it and count the last steps as static.
    let mut s = TrainSettings {
        iterations: 40,
        static_iterations: 10,
        static_tolerance_px: 0.0,
        ..Default::default()
    };
    s.field.width = 8;
    let mut t = Trainer::new(s, random_splats(10, DVec3::ZERO, 0.5, 1), 1.0);
    let stop = AtomicBool::new(false);
    let mut seen = 0;
    let sum = gaussians::train::run(&mut t, &Additive, &views, &stop, |info| {
        seen += 1;
        if info.iteration == 25 {
            stop.store(true, Ordering::Relaxed);
        }
    });
    assert!(sum.interrupted);
    assert_eq!((sum.iterations, seen), (25, 25));
    // 10 static iterations, then the field is on.
    assert_eq!((sum.static_steps, sum.deform_steps), (10, 15));
    stop.store(false, Ordering::Relaxed);
    let sum = gaussians::train::run(&mut t, &Additive, &views, &stop, |_| {});
    assert!(!sum.interrupted);
    assert_eq!(sum.iterations, 40);
    assert_eq!((sum.static_steps, sum.deform_steps), (0, 15));
}

/// With the default zero head, switching the field on leaves the model exactly as the
/// static phase left it (no jump in the loss at the switch).
#[test]
fn default_field_starts_as_the_identity() {
    let init = random_splats(16, DVec3::ZERO, 0.5, 9);
    let s = TrainSettings {
        static_iterations: 0,
        ..Default::default()
    };
    let t = Trainer::new(s, init.clone(), 1.0);
    assert!(t.field_on());
    for time in [0.0, 0.3, 1.0] {
        let (d, _) = t.deformed(time);
        assert_eq!(d.means, init.means);
        for (a, b) in d
            .log_scales
            .iter()
            .flatten()
            .zip(init.log_scales.iter().flatten())
        {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
    }
}

/// Grey views from `cams` at times 0, 1, 2, ….
fn grey_views(cams: &[Camera]) -> Vec<View> {
    cams.iter()
        .enumerate()
        .map(|(k, c)| View {
            camera: *c,
            time: k as f32,
            rgb: vec![0.5; 3 * W * H],
        })
        .collect()
}

/// The static/dynamic split happens once, at its iteration, flags the Gaussians the field
/// moves by at most the tolerance, and freezes them at their canonical parameters; when
/// it finds every Gaussian static, the model drops its field.
#[test]
fn static_split_flags_and_freezes_the_gaussians_the_field_barely_moves() {
    let views = grey_views(&cameras(2));
    let run = |tolerance_px: f32| {
        let s = TrainSettings {
            iterations: 8,
            static_iterations: 0,
            static_tolerance_px: tolerance_px,
            static_split_at: 0.5,
            field: gaussians::field::FieldSettings {
                zero_head_init: false,
                width: 8,
                ..Default::default()
            },
            // The split alone (no sizing at the run's end).
            size: gaussians::train::sizing::SizeSettings {
                tolerance_db: 0.0,
                ..Default::default()
            },
            ..Default::default()
        };
        let mut t = Trainer::new(s, random_splats(10, DVec3::ZERO, 0.5, 4), 1.0);
        assert_eq!(t.static_split_iteration(), Some(4));
        for it in 0..8 {
            assert_eq!(t.split.is_some(), it >= 4, "iteration {it}");
            t.step(&Additive, &views);
        }
        t
    };
    // Every Gaussian moves under a random field: a tiny tolerance keeps all dynamic.
    let t = run(1e-6);
    let sp = t.split.unwrap();
    assert_eq!((sp.iteration, sp.dynamic, sp.static_), (4, 10, 0));
    assert!(t.settings.dynamic_only && t.splats.dynamic.iter().all(|&d| d));
    // A huge tolerance flags all static: the model keeps no field at all.
    let t = run(1e9);
    let sp = t.split.unwrap();
    assert_eq!((sp.dynamic, sp.static_), (0, 10));
    assert!(!t.field_on() && !t.settings.dynamic_only && t.splats.dynamic.is_empty());
    assert!(gaussians::model::Model::from(&t).field.is_none());
    let (d, _) = t.deformed(0.7);
    assert_eq!(d.means, t.splats.means);
    assert_eq!(d.rotations, t.splats.rotations);
}

/// The split measures motion from where the field puts each Gaussian at the middle of
/// the recording: a shift the field applies at every time alike is no motion, and the
/// Gaussians it calls static are baked where the field put them (not sent back to their
/// canonical places); one the field moves over time stays dynamic and canonical.
#[test]
fn the_split_bakes_a_constant_shift_and_keeps_moving_gaussians_dynamic() {
    use gaussians::field::{FieldSettings, Mlp};
    use gaussians::train::static_split;
    let views = grey_views(&cameras(2));
    let settings = FieldSettings {
        width: 8,
        depth: 2,
        ..FieldSettings::default()
    };
    let mut mlp = Mlp::<f32>::new(settings, 1);
    mlp.zero_head();
    let head = *mlp.layers.last().unwrap();
    mlp.params[head.bias] = 0.05; // δx = (0.05, 0, 0) at every time
    let splats = random_splats(10, DVec3::ZERO, 0.5, 4);
    let (m, sum) = static_split::decide(&mlp, &splats, &views, 0.01, 7);
    assert_eq!((sum.iteration, sum.dynamic, sum.static_), (7, 0, 10));
    for (a, b) in m.means.iter().zip(&splats.means) {
        assert!((a[0] - (b[0] + 0.05)).abs() < 1e-6 && a[1] == b[1] && a[2] == b[2]);
    }
    // The raw time (the encoding's first input after the 3 + 3·2·pos_freqs position
    // columns) drives δy: every Gaussian moves 0.1 over the recording, well over 0.01 px.
    let t_col = 3 * (1 + 2 * settings.pos_freqs);
    // Hidden unit 0 of each layer passes the time alone: h = relu(relu(t)) = t.
    for l in [mlp.layers[0], mlp.layers[1]] {
        for i in 0..l.fan_in {
            mlp.params[l.weight + i * l.fan_out] = 0.0;
        }
        mlp.params[l.bias] = 0.0;
    }
    let (l0, l1) = (mlp.layers[0], mlp.layers[1]);
    mlp.params[l0.weight + t_col * l0.fan_out] = 1.0;
    mlp.params[l1.weight] = 1.0;
    mlp.params[head.weight + 1] = 0.1;
    let (m, sum) = static_split::decide(&mlp, &splats, &views, 0.01, 7);
    assert_eq!((sum.dynamic, sum.static_), (10, 0), "{sum:?}");
    assert_eq!(m.means, splats.means);
}

/// `L_track` through the training step: a faint Gaussian (no photometric pull to speak
/// of) whose track moves across the views ends up where its track saw it in each view,
/// its trajectory learning the motion its canonical centre cannot give.
#[test]
fn a_tracked_gaussian_is_pulled_to_its_track_in_every_view() {
    use gaussians::tracks::loss::TrackTerm;
    let cams = cameras(5);
    let times: Vec<f32> = (0..5).map(|k| k as f32 / 4.0).collect();
    // The track: a point moving on a line, seen through the view cameras.
    let path = |t: f32| DVec3::new(0.3, -0.1, 0.2) + DVec3::new(0.4, 0.2, -0.1) * (t as f64 - 0.5);
    let seen: Vec<_> = (cams.iter().zip(&times))
        .map(|(c, &t)| Some(c.project_world(path(t)).unwrap().0))
        .collect();
    let views: Vec<View> = (cams.iter().zip(&times))
        .map(|(c, &t)| View {
            camera: *c,
            time: t,
            rgb: vec![0.0; 3 * W * H],
        })
        .collect();
    for into_field in [true, false] {
        let mut s = random_splats(1, DVec3::ZERO, 0.1, 3);
        s.opacity_logits[0] = -12.0;
        // A tracked Gaussian starts on its lifted trajectory, never a row of zeros (a
        // still Gaussian's, which no gradient moves).
        s.motion = vec![[1e-3, 0.0, 0.0, 0.0, 0.0, 0.0]];
        s.track = vec![0];
        let mut settings = TrainSettings {
            position_lr_init: 0.01,
            position_lr_final: 0.001,
            ..fixed_gaussians(600)
        };
        settings.tracks.weight = 1.0;
        settings.tracks.into_field = into_field;
        let error = |t: &Trainer| {
            (views.iter().zip(&seen))
                .map(|(v, p)| {
                    let (d, _) = t.deformed(v.time);
                    let x = DVec3::from(d.means[0].map(f64::from));
                    (v.camera.project_world(x).unwrap().0 - p.unwrap()).length()
                })
                .fold(0.0, f64::max)
        };
        let mut t = Trainer::new(settings, s, 1.0);
        t.tracks = TrackTerm::new(vec![seen.clone()]);
        let before = error(&t);
        for _ in 0..600 {
            t.step(&Additive, &views);
        }
        let after = error(&t);
        assert!(before > 3.0, "the start is {before} px off: not a test");
        assert!(
            after < 0.1,
            "{after} px off its track after training (from {before})"
        );
        assert!(
            t.tracks.last.1 == 1 && t.tracks.last.0 < 1e-2,
            "{:?}",
            t.tracks.last
        );
    }
}

/// A still Gaussian (its trajectory a row of zeros) stays still under training, even
/// where the frames show it moving and a trajectory would fit them better; a moving one
/// beside it has its trajectory trained. Were the still rows trained, every Gaussian of
/// the background could follow its own path to fit each train view apart.
#[test]
fn training_moves_only_the_gaussians_with_a_trajectory() {
    let cams = cameras(6);
    let mut gt = truth();
    // In the frames every Gaussian moves.
    gt.motion = (0..gt.len())
        .map(|i| [0.3, -0.1 * i as f32, 0.2, 0.1, 0.0, -0.1])
        .collect();
    let views: Vec<View> = (cams.iter().enumerate())
        .map(|(k, c)| {
            let t = k as f32 / 5.0;
            let mut at = gt.clone();
            gaussians::motion::advance(&gt, t, &mut at);
            at.motion.clear();
            View {
                camera: *c,
                time: t,
                rgb: Additive.render(&at, c, 0, [0.0; 3]).0.rgb,
            }
        })
        .collect();
    let mut init = gt.clone();
    let n = init.len();
    for (i, m) in init.motion.iter_mut().enumerate() {
        // even: still; odd: a trajectory off the truth
        *m = if i % 2 == 0 {
            [0.0; 6]
        } else {
            m.map(|v| 0.5 * v)
        };
    }
    let mut t = Trainer::new(fixed_gaussians(200), init.clone(), camera_extent(&cams));
    for _ in 0..200 {
        t.step(&Additive, &views);
    }
    assert_eq!(t.splats.len(), n);
    for i in 0..n {
        let (got, was) = (t.splats.motion[i], init.motion[i]);
        if i % 2 == 0 {
            assert_eq!(got, [0.0; 6], "still Gaussian {i} was given a trajectory");
        } else {
            let moved: f32 = (0..6).map(|k| (got[k] - was[k]).abs()).sum();
            assert!(
                moved > 1e-3,
                "Gaussian {i}'s trajectory was not trained: {got:?}"
            );
        }
    }
}
