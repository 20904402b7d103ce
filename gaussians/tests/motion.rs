//! Per-Gaussian trajectories (`gaussians::motion`, `Splats::motion`): the rendered centre
//! against the closed form `μ + v·τ + a·τ²` in f64, the trainer's gradient against
//! central finite differences of a rendered loss, the model files' round trip, and the
//! column following the Gaussians through gathering and growth.

mod raster_common;

use gaussians::Planes;
use gaussians::model::{Model, motion_file};
use gaussians::motion::{self, T0};
use gaussians::raster::TileRasterizer;
use gaussians::train::init::random_splats;
use gaussians::train::{TrainSettings, Trainer};
use rand::{RngExt, SeedableRng};

fn random_motion(n: usize, seed: u64, scale: f32) -> Vec<[f32; 6]> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| std::array::from_fn(|_| rng.random_range(-scale..scale)))
        .collect()
}

/// Two Gaussians side by side in front of the default camera, of colour `sh_dc`.
fn side_by_side(sh_dc: [f32; 3]) -> gaussians::Splats {
    let mut s = gaussians::Splats::default();
    for x in [-0.3f32, 0.3] {
        s.push(gaussians::Gaussian::isotropic(
            [x, 0.0, -3.0],
            -2.0,
            2.0,
            sh_dc,
        ));
    }
    s
}

#[test]
fn a_centre_follows_its_quadratic_path() {
    let mut s = random_splats(50, glam::DVec3::ZERO, 0.5, 1);
    s.motion = random_motion(50, 2, 0.4);
    for t in [0.0f32, 0.3, T0, 1.0] {
        let mut moved = s.clone();
        motion::advance(&s, t, &mut moved);
        let means = moved.means;
        let tau = t as f64 - 0.5;
        let rows = means.iter().zip(s.means.iter().zip(&s.motion));
        for (i, (got, (mu, m))) in rows.enumerate() {
            for k in 0..3 {
                let want = mu[k] as f64 + m[k] as f64 * tau + m[3 + k] as f64 * tau * tau;
                assert!((got[k] as f64 - want).abs() < 1e-6, "t {t}, Gaussian {i}");
            }
        }
    }
    // No trajectories: nothing moves.
    let still = random_splats(5, glam::DVec3::ZERO, 0.5, 1);
    let mut moved = still.clone();
    motion::advance(&still, 0.9, &mut moved);
    assert_eq!(moved.means, still.means);
}

#[test]
fn a_gaussian_renders_only_within_its_life_and_as_before_there() {
    // Two Gaussians side by side; the second lives over [0.25, 0.5). Inside its life the
    // render is the one without lives; outside, the one of the first Gaussian alone.
    use gaussians::{Rasterizer, TileRasterizer};
    let cam = scene::Camera {
        intrinsics: scene::Intrinsics::from_fov_x(32, 32, 1.0),
        cam_to_world: scene::Pose::default(),
    };
    let both = side_by_side([0.8, 0.1, -0.5]);
    let mut first = gaussians::Splats::default();
    first.push(both.get(0));
    let mut lived = both.clone();
    lived.life = vec![gaussians::splats::ALWAYS, [0.25, 0.5]];
    let r = TileRasterizer;
    let render = |s: &gaussians::Splats| r.render(s, &cam, 0, [0.0; 3]).0.rgb;
    let at = |t: f32| {
        let mut s = lived.clone();
        motion::advance(&lived, t, &mut s);
        render(&s)
    };
    let (all, one) = (render(&both), render(&first));
    assert_ne!(all, one, "the second Gaussian shows");
    for t in [0.25f32, 0.3, 0.49] {
        assert_eq!(at(t), all, "t = {t}: alive");
    }
    for t in [0.0f32, 0.2, 0.5, 0.9] {
        let diff = at(t)
            .iter()
            .zip(&one)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(diff < 1e-6, "t = {t}: hidden, differs by {diff}");
    }
}

/// With windows sharing their end frames (`handover = "frame"`): a shared frame is drawn
/// by either window's copies, half of its views each, and the windows hold every frame
/// (by `windows`, whose lives end exactly at the shared frame).
#[test]
fn the_shared_frame_clock_draws_either_window_half_the_time() {
    use gaussians::tracks::{Handover, init::windows};
    let times = [0.0, 0.2, 0.4, 0.6, 0.8, 1.0];
    let w = windows(&times, 3, Handover::Frame);
    let n = 100_000;
    for k in 0..times.len() {
        let t = times[k] as f32;
        let prev = k.checked_sub(1).map(|j| times[j] as f32);
        let mut drawn = vec![0usize; w.len()];
        for i in 0..n {
            let l = motion::life_clock_shared(t, prev, (i as f32 + 0.5) / n as f32);
            let alive: Vec<usize> = (0..w.len())
                .filter(|&j| motion::alive(w[j].life, l))
                .collect();
            assert_eq!(alive.len(), 1, "frame {k}: one window alive at {l}");
            assert!(
                w[alive[0]].frames.contains(&k),
                "frame {k} drawn by {:?}",
                w[alive[0]]
            );
            drawn[alive[0]] += 1;
        }
        let shared = w.iter().filter(|x| x.frames.contains(&k)).count() == 2;
        let most = *drawn.iter().max().unwrap() as f64 / n as f64;
        assert!(
            (most - if shared { 0.5 } else { 1.0 }).abs() < 1e-3,
            "frame {k}: {drawn:?}"
        );
    }
}

/// A view drawn with the lives read at another time: the centres where `t` puts them,
/// the Gaussians shown those alive at `life_t`.
#[test]
fn advance_living_reads_the_lives_at_its_own_time() {
    let mut s = side_by_side([0.5; 3]);
    s.motion = vec![[0.0; 6], [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]];
    s.life = vec![[0.0, 0.5], [0.5, 1.0]];
    let mut out = s.clone();
    motion::advance_living(&s, 0.4, 0.6, &mut out);
    let hidden = |o: &gaussians::Splats, i: usize| o.opacity_logits[i] < -30.0;
    assert!(hidden(&out, 0) && !hidden(&out, 1));
    assert!(
        (out.means[1][0] - (0.3 + (0.4 - T0))).abs() < 1e-6,
        "{:?}",
        out.means[1]
    );
    let mut same = s.clone();
    motion::advance(&s, 0.4, &mut same);
    assert!(!hidden(&same, 0) && hidden(&same, 1));
    assert_eq!(same.means, out.means);
}

/// Without a field, the trainer's gradient of the trajectories matches central
/// differences in f64 of `Σ w·rgb` rendered by the f64 reference rasterizer at the
/// centres `μ + v·τ + a·τ²` (the scene of `raster_grad.rs`: Gaussians a few pixels to
/// ten wide, so the loss is smooth), every parameter of every Gaussian with a trajectory;
/// the still ones (rows of zeros) get none.
#[test]
fn the_trainer_gradient_of_the_trajectories_matches_finite_differences() {
    use gaussians::raster::reference::{self, Gaussians64};
    use raster_common::Rng;
    let mut rng = Rng(77);
    let mut splats = raster_common::random_splats(&mut rng, raster_common::SMOOTH);
    let n = splats.len();
    splats.motion = random_motion(n, 4, 0.3);
    // Every third Gaussian still: a row of zeros, whose trajectory gets no gradient.
    let still = |i: usize| i % 3 == 1;
    (0..n)
        .filter(|&i| still(i))
        .for_each(|i| splats.motion[i] = [0.0; 6]);
    let s = TrainSettings {
        deform: false,
        ..TrainSettings::default()
    };
    let tr = Trainer::new(s, splats, 1.0);
    let cam = raster_common::smooth_camera();
    let (w, h) = (cam.intrinsics.width, cam.intrinsics.height);
    let t = 0.9f32;
    let weights: Vec<f64> = (0..3 * w * h).map(|_| rng.uni(-1.0, 1.0)).collect();
    let w32: Vec<f32> = weights.iter().map(|&x| x as f32).collect();
    let r = TileRasterizer;
    let v = tr.render_view(&r, &cam, t);
    let g = tr.view_backward(&r, &v, &w32, Planes::NONE, None);
    assert_eq!(g.splats.motion.len(), n);
    let bg = tr.settings.background.map(f64::from);
    let tau = t as f64 - 0.5;
    let loss = |motion: &[[f64; 6]]| -> f64 {
        let mut g64 = Gaussians64::from(&tr.splats);
        for (m, mv) in g64.means.iter_mut().zip(motion) {
            (0..3).for_each(|k| m[k] += mv[k] * tau + mv[3 + k] * tau * tau);
        }
        let f = reference::render(&g64, &cam, 0, bg);
        f.rgb.iter().zip(&weights).map(|(a, b)| a * b).sum()
    };
    let base: Vec<[f64; 6]> = tr.splats.motion.iter().map(|m| m.map(f64::from)).collect();
    let (mut num, mut den) = (0.0f64, 0.0f64);
    const EPS: f64 = 1e-6;
    for i in 0..n {
        if still(i) {
            assert_eq!(
                g.splats.motion[i], [0.0; 6],
                "a still Gaussian {i} got a trajectory"
            );
            continue;
        }
        for k in 0..6 {
            let mut m = base.clone();
            m[i][k] += EPS;
            let lp = loss(&m);
            m[i][k] -= 2.0 * EPS;
            let fd = (lp - loss(&m)) / (2.0 * EPS);
            num += (g.splats.motion[i][k] as f64 - fd).powi(2);
            den += fd * fd;
        }
    }
    assert!(
        den.sqrt() > 1e-3,
        "the view must see the Gaussians move: {}",
        den.sqrt()
    );
    let rel = num.sqrt() / den.sqrt();
    assert!(
        rel < 1e-3,
        "relative error {rel:.2e} against f64 central differences"
    );
}

#[test]
fn a_saved_model_keeps_its_trajectories_and_moves_them() {
    let mut splats = random_splats(30, glam::DVec3::ZERO, 0.5, 7);
    splats.motion = random_motion(30, 8, 0.5);
    splats.life = (0..30).map(|i| [i as f32 / 40.0, 0.9]).collect();
    splats.life[3] = gaussians::splats::ALWAYS;
    let model = Model {
        splats,
        field: None,
        info: Default::default(),
    };
    let dir = tempfile::tempdir().unwrap();
    model.save(dir.path()).unwrap();
    assert!(dir.path().join(motion_file::MOTION_FILE).is_file());
    let back = Model::load(dir.path()).unwrap();
    assert_eq!(back.splats.motion, model.splats.motion);
    assert_eq!(back.splats.life, model.splats.life);
    let at = back.at(0.2);
    let tau = 0.2f64 - 0.5;
    for i in 0..30 {
        let (m, mu) = (model.splats.motion[i], model.splats.means[i]);
        for k in 0..3 {
            let want = mu[k] as f64 + m[k] as f64 * tau + m[3 + k] as f64 * tau * tau;
            assert!((at.means[i][k] as f64 - want).abs() < 1e-6);
        }
    }
    // A file of the wrong shape is refused, naming it.
    let bad = dir.path().join("bad.safetensors");
    motion_file::write(&bad, &model.splats.motion[..29], &[]).unwrap();
    let e = motion_file::read(&bad, 30).unwrap_err().to_string();
    assert!(
        e.contains("bad.safetensors") && e.contains("[30, 6]"),
        "{e}"
    );
}

#[test]
fn trajectories_follow_their_gaussians() {
    let mut s = random_splats(10, glam::DVec3::ZERO, 0.5, 9);
    s.motion = random_motion(10, 10, 0.5);
    let kept = gaussians::train::sizing::gather(&s, &[1, 4, 7]);
    assert_eq!(kept.motion, vec![s.motion[1], s.motion[4], s.motion[7]]);
    let mut grown = s.clone();
    grown.push(s.get(3));
    assert_eq!(grown.motion.len(), 11);
    assert_eq!(grown.motion[10], [0.0; 6], "a new Gaussian starts still");
    let mut none = random_splats(3, glam::DVec3::ZERO, 0.5, 9);
    none.push(s.get(0));
    assert!(none.motion.is_empty(), "no column appears by itself");
}
