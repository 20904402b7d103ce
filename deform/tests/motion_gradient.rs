//! The motion term's gradient as the joint step assembles it (the part on `x(t0)` taken
//! back with the view's RGB gradient, the part on `x(t1)` through a second field pass)
//! against central differences of `L_motion` itself, along random directions in the
//! canonical centres, in the field's weights and in the PoseNet's weights (through the
//! corrected camera's velocity in `F_ego`). The kernels are checked in f64 in the
//! unit tests; this checks their assembly in the f32 trainer.

mod fixture;

use deform::inputs::Inputs;
use deform::settings::{DeformSettings, FlowForm};
use deform::trainer::JointTrainer;
use fixture::{Rng, Variant, build};
use gaussians::TileRasterizer;

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
    // Along the gradient itself (a random direction nearly cancels: moving x(t0) and
    // x(t1) together barely changes a flow), normalised.
    let norm = g
        .splats
        .means
        .as_flattened()
        .iter()
        .map(|v| v * v)
        .sum::<f32>()
        .sqrt();
    assert!(norm > 0.0);
    let dir: Vec<[f32; 3]> = g.splats.means.iter().map(|v| v.map(|x| x / norm)).collect();
    let analytic: f64 = g
        .splats
        .means
        .iter()
        .zip(&dir)
        .map(|(a, b)| (0..3).map(|c| (a[c] * b[c]) as f64).sum::<f64>())
        .sum();
    let h = 1e-2f32;
    let base = tr.inner.splats.means.clone();
    let mut at = |sign: f32| {
        for (m, (b, v)) in tr.inner.splats.means.iter_mut().zip(base.iter().zip(&dir)) {
            *m = std::array::from_fn(|c| b[c] + sign * h * v[c]);
        }
        tr.motion_gradient(&r, &d, i).0
    };
    let numeric = (at(1.0) - at(-1.0)) / (2.0 * h as f64);
    tr.inner.splats.means = base;
    // PoseNet weights (F_ego's camera velocity comes from the corrected camera), in the
    // paper's form (the one with F_ego; its rendered depth is detached, so the centres
    // are checked in the exact form above).
    tr.settings.flow_form = FlowForm::Paper;
    let (_, _, gp) = tr.motion_gradient(&r, &d, i);
    let norm = gp.iter().map(|v| v * v).sum::<f32>().sqrt();
    assert!(norm > 0.0, "L_motion gives the PoseNet no gradient");
    let dir: Vec<f32> = gp.iter().map(|v| v / norm).collect();
    let analytic_p = norm as f64;
    let base_p = tr.posenet.as_ref().unwrap().params().to_vec();
    // Small: the loss bends within 0.03 along this direction (robust norm near its kink).
    let hp = 1e-3f32;
    let mut at_p = |sign: f32| {
        let p = tr.posenet.as_mut().unwrap().params_mut();
        for (x, (b, v)) in p.iter_mut().zip(base_p.iter().zip(&dir)) {
            *x = b + sign * hp * v;
        }
        tr.motion_gradient(&r, &d, i).0
    };
    let numeric_p = (at_p(1.0) - at_p(-1.0)) / (2.0 * hp as f64);
    tr.posenet
        .as_mut()
        .unwrap()
        .params_mut()
        .copy_from_slice(&base_p);
    tr.settings.flow_form = FlowForm::Exact;
    assert!(
        (analytic_p - numeric_p).abs() <= 0.03 * numeric_p.abs(),
        "PoseNet: analytic {analytic_p} numeric {numeric_p}"
    );
    assert!(
        analytic.abs() > 1e-3 && (analytic - numeric).abs() <= 0.03 * numeric.abs(),
        "centres: analytic {analytic} numeric {numeric}"
    );
    // Field weights, of a field that moves the Gaussians.
    for p in tr.inner.field.params.iter_mut() {
        *p += 0.05 * (rng.uniform() as f32 - 0.5);
    }
    let (_, g, _) = tr.motion_gradient(&r, &d, i);
    let norm = g.field.iter().map(|v| v * v).sum::<f32>().sqrt();
    let dir: Vec<f32> = g
        .field
        .iter()
        .map(|v| v / norm + 0.2 * (rng.uniform() as f32 - 0.5) / (g.field.len() as f32).sqrt())
        .collect();
    assert_eq!(g.field.len(), dir.len());
    let analytic: f64 = g.field.iter().zip(&dir).map(|(a, b)| (a * b) as f64).sum();
    let base = tr.inner.field.params.clone();
    let h = 1e-3f32;
    let mut at = |sign: f32| {
        for (p, (b, v)) in tr.inner.field.params.iter_mut().zip(base.iter().zip(&dir)) {
            *p = b + sign * h * v;
        }
        tr.motion_gradient(&r, &d, i).0
    };
    let numeric = (at(1.0) - at(-1.0)) / (2.0 * h as f64);
    assert!(
        analytic.abs() > 1e-3 && (analytic - numeric).abs() <= 0.03 * numeric.abs(),
        "field: analytic {analytic} numeric {numeric}"
    );
}
