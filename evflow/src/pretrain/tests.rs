//! Unit tests of the pretraining loop (split out of `mod.rs`).

use super::*;
use stagekit::Settings;

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
    let a = scene_config("rigid", 1, 64, &s).unwrap();
    let b = scene_config("rigid", 1001, 64, &s).unwrap();
    assert_eq!(a, scene_config("rigid", 1, 64, &s).unwrap());
    let big = scene_config("rigid", 1, 128, &s).unwrap();
    assert_eq!((big.width, big.height), (128, 128));
    assert_eq!(
        (big.objects, big.camera),
        (a.objects.clone(), a.camera.clone())
    );
    for (oa, ob) in a.objects.iter().zip(&b.objects) {
        assert_ne!(oa.texture.seed, ob.texture.seed);
        assert_ne!(oa.texture.colour_a, ob.texture.colour_a);
    }
    assert_eq!((a.width, a.height), (64, 64));
}

#[test]
fn flipped_samples_mirror_the_target() {
    let s = tiny();
    let d = make_scene("rigid", 1, 32, &s).unwrap();
    assert!(d.events.len() > 100, "{} events", d.events.len());
    let a = sample(&d, (0.1, 0.2), 5, Augment::default());
    let flip = Augment {
        flip: (true, true),
        ..Augment::default()
    };
    let b = sample(&d, (0.1, 0.2), 5, flip);
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
fn transposed_reversed_and_cropped_samples_map_exactly() {
    let s = tiny();
    let d = make_scene("rigid", 1, 32, &s).unwrap();
    let (n, bins) = (32, 5);
    let plane = n * n;
    let a = sample(&d, (0.1, 0.2), bins, Augment::default());
    let aug = |transpose, reverse, flip| Augment {
        flip,
        transpose,
        reverse,
        crop: None,
    };
    // Transpose: pixel (x, y) ← (y, x), flow (u, v) ← (v, u); with a horizontal flip on top.
    let t = sample(&d, (0.1, 0.2), bins, aug(true, false, (false, false)));
    let tf = sample(&d, (0.1, 0.2), bins, aug(true, false, (true, false)));
    // Reverse: voxel bin n ← −bin (B−1−n), flow ← −flow, CM times ← 1 − t.
    let r = sample(&d, (0.1, 0.2), bins, aug(false, true, (false, false)));
    let mut checked = 0;
    for y in 0..n {
        for x in 0..n {
            let (p, q, f) = (y * n + x, x * n + y, x * n + (n - 1 - y));
            assert_eq!(t.mask[q], a.mask[p]);
            assert_eq!(
                (t.target[q], t.target[plane + q]),
                (a.target[plane + p], a.target[p])
            );
            assert_eq!(tf.target[f], -a.target[plane + p]);
            assert_eq!(tf.target[plane + f], a.target[p]);
            assert_eq!(r.mask[p], a.mask[p]);
            assert_eq!(
                (r.target[p], r.target[plane + p]),
                (-a.target[p], -a.target[plane + p])
            );
            for b in 0..bins {
                assert_eq!(t.voxel[b * plane + q], a.voxel[b * plane + p]);
                assert_eq!(r.voxel[b * plane + p], -a.voxel[(bins - 1 - b) * plane + p]);
            }
            checked += usize::from(a.mask[p] > 0.0);
        }
    }
    assert!(checked > 10);
    for k in 0..a.cm.len() {
        assert_eq!((t.cm.x[k], t.cm.y[k]), (a.cm.y[k], a.cm.x[k]));
        assert_eq!(r.cm.t[k], 1.0 - a.cm.t[k]);
    }
    // Crop: the 16² block at (8, 4), events outside dropped and the rest shifted.
    let c = sample(
        &d,
        (0.1, 0.2),
        bins,
        Augment {
            crop: Some((8, 4, 16)),
            ..Augment::default()
        },
    );
    assert_eq!(
        (c.voxel.len(), c.target.len(), c.mask.len()),
        (bins * 256, 512, 256)
    );
    for y in 0..16 {
        for x in 0..16 {
            let (p, q) = ((y + 4) * n + x + 8, y * 16 + x);
            assert_eq!(c.mask[q], a.mask[p]);
            assert_eq!(
                (c.target[q], c.target[256 + q]),
                (a.target[p], a.target[plane + p])
            );
            assert_eq!(c.voxel[3 * 256 + q], a.voxel[3 * plane + p]);
        }
    }
    let inside = (0..a.cm.len())
        .filter(|&k| (8.0..24.0).contains(&a.cm.x[k]) && (4.0..20.0).contains(&a.cm.y[k]))
        .count();
    assert!(inside > 0 && c.cm.len() == inside);
    assert!(
        c.cm.x
            .iter()
            .chain(&c.cm.y)
            .all(|v| (0.0..16.0).contains(v))
    );
}

#[test]
fn larger_training_scenes_are_cropped_and_settings_checked() {
    let s = PretrainSettings {
        train_sizes: vec![32, 48],
        presets: vec!["rigid".into(), "fast".into()],
        augment_transpose: true,
        augment_reverse: true,
        eval_speed: Some([0.5, 1.0]),
        iterations: 2,
        ..tiny()
    };
    assert!(s.validate().is_ok());
    let (train, held) = make_scenes(&s).unwrap();
    let sizes: Vec<u32> = train.iter().map(|d| d.events.width).collect();
    assert_eq!(sizes, [32, 48]);
    assert_eq!(train[1].name, "fast/1@48");
    assert!(held.iter().all(|d| d.events.width == 32));
    let dir = tempfile::tempdir().unwrap();
    let r = run(&s, &dir.path().join("o"), false, &mut |_, _, _| {}).unwrap();
    assert!(r.loss_curve.iter().all(|l| l.is_finite()));
    for bad in [
        PretrainSettings {
            train_sizes: vec![16],
            ..tiny()
        },
        PretrainSettings {
            eval_speed: Some([2.0, 1.0]),
            ..tiny()
        },
    ] {
        assert!(bad.validate().is_err());
    }
}

#[test]
fn a_tiny_run_writes_loadable_weights_and_a_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("pre");
    let mut calls = 0;
    let r = run(&tiny(), &out, false, &mut |k, n, l| {
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
    let e = run(&bad, &dir.path().join("bad"), false, &mut |_, _, _| {}).unwrap_err();
    assert!(e.to_string().contains("lr"), "{e}");
    assert!(!dir.path().join("bad").exists());
}
