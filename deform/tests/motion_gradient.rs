//! The motion term's gradient as the joint step assembles it (the part on `x(t0)` taken
//! back with the view's RGB gradient, the part on `x(t1)` through a second field pass)
//! against central differences of `L_motion` itself, along several directions in the
//! canonical centres, in the field's weights and in the PoseNet's weights (through the
//! corrected camera's velocity in `F_ego`): each the normalised gradient plus a random
//! unit vector, so an error orthogonal to the gradient shows too. The kernels are checked in f64 in the
//! unit tests; this checks their assembly in the f32 trainer.

mod fixture;

use deform::inputs::Inputs;
use deform::settings::{DeformSettings, FlowForm};
use deform::trainer::JointTrainer;
use fixture::{Rng, Variant, build};
use gaussians::TileRasterizer;

/// Directions `ĝ + u` (ĝ the normalised gradient `g`, `u` a random unit vector): a
/// purely random direction nearly cancels (moving x(t0) and x(t1) together barely
/// changes a flow), and ĝ alone would miss an error orthogonal to the gradient.
fn directions(g: &[f32], rng: &mut Rng, n: usize) -> Vec<Vec<f32>> {
    let unit = |v: Vec<f32>| {
        let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!(norm > 0.0);
        v.into_iter().map(|x| x / norm).collect::<Vec<f32>>()
    };
    let gh = unit(g.to_vec());
    (0..n)
        .map(|_| {
            let u = unit((0..g.len()).map(|_| rng.uniform() as f32 - 0.5).collect());
            gh.iter().zip(&u).map(|(a, b)| a + b).collect()
        })
        .collect()
}

/// The analytic directional derivative `g·d` against the central difference of
/// `loss(x + h·d)`, within 3 % of `|g|` (the scale of both).
fn check(name: &str, g: &[f32], dirs: &[Vec<f32>], h: f32, mut loss: impl FnMut(&[f32]) -> f64) {
    let norm = g.iter().map(|v| (v * v) as f64).sum::<f64>().sqrt();
    assert!(norm > 1e-3, "{name}: no gradient ({norm})");
    for (k, d) in dirs.iter().enumerate() {
        let analytic: f64 = g.iter().zip(d).map(|(a, b)| (a * b) as f64).sum();
        let step = |sign: f32| d.iter().map(|v| sign * h * v).collect::<Vec<f32>>();
        let numeric = (loss(&step(1.0)) - loss(&step(-1.0))) / (2.0 * h as f64);
        assert!(
            (analytic - numeric).abs() <= 0.03 * norm,
            "{name}, direction {k}: analytic {analytic} numeric {numeric} (|g| {norm})"
        );
    }
}

#[test]
fn assembled_motion_gradient_matches_central_differences() {
    let f = build(Variant::Normal);
    let mut s = DeformSettings {
        flow_form: FlowForm::Exact,
        ..DeformSettings::default()
    };
    s.schedule.gamma2_iters = 0.0;
    let d = Inputs::load(&f.scene, &f.model, &f.flows, &f.assoc, &s).unwrap();
    let mut tr = JointTrainer::new(&d, s);
    let r = TileRasterizer;
    let mut rng = Rng(7);
    let i = 1;
    let (l0, g, _) = tr.motion_gradient(&r, &d, i);
    assert!(
        l0 > 1e-3,
        "the fixture's flows disagree with the model: L = {l0}"
    );
    // Canonical centres, with the warm-up's field (zero head: the identity for every
    // input, so the field's input, detached by design as in the warm-up, does not move
    // the differences either).
    let gm: Vec<f32> = g.splats.means.as_flattened().to_vec();
    let dirs = directions(&gm, &mut rng, 3);
    let base = tr.inner.splats.means.clone();
    check("centres", &gm, &dirs, 1e-2, |step| {
        for (k, (m, b)) in tr.inner.splats.means.iter_mut().zip(&base).enumerate() {
            *m = std::array::from_fn(|c| b[c] + step[3 * k + c]);
        }
        tr.motion_gradient(&r, &d, i).0
    });
    tr.inner.splats.means = base;
    // PoseNet weights (F_ego's camera velocity comes from the corrected camera), in the
    // paper's form (the one with F_ego; its rendered depth is detached, so the centres
    // are checked in the exact form above). Small steps: the loss bends within 0.03
    // along these directions (robust norm near its kink).
    tr.settings.flow_form = FlowForm::Paper;
    let (_, _, gp) = tr.motion_gradient(&r, &d, i);
    let dirs = directions(&gp, &mut rng, 3);
    let base_p = tr.posenet.as_ref().unwrap().params().to_vec();
    check("PoseNet", &gp, &dirs, 1e-3, |step| {
        let p = tr.posenet.as_mut().unwrap().params_mut();
        for (x, (b, v)) in p.iter_mut().zip(base_p.iter().zip(step)) {
            *x = b + v;
        }
        tr.motion_gradient(&r, &d, i).0
    });
    tr.posenet
        .as_mut()
        .unwrap()
        .params_mut()
        .copy_from_slice(&base_p);
    tr.settings.flow_form = FlowForm::Exact;
    // Field weights, of a field that moves the Gaussians.
    for p in tr.inner.field.params.iter_mut() {
        *p += 0.05 * (rng.uniform() as f32 - 0.5);
    }
    let (_, g, _) = tr.motion_gradient(&r, &d, i);
    let dirs = directions(&g.field, &mut rng, 3);
    let base = tr.inner.field.params.clone();
    check("field", &g.field, &dirs, 1e-3, |step| {
        for (p, (b, v)) in tr.inner.field.params.iter_mut().zip(base.iter().zip(step)) {
            *p = b + v;
        }
        tr.motion_gradient(&r, &d, i).0
    });
}

/// `L_motion` of a model whose Gaussians follow their own trajectories (the tracks
/// init's `Splats::motion`) against a plain reference in f64: each bound Gaussian's
/// centre at both ends of the span is `μ + v·τ + a·τ²` (τ the normalised time minus ½,
/// the seconds mapped through the train frames' times), projected by the recorded
/// cameras (no PoseNet), its flow the difference of the two pixels, `r` the events'
/// weighted mean flow over the span minus it, `L = mean |r|²`. Then the trajectories'
/// gradient against central differences. The term once took `x(t1)` without the
/// trajectory: the flow of every tracked Gaussian was its trajectory's shift back.
#[test]
fn motion_term_follows_the_trajectories() {
    let f = build(Variant::Normal);
    let mut s = DeformSettings {
        flow_form: FlowForm::Exact,
        posenet: false,
        motion_span: 0.02,
        ..DeformSettings::default()
    };
    s.schedule.gamma2_iters = 0.0;
    s.motion.norm = deform::motion_loss::Norm::L2;
    s.motion.outlier_px = 0.0;
    s.motion_neighbours.radius_px = 0.0;
    let d = Inputs::load(&f.scene, &f.model, &f.flows, &f.assoc, &s).unwrap();
    let mut tr = JointTrainer::new(&d, s);
    let mut rng = Rng(11);
    let n = tr.inner.splats.len();
    tr.inner.splats.motion = (0..n)
        .map(|_| std::array::from_fn(|_| 0.6 * (rng.uniform() as f32 - 0.5)))
        .collect();
    let r = TileRasterizer;
    let i = 1;
    let (t0, t1) = (d.times[i], d.times[i] + 0.02);
    // Seconds → the field's normalised time, between the train frames around `t`.
    let norm_time = |t: f64| {
        let j = (0..d.times.len() - 1)
            .find(|&j| d.times[j] <= t && t < d.times[j + 1])
            .unwrap();
        let a = (t - d.times[j]) / (d.times[j + 1] - d.times[j]);
        d.views[j].time as f64 + a * (d.views[j + 1].time - d.views[j].time) as f64
    };
    let reference = |tr: &JointTrainer| {
        let sp = &tr.inner.splats;
        let at = |g: usize, t: f64| {
            let tau = norm_time(t) - 0.5;
            let (m, v) = (sp.means[g], sp.motion[g]);
            glam::DVec3::from_array(std::array::from_fn(|k| {
                m[k] as f64 + v[k] as f64 * tau + v[3 + k] as f64 * tau * tau
            }))
        };
        let (c0, c1) = (tr.camera_at(&d, t0).0, tr.camera_at(&d, t1).0);
        let b = &d.bindings[i];
        let (mut sum, mut count) = (0.0f64, 0usize);
        for g in 0..b.gaussians() {
            let (ev, w) = b.of(g);
            let (Some((p0, _)), Some((p1, _))) =
                (c0.project_world(at(g, t0)), c1.project_world(at(g, t1)))
            else {
                continue;
            };
            let (mut fu, mut fv, mut ws) = (0.0f64, 0.0f64, 0.0f64);
            for (&k, &wk) in ev.iter().zip(w) {
                let (u, v) = (d.flow_u[k as usize], d.flow_v[k as usize]);
                if u.is_finite() && v.is_finite() {
                    (fu, fv, ws) = (
                        fu + wk as f64 * u as f64,
                        fv + wk as f64 * v as f64,
                        ws + wk as f64,
                    );
                }
            }
            if ws > 0.0 {
                let dt = t1 - t0;
                let r = [dt * fu / ws - (p1.x - p0.x), dt * fv / ws - (p1.y - p0.y)];
                sum += r[0] * r[0] + r[1] * r[1];
                count += 1;
            }
        }
        assert!(count > 20, "too few bound Gaussians: {count}");
        sum / count as f64
    };
    let want = reference(&tr);
    let (got, g, _) = tr.motion_gradient(&r, &d, i);
    assert!(want > 0.05, "the trajectories barely move: L = {want}");
    assert!(
        (got - want).abs() <= 1e-3 * want,
        "L_motion {got} against the reference {want}"
    );
    // The trajectories' gradient (both ends of the span) against central differences.
    let gm: Vec<f32> = g.splats.motion.as_flattened().to_vec();
    let dirs = directions(&gm, &mut rng, 3);
    let base = tr.inner.splats.motion.clone();
    check("trajectories", &gm, &dirs, 1e-2, |step| {
        for (k, (m, b)) in tr.inner.splats.motion.iter_mut().zip(&base).enumerate() {
            *m = std::array::from_fn(|c| b[c] + step[6 * k + c]);
        }
        tr.motion_gradient(&r, &d, i).0
    });
}
