//! Save / load of models: bit-exact round trips and errors that name the file.

use super::*;
use crate::field::FieldSettings;
use crate::splats::Gaussian;

/// `n` scattered Gaussians with varied scales, opacities and colours, all dynamic (the
/// model's files need no trainer to make them).
fn random_splats(n: usize, _centre: glam::DVec3, half: f64, seed: u64) -> Splats {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut unit = move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut s = Splats::with_capacity(n);
    for _ in 0..n {
        let p: [f32; 3] = std::array::from_fn(|_| half as f32 * (2.0 * unit() - 1.0));
        let log_scale = (0.02 + 0.1 * unit()).ln();
        let opacity_logit = 4.0 * unit() - 2.0;
        let sh_dc = std::array::from_fn(|_| unit() - 0.5);
        s.push(Gaussian {
            dynamic: true,
            ..Gaussian::isotropic(p, log_scale, opacity_logit, sh_dc)
        });
    }
    s
}

fn model(with_field: bool) -> Model {
    let mut splats = random_splats(50, glam::DVec3::ZERO, 1.0, 3);
    for (i, r) in splats.sh_rest.iter_mut().enumerate() {
        r[0] = 0.01 * i as f32;
        r[44] = -0.02 * i as f32;
    }
    splats.dynamic = (0..50).map(|i| i % 3 != 0).collect();
    let field = with_field.then(|| {
        let s = FieldSettings {
            depth: 2,
            width: 16,
            ..FieldSettings::default()
        };
        Mlp::<f32>::new(s, 7)
    });
    Model {
        info: ModelInfo {
            dynamic_only: true,
            gaussians: 50,
            background: [0.25, 0.5, 1.0],
            ..ModelInfo::default()
        },
        splats,
        field,
    }
}

#[test]
fn save_load_round_trips_bit_exactly() {
    for with_field in [false, true] {
        let dir = tempfile::tempdir().unwrap();
        let m = model(with_field);
        m.save(dir.path()).unwrap();
        let back = Model::load(dir.path()).unwrap();
        assert_eq!(back.splats, m.splats);
        assert_eq!(back.info.gaussians, 50);
        assert_eq!(back.info.has_field, with_field);
        assert_eq!(back.info.background, m.info.background);
        match (&back.field, &m.field) {
            (Some(a), Some(b)) => {
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a.params), bits(&b.params));
                assert_eq!(a.settings, b.settings);
            }
            (None, None) => {}
            _ => panic!("field presence differs"),
        }
        for t in [0.0, 0.4, 1.0] {
            assert_eq!(back.at(t), m.at(t));
        }
    }
}

#[test]
fn field_moves_only_dynamic_gaussians() {
    let m = model(true);
    let a = m.at(0.7);
    let mut moved = 0;
    for i in 0..50 {
        if !m.splats.dynamic[i] {
            assert_eq!(a.means[i], m.splats.means[i]);
        } else if a.means[i] != m.splats.means[i] {
            moved += 1;
        }
    }
    assert!(moved > 0);
    assert_eq!(model(false).at(0.3), model(false).splats);
}

fn err_of(dir: &Path) -> String {
    Model::load(dir).unwrap_err().to_string()
}

#[test]
fn missing_or_corrupt_files_give_errors_naming_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    assert!(err_of(d).contains(INFO_FILE));
    model(true).save(d).unwrap();
    let info = std::fs::read_to_string(d.join(INFO_FILE)).unwrap();

    std::fs::write(d.join(INFO_FILE), "{ not json").unwrap();
    assert!(err_of(d).contains(INFO_FILE));
    std::fs::write(
        d.join(INFO_FILE),
        info.replace("\"gaussians\": 50", "\"gaussians\": 49"),
    )
    .unwrap();
    let e = err_of(d);
    assert!(e.contains(PLY_FILE) && e.contains("49"), "{e}");
    std::fs::write(
        d.join(INFO_FILE),
        info.replace("\"sh_degree\": 3", "\"sh_degree\": 2"),
    )
    .unwrap();
    assert!(err_of(d).contains(PLY_FILE));
    std::fs::write(
        d.join(INFO_FILE),
        info.replacen("\"format_version\": 2", "\"format_version\": 3", 1),
    )
    .unwrap();
    assert!(Model::load(d).is_err());
    std::fs::write(d.join(INFO_FILE), &info).unwrap();
    Model::load(d).unwrap();

    let w = d.join(field::io::WEIGHTS_FILE);
    let bytes = std::fs::read(&w).unwrap();
    std::fs::write(&w, &bytes[..bytes.len() / 2]).unwrap();
    assert!(err_of(d).contains(field::io::WEIGHTS_FILE));
    std::fs::remove_file(&w).unwrap();
    assert!(err_of(d).contains(field::io::WEIGHTS_FILE));
    std::fs::remove_file(d.join(field::io::SETTINGS_FILE)).unwrap();
    assert!(err_of(d).contains(field::io::SETTINGS_FILE));
    std::fs::remove_file(d.join(PLY_FILE)).unwrap();
    assert!(err_of(d).contains(PLY_FILE));
}

#[test]
fn render_uses_the_saved_background() {
    let mut m = model(false);
    m.splats = Splats::default();
    m.info.gaussians = 0;
    let cam = scene::Camera {
        intrinsics: scene::Intrinsics::from_fov_x(16, 8, 1.0),
        cam_to_world: scene::Pose::default(),
    };
    let f = m.render(&cam, 0.5);
    assert_eq!((f.width, f.height), (16, 8));
    assert!(f.rgb[..128].iter().all(|&v| v == 0.25));
    assert!(f.rgb[256..].iter().all(|&v| v == 1.0));
}

/// `n` Gaussians with an irregular pattern of dynamic flags.
fn flagged_model(n: usize) -> Model {
    let mut splats = random_splats(n, glam::DVec3::ZERO, 1.0, 11);
    splats.dynamic = (0..n).map(|i| (i * 7919 + i / 3) % 5 < 2).collect();
    Model {
        info: ModelInfo {
            dynamic_only: true,
            ..ModelInfo::default()
        },
        splats,
        field: None,
    }
}

#[test]
fn dynamic_flags_are_in_their_binary_file_and_round_trip_bit_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut m = flagged_model(32_768);
    m.save(d).unwrap();
    let info = std::fs::read_to_string(d.join(INFO_FILE)).unwrap();
    assert!(info.len() < 1000, "model.json is {} bytes", info.len());
    assert!(info.contains("\"has_dynamic_flags\": true"), "{info}");
    assert!(!info.contains("\"dynamic\""), "{info}");
    let bytes = std::fs::read(d.join(FLAGS_FILE)).unwrap();
    let body = &bytes[bytes.len() - 32_768..];
    assert!(
        body.iter()
            .zip(&m.splats.dynamic)
            .all(|(&b, &f)| b == f as u8)
    );
    let back = Model::load(d).unwrap();
    assert_eq!(back.splats, m.splats);
    assert!(back.info.has_dynamic_flags);

    // Without flags the model claims no flags file (a stale one is not read).
    m.splats.dynamic.clear();
    m.save(d).unwrap();
    let back = Model::load(d).unwrap();
    assert!(back.splats.dynamic.is_empty() && !back.info.has_dynamic_flags);
    assert!(back.splats.is_dynamic(0));
}

#[test]
fn corrupt_or_truncated_dynamic_flags_give_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let m = flagged_model(50);
    m.save(d).unwrap();
    let f = d.join(FLAGS_FILE);
    let good = std::fs::read(&f).unwrap();
    let expect = |what: &str, also: &str| {
        let e = err_of(d);
        assert!(e.contains(FLAGS_FILE) && e.contains(also), "{what}: {e}");
        eprintln!("{what}: {e}");
    };
    for cut in [0, 7, 8, good.len() / 2, good.len() - 1] {
        std::fs::write(&f, &good[..cut]).unwrap();
        expect(&format!("truncated at {cut}"), "");
    }
    // The last byte is the last Gaussian's flag.
    let mut bad = good.clone();
    *bad.last_mut().unwrap() = 2;
    std::fs::write(&f, &bad).unwrap();
    expect("flag byte 2", "Gaussian 49");
    dynamic_flags::write(&f, &[true; 49]).unwrap();
    expect("49 flags for 50 Gaussians", "[49]");
    let tensor =
        safetensors::tensor::TensorView::new(safetensors::Dtype::U8, vec![50], &[1u8; 50]).unwrap();
    let data = safetensors::serialize([(dynamic_flags::FLAGS_TENSOR, tensor)], None).unwrap();
    std::fs::write(&f, data).unwrap();
    expect("u8 instead of bool", "U8");
    std::fs::remove_file(&f).unwrap();
    expect("missing", "");
    std::fs::write(&f, &good).unwrap();
    assert_eq!(Model::load(d).unwrap().splats.dynamic, m.splats.dynamic);
}

#[test]
fn format_1_models_with_the_flags_in_model_json_still_load() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let m = model(true);
    m.save(d).unwrap();
    // Rewrite the files as format 1 wrote them: the flags as a '0'/'1' string.
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join(INFO_FILE)).unwrap()).unwrap();
    let flags: String = m
        .splats
        .dynamic
        .iter()
        .map(|&f| if f { '1' } else { '0' })
        .collect();
    let obj = v.as_object_mut().unwrap();
    obj.insert("format_version".into(), 1.into());
    obj.remove("has_dynamic_flags");
    obj.insert("dynamic".into(), flags.clone().into());
    let legacy = serde_json::to_string_pretty(&v).unwrap();
    std::fs::write(d.join(INFO_FILE), &legacy).unwrap();
    std::fs::remove_file(d.join(FLAGS_FILE)).unwrap();

    let back = Model::load(d).unwrap();
    assert_eq!(back.splats, m.splats);
    assert_eq!(back.info.format_version, FORMAT_VERSION);
    assert!(back.info.has_dynamic_flags);
    for t in [0.0, 0.6] {
        assert_eq!(back.at(t), m.at(t));
    }
    // Saved again, it is format 2.
    let again = dir.path().join("again");
    back.save(&again).unwrap();
    assert!(again.join(FLAGS_FILE).is_file());
    assert_eq!(Model::load(&again).unwrap().splats, m.splats);

    // A bad string names model.json; none means every Gaussian dynamic.
    std::fs::write(d.join(INFO_FILE), legacy.replace(&flags, &flags[1..])).unwrap();
    let e = err_of(d);
    assert!(e.contains(INFO_FILE) && e.contains("dynamic"), "{e}");
    std::fs::write(d.join(INFO_FILE), legacy.replace(&flags, "x")).unwrap();
    assert!(err_of(d).contains(INFO_FILE));
    v.as_object_mut().unwrap().remove("dynamic");
    std::fs::write(d.join(INFO_FILE), v.to_string()).unwrap();
    assert!(Model::load(d).unwrap().splats.dynamic.is_empty());
}
