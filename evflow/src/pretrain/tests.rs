//! Unit tests of the pretraining loop (split out of `mod.rs`).

use super::*;

fn tiny() -> PretrainSettings {
    PretrainSettings {
        base: 2,
        presets: vec!["rigid".into()],
        train_seeds: vec![1],
        eval_presets: vec!["fast".into()],
        eval_seeds: vec![2],
        resolution: 32,
        scene_duration: 0.25,
        render_rate_hz: 200.0,
        window_min_s: 0.05,
        window_max_s: 0.1,
        iterations: 3,
        batch: 2,
        cm_weight: 0.5,
        eval_windows: 2,
        ..PretrainSettings::default()
    }
}

#[test]
fn settings_are_checked() {
    assert!(PretrainSettings::default().validate().is_ok());
    let mut s = PretrainSettings::default();
    s.eval_seeds.push(s.train_seeds[0]);
    assert!(s.validate().unwrap_err().contains("held-out"));
    s = PretrainSettings {
        presets: vec!["nope".into()],
        ..PretrainSettings::default()
    };
    assert!(s.validate().unwrap_err().contains("nope"));
    let e = toml::from_str::<PretrainSettings>("bogus = 1")
        .unwrap_err()
        .to_string();
    assert!(e.contains("bogus"), "{e}");
    let s: PretrainSettings = toml::from_str("base = 8\niterations = 7").unwrap();
    assert_eq!((s.base, s.iterations, s.batch), (8, 7, 4));
}

#[test]
fn seeds_change_textures_deterministically() {
    let s = PretrainSettings::default();
    let a = scene_config("rigid", 1, &s).unwrap();
    let b = scene_config("rigid", 1001, &s).unwrap();
    assert_eq!(a, scene_config("rigid", 1, &s).unwrap());
    for (oa, ob) in a.objects.iter().zip(&b.objects) {
        assert_ne!(oa.texture.seed, ob.texture.seed);
        assert_ne!(oa.texture.colour_a, ob.texture.colour_a);
    }
    assert_eq!((a.width, a.height), (64, 64));
}

#[test]
fn flipped_samples_mirror_the_target() {
    let s = tiny();
    let d = make_scene("rigid", 1, &s).unwrap();
    assert!(d.events.len() > 100, "{} events", d.events.len());
    let a = sample(&d, (0.1, 0.2), 5, (false, false));
    let b = sample(&d, (0.1, 0.2), 5, (true, true));
    let n = 32;
    let mut checked = 0;
    for y in 0..n {
        for x in 0..n {
            let (p, q) = (y * n + x, (n - 1 - y) * n + (n - 1 - x));
            assert_eq!(a.mask[p], b.mask[q]);
            assert_eq!(a.target[p], -b.target[q]);
            assert_eq!(a.target[n * n + p], -b.target[n * n + q]);
            assert_eq!(a.voxel[p], b.voxel[q]);
            checked += usize::from(a.mask[p] > 0.0);
        }
    }
    assert!(checked > 10);
    assert_eq!(a.cm.len(), b.cm.len());
    assert!(a.cm.t.iter().all(|t| (0.0..=1.0).contains(t)));
}

#[test]
fn a_tiny_run_writes_loadable_weights_and_a_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("pre");
    let mut calls = 0;
    let r = run(&tiny(), &out, &mut |k, n, l| {
        calls += 1;
        assert!(k <= n && l.is_finite());
    })
    .unwrap();
    assert_eq!(calls, 3);
    assert_eq!(r.loss_curve.len(), 3);
    assert_eq!(r.held_out.len(), 1);
    let h = &r.held_out[0];
    assert!(h.metrics.count > 0 && h.metrics.epe.is_finite());
    assert!((h.zero.epe - h.zero.gt_magnitude).abs() < 1e-9);
    let net = FlowNet::load(&out.join(WEIGHTS_FILE), None, &Device::flex(), DType::F32).unwrap();
    assert_eq!(net.config, tiny().net_config());
    assert!(out.join("report.json").is_file());
    let bad = PretrainSettings {
        iterations: 1,
        lr: -1.0,
        ..tiny()
    };
    let e = run(&bad, &dir.path().join("bad"), &mut |_, _, _| {}).unwrap_err();
    assert!(e.to_string().contains("lr"), "{e}");
    assert!(!dir.path().join("bad").exists());
}
