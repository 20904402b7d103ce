//! What only shows when the joint trainer runs: the scene half of `L_event` after the
//! PoseNet's warm-up (every other test trains fewer iterations than `posenet_warmup`),
//! the ablation switches reaching the trainer (not only listed in `--help`), and the
//! contrast modes `given`, `learn` and `estimate_learn` through a whole run.

mod fixture;

use deform::stage::{TrainArgs, TrainOutcome};
use deform::trainer::JointStep;
use fixture::{Fixture, Variant, build};
use gaussians::model::Model;
use serde_json::Value;

/// `deform train` on the fixture with `settings` (TOML) and the switches of `args`,
/// into `<dir>/<name>`; its report too.
fn train_with(
    fx: &Fixture,
    name: &str,
    settings: &str,
    args: TrainArgs,
) -> (TrainOutcome, Vec<JointStep>, Value) {
    let (o, steps) = fx.train_with(name, settings, args).unwrap();
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(o.out.join("report.json")).unwrap()).unwrap();
    (o, steps, report)
}

/// Largest distance between the canonical centres of two saved models.
fn centre_gap(a: &std::path::Path, b: &std::path::Path) -> f64 {
    let (a, b) = (Model::load(a).unwrap(), Model::load(b).unwrap());
    assert_eq!(a.splats.len(), b.splats.len());
    a.splats
        .means
        .iter()
        .zip(&b.splats.means)
        .map(|(p, q)| {
            (0..3)
                .map(|c| (p[c] - q[c]) as f64)
                .map(|d| d * d)
                .sum::<f64>()
        })
        .fold(0.0, f64::max)
        .sqrt()
}

const BASE: &str = "iterations = 16\nlog_every = 1\nrebind_every = 100\ndensify = false\n\
                    [schedule]\ngamma2_max = 0.0\n";

#[test]
fn after_the_posenet_warm_up_the_event_loss_moves_the_scene() {
    let fx = build(Variant::Normal);
    let run = |name: &str, extra: &str| {
        let (o, steps, _) =
            train_with(&fx, name, &format!("{extra}\n{BASE}"), TrainArgs::default());
        assert!(
            steps.iter().any(|s| s.l_event > 0.0),
            "{name}: no event loss"
        );
        o.out
    };
    // γ1 > 0 all along, the scene held during a warm-up longer than the run; the same
    // with the warm-up over at once; and without the event loss.
    let held = run("held", "posenet_warmup = 1000");
    let moved = run("moved", "posenet_warmup = 0");
    let (o, steps, _) = train_with(
        &fx,
        "no-event",
        &format!("posenet_warmup = 0\n{BASE}"),
        TrainArgs {
            no_event_loss: true,
            ..TrainArgs::default()
        },
    );
    assert!(
        steps.iter().all(|s| s.l_event == 0.0),
        "γ1 = 0 still logs an event loss"
    );
    let by_events = centre_gap(&held, &moved);
    let by_rgb_only = centre_gap(&held, &o.out);
    eprintln!("scene moved by L_event {by_events:.3e}, held vs no event loss {by_rgb_only:.3e}");
    // During the warm-up L_event moves only the camera: the scene trains as without it.
    assert!(
        by_rgb_only <= 0.05 * by_events && by_events > 1e-5,
        "scene moved by L_event {by_events}, held scene vs no event loss {by_rgb_only}"
    );
}

#[test]
fn the_ablation_switches_reach_the_trainer() {
    let fx = build(Variant::Normal);
    let auto = "iterations = 6\nlog_every = 1\nrebind_every = 3\nposenet_warmup = 0\n\
                [schedule]\ngamma2_iters = 0.0\n";
    // By default the motion term is off at these 10 fps frames (100 ms apart, under
    // 1/9 s): resolved in the report, never computed, the bindings never rebuilt.
    let (_, steps, r) = train_with(&fx, "auto", auto, TrainArgs::default());
    assert_eq!(r["settings"]["schedule"]["motion"], "off", "{r}");
    assert!(steps.iter().all(|s| s.l_motion == 0.0 && s.bound == 0));
    assert!(steps.iter().any(|s| s.l_event > 0.0));
    assert_eq!(r["rebinds"], 0, "{r}");

    let settings = &format!("{auto}motion = \"on\"\n");
    let (full, steps, r) = train_with(&fx, "full", settings, TrainArgs::default());
    assert_eq!(r["settings"]["schedule"]["motion"], "on", "{r}");
    assert!(r["rebinds"].as_u64().unwrap() >= 2, "{r}");
    assert!(steps.iter().any(|s| s.l_event > 0.0) && steps.iter().any(|s| s.l_motion > 0.0));
    assert!(full.out.join("posenet.safetensors").is_file());
    assert_eq!(r["settings"]["posenet"], true);

    let (_, steps, r) = train_with(
        &fx,
        "no-motion",
        settings,
        TrainArgs {
            no_motion_loss: true,
            ..TrainArgs::default()
        },
    );
    assert!(
        steps.iter().all(|s| s.l_motion == 0.0),
        "motion loss still on"
    );
    assert!(steps.iter().any(|s| s.l_event > 0.0));
    assert_eq!(r["settings"]["schedule"]["gamma2_max"], 0.0);

    let (o, steps, r) = train_with(
        &fx,
        "no-posenet",
        settings,
        TrainArgs {
            no_posenet: true,
            ..TrainArgs::default()
        },
    );
    assert!(!o.out.join("posenet.safetensors").exists());
    assert_eq!(r["settings"]["posenet"], false);
    assert!(steps.iter().any(|s| s.l_event > 0.0));

    // The event term on a quarter of the image: it still trains, and not as the whole.
    let tiles = format!("event_tiles = 2\n{settings}");
    let (o, steps, r) = train_with(&fx, "tiles", &tiles, TrainArgs::default());
    assert_eq!(r["settings"]["event_tiles"], 2);
    assert!(
        steps.iter().any(|s| s.l_event > 0.0),
        "no event loss on tiles"
    );
    let gap = centre_gap(&full.out, &o.out);
    assert!(gap > 1e-6, "tiles trained as the whole image ({gap:.2e})");

    // At half resolution: it trains, and not as at full resolution.
    let half = format!("event_downsample = 2\n{settings}");
    let (o, steps, r) = train_with(&fx, "half", &half, TrainArgs::default());
    assert_eq!(r["settings"]["event_downsample"], 2);
    assert!(
        steps.iter().any(|s| s.l_event > 0.0),
        "no event loss at half resolution"
    );
    let gap = centre_gap(&full.out, &o.out);
    assert!(gap > 1e-6, "half resolution trained as full ({gap:.2e})");
}

#[test]
fn each_contrast_mode_runs_through_the_trainer() {
    let fx = build(Variant::Normal);
    let run = |mode: &str| {
        let settings = format!(
            "iterations = 8\nlog_every = 1\nrebind_every = 100\nposenet_warmup = 0\n\
             contrast = \"{mode}\"\ncontrast_threshold = 0.25\ncontrast_lr = 0.05\n"
        );
        let (_, steps, r) = train_with(&fx, mode, &settings, TrainArgs::default());
        let c = r["contrast"].clone();
        assert_eq!(c["mode"], mode, "{c}");
        (steps, c)
    };
    let (steps, c) = run("given");
    assert_eq!(
        (c["initial"].as_f64(), c["last"].as_f64()),
        (Some(0.25), Some(0.25)),
        "{c}"
    );
    assert!(steps.iter().all(|s| s.contrast == 0.25));

    let (steps, c) = run("learn");
    assert_eq!(c["initial"].as_f64(), Some(0.25), "{c}");
    let last = c["last"].as_f64().unwrap();
    assert!(last != 0.25 && last.is_finite() && last > 0.0, "learn: {c}");
    assert_eq!(steps.last().unwrap().contrast, last);

    let (_, c) = run("estimate_learn");
    let estimate = c["estimate"]["c"].as_f64();
    let initial = c["initial"].as_f64().unwrap();
    match estimate {
        Some(e) => assert_eq!(initial, e, "starts from the estimate: {c}"),
        None => assert_eq!(initial, 0.25, "no estimate: starts from the given C: {c}"),
    }
    let last = c["last"].as_f64().unwrap();
    assert!(last != initial && last.is_finite() && last > 0.0, "{c}");
}

/// The trainer's rebinding (on the deformed Gaussians it holds) and the `assoc` stage on
/// the model the joint training saved (its field moved by the training) bind the same
/// events to the same Gaussians; and none to a Gaussian outside its life.
#[test]
fn rebinding_agrees_with_the_assoc_stage_on_the_deformed_model() {
    use deform::inputs::Inputs;
    use deform::settings::DeformSettings;
    use deform::trainer::JointTrainer;
    let fx = build(Variant::Normal);
    let (o, _, _) = train_with(
        &fx,
        "trained",
        "iterations = 12\nlog_every = 1\nrebind_every = 100\nposenet_warmup = 0\n",
        TrainArgs::default(),
    );
    let s = DeformSettings::default();
    // The saved field moves the Gaussians (else this would compare canonical models).
    let m = Model::load(&o.out).unwrap();
    let (a, b) = (m.at(0.0), m.at(1.0));
    let moved = a
        .means
        .iter()
        .zip(&b.means)
        .map(|(p, q)| (0..3).map(|c| (p[c] - q[c]).abs()).fold(0.0f32, f32::max))
        .fold(0.0f32, f32::max);
    assert!(
        moved > 1e-6,
        "the trained field does not move the Gaussians"
    );
    let stage_out = fx.dir.path().join("assoc-again");
    assoc::stage::run(&fx.scene, &o.out, &stage_out, &s.assoc, false, |_, _| {}).unwrap();
    let from_stage = assoc::read_assoc(&stage_out.join("assoc.bin")).unwrap();

    // The saved model as a warm-up directory (the joint stage's settings.toml is its
    // own; the trainer reads the warm-up's).
    let as_warmup = fx.dir.path().join("as-warm-up");
    copy_dir(&o.out, &as_warmup);
    std::fs::copy(
        fx.model.join("settings.toml"),
        as_warmup.join("settings.toml"),
    )
    .unwrap();
    let d = Inputs::load(&fx.scene, &as_warmup, &fx.flows, &stage_out, &s).unwrap();
    let mut tr = JointTrainer::new(&d, s);
    tr.bindings.clear(); // what the trainer loaded: the rebinding must make them anew
    tr.rebind(&gaussians::TileRasterizer, &d);
    assert_eq!(tr.bindings.len(), from_stage.len());
    let mut bound = 0;
    for (i, (r, f)) in tr.bindings.iter().zip(&from_stage).enumerate() {
        let b = &f.bindings;
        assert_eq!(r.offsets, b.offsets, "frame {i}: offsets");
        assert_eq!(r.events, b.events, "frame {i}: events");
        let worst = r
            .weights
            .iter()
            .zip(&b.weights)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        assert!(worst <= 1e-6, "frame {i}: weights differ by {worst}");
        bound += b.bound();
    }
    assert!(bound > 0, "nothing bound: the comparison is empty");

    // Lives (`Splats::life`): every other Gaussian exists from the recording's middle
    // on. The rebinding binds no event to one outside its life (it is not drawn then),
    // where, alive, some of them were bound at those frames above.
    let n = tr.inner.splats.len();
    let late = |g: usize| g.is_multiple_of(2);
    let was_bound: Vec<Vec<bool>> = (tr.bindings.iter())
        .map(|b| (0..n).map(|g| !b.of(g).0.is_empty()).collect())
        .collect();
    tr.inner.splats.motion = vec![[0.0; 6]; n];
    tr.inner.splats.life = (0..n)
        .map(|g| {
            if late(g) {
                [0.5, f32::MAX]
            } else {
                gaussians::splats::ALWAYS
            }
        })
        .collect();
    tr.rebind(&gaussians::TileRasterizer, &d);
    let (mut dead_before, mut alive_after) = (0, 0);
    for (i, (b, was)) in tr.bindings.iter().zip(&was_bound).enumerate() {
        let t = d.views[i].time;
        for g in (0..n).filter(|&g| late(g)) {
            let now = !b.of(g).0.is_empty();
            if t < 0.5 {
                assert!(
                    !now,
                    "frame {i} (t = {t}): Gaussian {g} bound outside its life"
                );
                dead_before += usize::from(was[g]);
            } else {
                alive_after += usize::from(now);
            }
        }
    }
    assert!(
        dead_before > 0,
        "no Gaussian outside its life was bound when alive"
    );
    assert!(
        alive_after > 0,
        "the Gaussians within their lives bind nothing"
    );
    assert_eq!(tr.fallbacks.rebind_frames_unbound, 0);

    // Every Gaussian born at the middle: the frames before it have nothing to bind, and
    // the report counts each of them (once per rebinding) instead of hiding it.
    tr.inner.splats.life = vec![[0.5, f32::MAX]; n];
    tr.rebind(&gaussians::TileRasterizer, &d);
    let early = d.views.iter().filter(|v| v.time < 0.5).count();
    assert!(
        early > 0 && early < d.views.len(),
        "{early} frames before the middle"
    );
    assert_eq!(tr.fallbacks.rebind_frames_unbound, early as u64);
    for (i, b) in tr
        .bindings
        .iter()
        .enumerate()
        .filter(|(i, _)| d.views[*i].time < 0.5)
    {
        assert_eq!(b.bound(), 0, "frame {i}: bound with no Gaussian alive");
    }
}

fn copy_dir(from: &std::path::Path, to: &std::path::Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            copy_dir(&p, &to.join(e.file_name()));
        } else {
            std::fs::copy(&p, to.join(e.file_name())).unwrap();
        }
    }
}
