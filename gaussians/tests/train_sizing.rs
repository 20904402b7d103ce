//! Right-sizing (`gaussians::train::sizing`) on scenes made of known Gaussians: the
//! train views are renders of a ground-truth cloud (plus a little noise), the model is
//! that cloud with extra Gaussians no view sees.

mod raster_common;

use gaussians::field::FieldSettings;
use gaussians::raster::TileRasterizer;
use gaussians::train::judge::{Candidate, Judge, gather_deltas, posed_deltas};
use gaussians::train::sizing::{STILL_WORSE_FRACTION, gather, top_k};
use gaussians::train::{TrainSettings, Trainer, View};
use gaussians::{Rasterizer, Splats};
use glam::DVec3;
use raster_common::*;

const TOL: f64 = 0.1;

fn cameras() -> Vec<scene::Camera> {
    (0..4)
        .map(|k| camera(40, 36, 36.0, DVec3::new(0.3 * k as f64 - 0.45, 0.1, 4.0)))
        .collect()
}

/// The ground truth: DC colour only (so SH degree 0 renders it exactly).
fn truth(seed: u64) -> Splats {
    let kind = SceneKind {
        n: 60,
        spread: 1.2,
        log_scale: (-2.5, -1.2),
        logit: (-1.0, 3.0),
        sh_rest: 0.0,
    };
    random_splats(&mut Rng(seed), kind)
}

/// Views of `s` deformed by `field` (None: static) at times 0, ⅓, ⅔, 1, with noise of
/// ±1.5 % so the train PSNR is finite.
fn views(s: &Splats, field: Option<&gaussians::field::Mlp<f32>>) -> Vec<View> {
    let mut rng = Rng(5);
    cameras()
        .into_iter()
        .enumerate()
        .map(|(k, camera)| {
            let time = k as f32 / 3.0;
            let moved = match field {
                None => s.clone(),
                Some(f) => {
                    let (d, _) = gaussians::field::splat_deltas(f, s, time, false);
                    gaussians::field::deform_splats(s, &d)
                }
            };
            let (img, _) = TileRasterizer.render(&moved, &camera, 0, [0.0; 3]);
            let rgb = img.rgb.iter().map(|&v| v + rng.uf(-0.015, 0.015)).collect();
            View { camera, time, rgb }
        })
        .collect()
}

/// A trainer holding `model` at the sizing iteration, the field on, SH degree 2 in use.
fn trainer(model: Splats, field: gaussians::field::Mlp<f32>) -> Trainer {
    let mut s = TrainSettings {
        iterations: 100,
        static_iterations: 0,
        sh_degree: 3,
        sh_interval: 25,
        field: field.settings,
        ..TrainSettings::default()
    };
    s.size.tolerance_db = TOL;
    s.size.at = 50;
    let mut tr = Trainer::new(s, model, 1.0);
    tr.field = field;
    tr.iteration = 50;
    tr
}

fn small_field() -> gaussians::field::Mlp<f32> {
    let s = FieldSettings {
        depth: 2,
        width: 16,
        ..FieldSettings::default()
    };
    let mut f = gaussians::field::Mlp::new(s, 3);
    f.zero_head();
    f
}

/// [`small_field`] moving along x (head output 0 only): by `shift` at every time, plus
/// a part that varies with position and time, head weight i = `gain`·((i·`mul` mod
/// `modulo`) − (`modulo` − 1)/2).
fn moving_field(shift: f32, gain: f32, mul: usize, modulo: usize) -> gaussians::field::Mlp<f32> {
    let mut f = small_field();
    let head = *f.layers.last().unwrap();
    f.params[head.bias] = shift;
    let centre = (modulo - 1) as f32 / 2.0;
    for i in 0..head.fan_in {
        f.params[head.weight + i * head.fan_out] = gain * ((i * mul % modulo) as f32 - centre);
    }
    f
}

/// The truth plus Gaussians behind every camera and far outside every view.
fn padded(t: &Splats) -> Splats {
    let mut m = t.clone();
    for k in 0..20 {
        push_gaussian(&mut m, [0.1 * k as f32, 0.0, 6.0], -1.5, 2.0);
        push_gaussian(&mut m, [30.0 + k as f32, 0.0, 0.0], -1.5, 2.0);
    }
    m
}

/// A judge of candidates at `views` on a black background.
fn judge(views: &[View]) -> Judge<'_, TileRasterizer> {
    Judge {
        r: &TileRasterizer,
        views,
        background: [0.0; 3],
        evaluations: 0,
    }
}

fn psnr(views: &[View], s: &Splats, sh: u32) -> f64 {
    let mut j = judge(views);
    j.psnr(&Candidate {
        splats: s,
        field: None,
        dynamic_only: false,
        sh_degree: sh,
        deltas: None,
    })
}

/// A static scene: the field (identity here) is dropped, degree 0 is enough, the unseen
/// Gaussians go, and the count is the smallest within tolerance: one Gaussian fewer (in
/// weight order) falls below it.
#[test]
fn a_static_scene_loses_its_field_its_sh_and_its_unseen_gaussians() {
    let t = truth(21);
    let v = views(&t, None);
    let mut tr = trainer(padded(&t), small_field());
    assert_eq!(tr.sh_degree(), 2);
    tr.size_if_due(&TileRasterizer, &v);
    let s = tr.sizing.clone().expect("sized at iteration 50");
    assert!(s.field_dropped && s.still && !tr.field_on());
    assert_eq!(s.field_motion_px_quantiles, Some([0.0; 4]));
    assert_eq!((s.sh_degree_before, s.sh_degree), (2, 0));
    assert_eq!(s.train_psnr_by_sh_degree.len(), 1);
    assert_eq!((tr.settings.sh_degree, tr.sh_degree()), (0, 0));
    assert_eq!(s.gaussians_before, 100);
    assert!(s.gaussians_without_weight >= 40, "{s:?}");
    assert!(s.gaussians <= 60 && s.gaussians == tr.splats.len(), "{s:?}");
    assert!(s.train_psnr_after >= s.train_psnr_before - TOL, "{s:?}");
    assert!(
        s.train_psnr_before > 30.0 && s.train_psnr_before < 60.0,
        "{s:?}"
    );
    // Adam's state follows the kept Gaussians.
    assert_eq!(tr.adam.groups[0].m.len(), 3 * tr.splats.len());
    // Smallest: the weights of the padded model rank the same kept set; one fewer fails.
    let w = {
        let model = padded(&t);
        let mut j = judge(&v);
        j.contributions(&Candidate {
            splats: &model,
            field: None,
            dynamic_only: false,
            sh_degree: 0,
            deltas: None,
        })
        .unwrap()
    };
    let model = padded(&t);
    let k = s.gaussians;
    // (Frozen by the identity field: means and opacities exact, scales through exp/ln.)
    let kept = gather(&model, &top_k(&w, k));
    let same = kept.means == tr.splats.means && kept.opacity_logits == tr.splats.opacity_logits;
    assert!(same, "the kept Gaussians are not the top {k} by weight");
    assert!(tr.splats.dynamic.is_empty(), "no field: no flags");
    let fewer = gather(&model, &top_k(&w, k - 1));
    assert!(psnr(&v, &fewer, 0) < s.train_psnr_before - TOL);
    assert!((psnr(&v, &tr.splats, 0) - s.train_psnr_after).abs() < 1e-12);
    // Before, without field, the visible-change check (two passes), degree 0, the
    // weights, the 60 weighed, ≤ ⌈log₂ 60⌉ more counts, after.
    assert!((9..=14).contains(&s.evaluations), "{s:?}");
}

/// A moving scene: the views need the field (it moves the Gaussians by several
/// pixels), so it stays, and so does the sizing's promise on the train PSNR.
#[test]
fn a_moving_scene_keeps_its_field() {
    let t = truth(22);
    // δx: a shift of 0.3 units along x (≈ 2.7 px) at every time, plus a part that
    // varies with position and time.
    let f = moving_field(0.3, 0.05, 7, 13);
    let v = views(&t, Some(&f));
    let mut tr = trainer(padded(&t), f);
    tr.size_if_due(&TileRasterizer, &v);
    let s = tr.sizing.clone().unwrap();
    assert!(!s.field_dropped && !s.still && tr.field_on(), "{s:?}");
    let q = s.field_motion_px_quantiles.unwrap();
    assert!(q[2] > 1.0 && q[3] >= q[2], "{q:?}");
    let without = s.train_psnr_without_field.unwrap();
    assert!(without < s.train_psnr_before - 3.0, "{s:?}");
    assert!(s.gaussians < 100 && s.train_psnr_after >= s.train_psnr_before - TOL);
    // The Gaussians the field barely moves (here: those behind the cameras, which no
    // view sees, and any the small field leaves in place) are split off, baked.
    let sp = s.split.expect("a split");
    assert!(sp.train_psnr >= s.train_psnr_before - TOL, "{sp:?}");
    assert_eq!(sp.dynamic + sp.static_, 100);
    assert!(tr.settings.dynamic_only && tr.splats.dynamic.len() == tr.splats.len());
    assert!(
        tr.splats.dynamic.iter().any(|&d| d) && sp.static_ > 0,
        "{sp:?}"
    );
    // Sizing happens once.
    let before = tr.splats.clone();
    tr.size_if_due(&TileRasterizer, &v);
    assert_eq!(tr.splats, before);
}

/// The sizing evaluates the field once per view and scores SH degrees and pruned
/// subsets from those deltas: the same PSNR as evaluating the field on each candidate.
#[test]
fn deltas_evaluated_once_score_as_the_field_does() {
    let t = truth(24);
    let f = moving_field(0.2, 0.04, 5, 11);
    let v = views(&t, Some(&f));
    let model = padded(&t);
    let mut j = judge(&v);
    let with_field = Candidate {
        splats: &model,
        field: Some(&f),
        dynamic_only: false,
        sh_degree: 0,
        deltas: None,
    };
    let posed = posed_deltas(&with_field, &v).expect("a field");
    assert_eq!(posed.len(), v.len());
    let from_deltas = Candidate {
        deltas: Some(&posed),
        ..with_field
    };
    let p = j.psnr(&with_field);
    assert!(p > 25.0 && p.is_finite(), "{p}");
    assert_eq!(j.psnr(&from_deltas), p);
    // Every other Gaussian of the model: the gathered deltas against the field on the
    // subset (the field moves each Gaussian on its own).
    let keep: Vec<usize> = (0..model.len()).step_by(2).collect();
    let sub = gather(&model, &keep);
    let sub_deltas = gather_deltas(&posed, &keep);
    let a = j.psnr(&Candidate {
        splats: &sub,
        ..with_field
    });
    let b = j.psnr(&Candidate {
        splats: &sub,
        deltas: Some(&sub_deltas),
        ..with_field
    });
    assert!(
        a < p - 1.0,
        "half the Gaussians must score lower: {a} vs {p}"
    );
    assert!((a - b).abs() < 1e-9, "{a} vs {b}");
}

/// A field that grows and shrinks the Gaussians over time without moving them (how an
/// RGB-only warm-up shows a fast object at a low frame rate): no centre moves, but
/// without the field the views are visibly wrong, so the scene is not still.
#[test]
fn a_field_that_only_scales_keeps_its_field() {
    let t = truth(23);
    let mut f = small_field();
    // δs (outputs 7..10) from the hidden features, which vary with time and position.
    let head = *f.layers.last().unwrap();
    for i in 0..head.fan_in {
        for o in 7..10 {
            f.params[head.weight + i * head.fan_out + o] = 0.6 * ((i * 5 % 11) as f32 - 5.0);
        }
    }
    let v = views(&t, Some(&f));
    let mut tr = trainer(padded(&t), f);
    tr.size_if_due(&TileRasterizer, &v);
    let s = tr.sizing.clone().unwrap();
    let q = s.field_motion_px_quantiles.unwrap();
    assert!(q[3] < 1e-3, "no centre moves: {q:?}");
    let worse = s.visibly_worse_without_field.unwrap();
    assert!(worse > 10.0 * STILL_WORSE_FRACTION, "{s:?}");
    assert!(!s.still && !s.field_dropped && tr.field_on(), "{s:?}");
}

/// A field that shifts everything by the same amount at every time (what a field
/// trained beside the canonical Gaussians also holds): the scene is static, so the
/// field goes, and its shift stays, baked into the Gaussians.
#[test]
fn a_constant_deformation_is_baked_in_when_the_field_goes() {
    let t = truth(24);
    let mut f = small_field();
    let head = *f.layers.last().unwrap();
    f.params[head.bias] = 0.3;
    let v = views(&t, Some(&f));
    let mut tr = trainer(padded(&t), f);
    tr.settings.size.prune = false;
    tr.size_if_due(&TileRasterizer, &v);
    let s = tr.sizing.clone().unwrap();
    assert!(s.field_dropped && s.still && !tr.field_on(), "{s:?}");
    assert!(s.field_motion_px_quantiles.unwrap()[3] < 1e-4, "{s:?}");
    assert!(s.train_psnr_without_field.unwrap() >= s.train_psnr_before - TOL);
    assert_eq!(tr.splats.len(), 100);
    for i in 0..60 {
        let (a, b) = (tr.splats.means[i], t.means[i]);
        assert!((a[0] - b[0] - 0.3).abs() < 1e-6 && a[1] == b[1] && a[2] == b[2]);
    }
}

/// The split takes the frozen parameters of the Gaussians at or under the tolerance and
/// flags them static; the others keep theirs and move.
#[test]
fn a_split_bakes_the_still_gaussians() {
    let canonical = truth(25);
    let mut frozen = canonical.clone();
    for m in &mut frozen.means {
        m[0] += 1.0;
    }
    for l in &mut frozen.log_scales {
        l[1] -= 0.5;
    }
    let motion: Vec<f32> = (0..60).map(|i| i as f32 * 0.1).collect();
    let s = gaussians::train::static_split::split(&canonical, &frozen, &motion, 2.0);
    for i in 0..60 {
        let (src, dynamic) = if i <= 20 {
            (&frozen, false)
        } else {
            (&canonical, true)
        };
        assert_eq!(s.dynamic[i], dynamic, "{i}");
        assert_eq!(s.means[i], src.means[i]);
        assert_eq!(s.log_scales[i], src.log_scales[i]);
        assert_eq!(s.sh_dc[i], canonical.sh_dc[i]);
    }
}

/// `tolerance_db = 0` is the fixed-size model: no sizing iteration at all.
#[test]
fn zero_tolerance_means_fixed_sizes() {
    let t = truth(23);
    let mut tr = trainer(padded(&t), small_field());
    tr.settings.size.tolerance_db = 0.0;
    assert_eq!(tr.sizing_iteration(), None);
    tr.size_if_due(&TileRasterizer, &views(&t, None));
    assert!(tr.sizing.is_none() && tr.splats.len() == 100 && tr.field_on());
    // Auto: the end of densification, or the run's end when that comes first.
    tr.settings.size.tolerance_db = 0.1;
    tr.settings.size.at = 0;
    tr.settings.densify.until_iter = 70;
    assert_eq!(tr.sizing_iteration(), Some(70));
    tr.settings.densify.until_iter = 7000;
    assert_eq!(tr.sizing_iteration(), Some(100));
}
