//! The field's width probe (`gaussians::train::field_probe`): which views it holds out,
//! which widths it tries and keeps, and that training goes on from the kept candidate.

mod raster_common;

use gaussians::field::FieldSettings;
use gaussians::raster::TileRasterizer;
use gaussians::train::field_probe::{candidate_widths, choose, held_out_views};
use gaussians::train::judge::{Candidate, Judge};
use gaussians::train::{TrainSettings, Trainer, View};
use gaussians::{Rasterizer, Splats};
use glam::DVec3;
use raster_common::*;

#[test]
fn held_out_views_are_in_between_times() {
    let times: Vec<f32> = (0..17).map(|k| k as f32 / 16.0).collect();
    assert_eq!(held_out_views(&times, 4), vec![2, 6, 10, 14]);
    // Shuffled views: the same times are held out, by index.
    let perm = [5, 0, 16, 3, 9, 12, 1, 14, 7, 2, 11, 6, 15, 4, 13, 8, 10];
    let shuffled: Vec<f32> = perm.iter().map(|&k| times[k]).collect();
    let h = held_out_views(&shuffled, 4);
    let mut held_times: Vec<usize> = h.iter().map(|&i| perm[i]).collect();
    held_times.sort_unstable();
    assert_eq!(held_times, vec![2, 6, 10, 14]);
    // The first and last times are never held out, even where the step would reach them.
    let nine: Vec<f32> = (0..9).map(|k| k as f32).collect();
    assert_eq!(held_out_views(&nine, 3), vec![2, 5]);
    assert_eq!(held_out_views(&nine, 6), vec![2]);
    // Too few views to spare any.
    assert!(held_out_views(&times[..7], 4).is_empty());
    assert!(held_out_views(&times, 1).is_empty());
}

#[test]
fn candidates_halve_down_to_the_narrowest() {
    assert_eq!(candidate_widths(64, 1), vec![64, 32]);
    assert_eq!(candidate_widths(64, 3), vec![64, 32, 16, 8]);
    assert_eq!(candidate_widths(64, 9), vec![64, 32, 16, 8]);
    assert_eq!(candidate_widths(12, 2), vec![12]);
    assert_eq!(candidate_widths(64, 0), vec![64]);
}

#[test]
fn the_narrowest_width_within_tolerance_is_kept() {
    let w = [64, 32, 16];
    assert_eq!(choose(&w, &[23.0, 22.95, 22.5], 0.1), 1);
    assert_eq!(choose(&w, &[23.0, 22.85, 22.5], 0.1), 0);
    // A narrower field may also be better.
    assert_eq!(choose(&w, &[22.0, 22.4, 22.35], 0.1), 2);
    assert_eq!(choose(&w, &[22.0, 22.4, 22.25], 0.1), 1);
    // NaN never wins, nor sets the best.
    assert_eq!(choose(&w, &[23.0, f64::NAN, 22.95], 0.1), 2);
    assert_eq!(choose(&w, &[23.0, 22.99, 22.98], 0.0), 0);
}

/// Ten views of a cloud that drifts along x over the recording.
fn moving_views(truth: &Splats) -> Vec<View> {
    (0..10)
        .map(|k| {
            let time = k as f32 / 9.0;
            let camera = camera(36, 32, 34.0, DVec3::new(0.1 * k as f64 - 0.45, 0.05, 4.0));
            let mut moved = truth.clone();
            for m in &mut moved.means {
                m[0] += 0.4 * time;
            }
            let (img, _) = TileRasterizer.render(&moved, &camera, 0, [0.0; 3]);
            View {
                camera,
                time,
                rgb: img.rgb,
            }
        })
        .collect()
}

/// `n` random Gaussians of DC colour only, a unit spread.
fn scene_kind(n: usize) -> SceneKind {
    SceneKind {
        n,
        spread: 1.0,
        log_scale: (-2.3, -1.5),
        logit: (0.0, 3.0),
        sh_rest: 0.0,
    }
}

fn probing_trainer(model: Splats, probe: u32) -> Trainer {
    let mut s = TrainSettings {
        iterations: 400,
        static_iterations: 20,
        sh_degree: 0,
        background: [0.0; 3],
        field: FieldSettings {
            depth: 2,
            width: 16,
            pos_freqs: 4,
            time_freqs: 3,
            ..FieldSettings::default()
        },
        ..TrainSettings::default()
    };
    s.densify.until_iter = 0;
    s.size.at = 300;
    s.size.field_probe = probe;
    s.size.field_halvings = 1;
    let mut t = Trainer::new(s, model, 1.0);
    t.iteration = 20;
    t
}

fn held_out_psnr(tr: &Trainer, views: &[View]) -> f64 {
    let mut j = Judge {
        r: &TileRasterizer,
        views,
        background: [0.0; 3],
        evaluations: 0,
    };
    j.psnr(&Candidate {
        splats: &tr.splats,
        field: Some(&tr.field),
        dynamic_only: tr.settings.dynamic_only,
        sh_degree: tr.sh_degree(),
        deltas: None,
    })
}

#[test]
fn the_probe_trains_each_width_and_goes_on_from_the_one_kept() {
    let kind = scene_kind(40);
    let truth = random_splats(&mut Rng(31), kind);
    let views = moving_views(&truth);
    let start = random_splats(&mut Rng(32), kind);
    let mut tr = probing_trainer(start.clone(), 60);
    assert_eq!(tr.field_probe_iterations(), Some(60));
    tr.probe_field_if_due(&TileRasterizer, &views);
    let p = tr.field_probe.clone().expect("the probe ran");
    assert_eq!((p.iteration, p.probe_iterations), (20, 60));
    assert_eq!(p.held_out, vec![2, 6]);
    assert_eq!(p.widths, vec![16, 8]);
    assert!(
        p.held_out_psnr.iter().all(|s| s.is_finite() && *s > 5.0),
        "{p:?}"
    );
    let pick = choose(&p.widths, &p.held_out_psnr, tr.settings.size.tolerance_db);
    assert_eq!(p.width, p.widths[pick]);
    // The trainer is the kept candidate after its probe: its field has that width, its
    // iteration is past the probe, and its held-out score is the one recorded.
    assert_eq!(tr.iteration, 80);
    assert_eq!(tr.settings.field.width, p.width);
    assert_eq!(tr.field.settings.width, p.width);
    let fresh = gaussians::field::Mlp::<f32>::new(tr.settings.field, 0);
    assert_eq!(tr.field.params.len(), fresh.params.len());
    let held: Vec<View> = p.held_out.iter().map(|&i| views[i].clone()).collect();
    assert_eq!(held_out_psnr(&tr, &held), p.held_out_psnr[pick]);
    // The probe trained the field and the Gaussians.
    assert!(tr.field.params.iter().any(|&w| w != 0.0) && tr.splats != start);
    // It runs once, and the training goes on with the kept width.
    tr.probe_field_if_due(&TileRasterizer, &views);
    assert_eq!(tr.iteration, 80);
    let info = tr.step(&TileRasterizer, &views);
    assert!(info.field_on && info.psnr.is_finite());
    assert_eq!(tr.iteration, 81);
}

#[test]
fn the_probe_stops_short_of_the_sizing_and_can_be_turned_off() {
    let s = random_splats(&mut Rng(3), scene_kind(10));
    // Sizing at 300: a probe of 1000 is cut to 279 (it ends before the sizing's step).
    assert_eq!(
        probing_trainer(s.clone(), 1000).field_probe_iterations(),
        Some(279)
    );
    let mut t = probing_trainer(s.clone(), 200);
    t.settings.size.at = 60;
    assert_eq!(
        t.field_probe_iterations(),
        None,
        "39 iterations rank nothing"
    );
    t.settings.size.at = 300;
    t.settings.size.field_halvings = 0;
    assert_eq!(t.field_probe_iterations(), None, "one candidate");
    t.settings.size.field_halvings = 1;
    t.settings.size.tolerance_db = 0.0;
    assert_eq!(t.field_probe_iterations(), None, "fixed sizes");
    t.settings.size.tolerance_db = 0.1;
    t.settings.deform = false;
    assert_eq!(t.field_probe_iterations(), None, "no field");
    // Too few views to hold any out: no probe, and the step is an ordinary one.
    t.settings.deform = true;
    let views = moving_views(&s);
    t.step(&TileRasterizer, &views[..6]);
    assert!(t.field_probe.is_none());
    assert_eq!((t.iteration, t.field.settings.width), (21, 16));
}
