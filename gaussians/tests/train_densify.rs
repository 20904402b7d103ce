//! Densification plan: clone vs split, pruning, the cap, moment sources, opacity reset.

use gaussians::densify::{DensifySettings, Geometry, GradStats, plan, reset_opacity};

fn logit(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

#[test]
fn clones_small_splits_large_prunes_transparent() {
    let means = vec![
        [0.0f32; 3],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let small = 0.005f32.ln();
    let large = 0.05f32.ln();
    let log_scales = vec![[small; 3], [large, small, small], [small; 3], [small; 3]];
    let rotations = vec![[1.0f32, 0.0, 0.0, 0.0]; 4];
    let opacity = vec![logit(0.5), logit(0.5), logit(0.5), logit(0.001)];
    let mut stats = GradStats::new(4);
    stats.add(&[0.001, 0.001, 0.0001, 0.01], &[3.0, 3.0, 3.0, 3.0]);
    stats.add(&[0.0, 0.0, 0.0, 0.0], &[0.0, 0.0, 0.0, 0.0]); // invisible: not counted
    let geo = Geometry {
        means: &means,
        log_scales: &log_scales,
        rotations: &rotations,
        opacity_logits: &opacity,
    };
    let s = DensifySettings::default();
    let p = plan(&geo, &stats, &s, 1.0, false, 1);
    assert_eq!((p.cloned, p.split, p.pruned), (1, 1, 1));
    // kept 0 and 2 first, then the clone of 0, then the two children of 1
    assert_eq!(p.source, vec![0, 2, 0, 1, 1]);
    assert_eq!(p.fresh, vec![false, false, true, true, true]);
    assert_eq!(p.moment_sources(), vec![Some(0), Some(2), None, None, None]);
    assert_eq!(p.means[2], [0.0; 3]);
    let child = p.log_scales[3];
    assert!((child[0] - (0.05f32 / 1.6).ln()).abs() < 1e-6);
    // children are sampled from the Gaussian: spread mostly along its long axis
    for k in [3, 4] {
        let d = [p.means[k][0] - 1.0, p.means[k][1], p.means[k][2]];
        assert!(
            d[0].abs() < 0.3 && d[1].abs() < 0.03 && d[2].abs() < 0.03,
            "{d:?}"
        );
        assert!(d[0] != 0.0);
    }
    assert_eq!(p.gather(&[10, 11, 12, 13]), vec![10, 12, 10, 11, 11]);
}

#[test]
fn size_pruning_and_cap() {
    let n = 10;
    let means = vec![[0.0f32; 3]; n];
    let mut log_scales = vec![[0.001f32.ln(); 3]; n];
    log_scales[0] = [0.5f32.ln(); 3]; // > 0.1 · extent
    let rotations = vec![[1.0f32, 0.0, 0.0, 0.0]; n];
    let opacity = vec![0.0f32; n];
    let mut stats = GradStats::new(n);
    let mut radius = vec![2.0f32; n];
    radius[1] = 50.0;
    let grads: Vec<f32> = (0..n).map(|i| 0.001 * (i + 1) as f32).collect();
    stats.add(&grads, &radius);
    let geo = Geometry {
        means: &means,
        log_scales: &log_scales,
        rotations: &rotations,
        opacity_logits: &opacity,
    };
    let mut s = DensifySettings::default();
    let p = plan(&geo, &stats, &s, 1.0, false, 0);
    assert_eq!((p.pruned, p.cloned), (0, 9));
    let p = plan(&geo, &stats, &s, 1.0, true, 0);
    assert_eq!(p.pruned, 2);
    s.max_gaussians = 11;
    let p = plan(&geo, &stats, &s, 1.0, true, 0);
    assert_eq!(p.source.len(), 11);
    // the cap keeps the highest-gradient candidates: indices 9, 8, 7
    assert_eq!(&p.source[8..], &[7, 8, 9]);
}

#[test]
fn opacity_reset_caps_at_one_percent() {
    let mut o = vec![logit(0.9), logit(0.001)];
    reset_opacity(&mut o);
    assert!((1.0 / (1.0 + (-o[0]).exp()) - 0.01).abs() < 1e-6);
    assert!((o[1] - logit(0.001)).abs() < 1e-6);
}
