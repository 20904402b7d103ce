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
