//! The model readers against thousands of damaged copies of a valid file
//! (`testkit::mutate`, docs/DESIGN.md "Inputs that cannot hurt"): the 3DGS PLY
//! (binary as written, and ASCII), `model.json`, the deformation field
//! (`field.safetensors` + `field.json`), the dynamic flags (`dynamic.safetensors`) and
//! the warm-up's `settings.toml` (which `deform` reads).

#[global_allocator]
static ALLOC: testkit::TrackingAlloc = testkit::TrackingAlloc;

use gaussians::field::{FieldSettings, Mlp};
use gaussians::model::{FLAGS_FILE, INFO_FILE, Model, ModelInfo, PLY_FILE};
use gaussians::train::TrainSettings;
use gaussians::train::init::random_splats;
use std::fs;
use std::path::Path;
use testkit::{Plan, fuzz};

/// A saved model of 40 Gaussians (SH degree 1) with dynamic flags and a small field.
fn save_model(dir: &Path) {
    let mut splats = random_splats(40, glam::DVec3::ZERO, 1.0, 3);
    splats.dynamic = (0..40).map(|i| i % 3 != 0).collect();
    let field = Mlp::<f32>::new(
        FieldSettings {
            depth: 2,
            width: 8,
            ..FieldSettings::default()
        },
        7,
    );
    Model {
        info: ModelInfo {
            sh_degree: 1,
            gaussians: 40,
            ..ModelInfo::default()
        },
        splats,
        field: Some(field),
    }
    .save(dir)
    .unwrap();
}

/// Damage one file of a saved model and load the whole model.
fn fuzz_model_file(name: &str, seed: u64, mutations: usize, length_fields: Vec<(usize, usize)>) {
    let dir = tempfile::tempdir().unwrap();
    save_model(dir.path());
    let path = dir.path().join(name);
    let bytes = fs::read(&path).unwrap();
    let mut plan = Plan::new(seed);
    plan.mutations = mutations;
    plan.length_fields = length_fields;
    fuzz(&path, &bytes, &plan, |_| Model::load(dir.path())).assert_clean();
}

#[test]
fn ply_reader() {
    let _alone = testkit::alloc::exclusive();
    fuzz_model_file(PLY_FILE, 31, 2000, vec![]);
}

#[test]
fn model_json_reader() {
    let _alone = testkit::alloc::exclusive();
    fuzz_model_file(INFO_FILE, 32, 2000, vec![]);
}

#[test]
fn field_readers() {
    let _alone = testkit::alloc::exclusive();
    fuzz_model_file("field.safetensors", 33, 1000, vec![(0, 8)]);
    fuzz_model_file("field.json", 34, 1000, vec![]);
}

#[test]
fn dynamic_flags_reader() {
    let _alone = testkit::alloc::exclusive();
    fuzz_model_file(FLAGS_FILE, 35, 1000, vec![(0, 8)]);
}

/// An ASCII PLY (other tools write these): its vertex count is text.
#[test]
fn ascii_ply_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ascii.ply");
    let names = gaussians::ply::property_names(0);
    let mut text = String::from("ply\nformat ascii 1.0\nelement vertex 3\n");
    for n in &names {
        text += &format!("property float {n}\n");
    }
    text += "end_header\n";
    for i in 0..3 {
        let row: Vec<String> = (0..names.len())
            .map(|k| format!("{}", 0.125 * (i * names.len() + k) as f32))
            .collect();
        text += &row.join(" ");
        text += "\n";
    }
    let plan = Plan::new(36);
    fuzz(&path, text.as_bytes(), &plan, gaussians::ply::read).assert_clean();
}

#[test]
fn warmup_settings_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    stagekit::settings::write_resolved(dir.path(), &TrainSettings::default()).unwrap();
    let path = dir.path().join("settings.toml");
    let bytes = fs::read(&path).unwrap();
    let mut plan = Plan::new(37);
    plan.mutations = 1500;
    fuzz(&path, &bytes, &plan, |p| {
        stagekit::settings::resolve::<TrainSettings>(Some(p), |_| {})
    })
    .assert_clean();
}

/// Regression (found reading the field reader for the harness's hostile sizes): a
/// `field.json` claiming 64 layers of width 8192 made the reader allocate 17 GB of
/// parameters before looking at the weights file. Now the count is checked against it.
#[test]
fn field_settings_larger_than_the_weights_are_refused_before_allocating() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    save_model(dir.path());
    let path = dir.path().join("field.json");
    let text = fs::read_to_string(&path).unwrap();
    let text = text
        .replace("\"depth\": 2", "\"depth\": 64")
        .replace("\"width\": 8", "\"width\": 8192");
    assert!(text.contains("8192") && text.contains("64"), "{text}");
    fs::write(&path, text).unwrap();
    let (r, peak) = testkit::alloc::peak_during(|| Model::load(dir.path()));
    let msg = r.unwrap_err().to_string();
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    assert!(
        msg.contains("parameters but field.safetensors holds"),
        "{msg}"
    );
    assert!(peak < 4 << 20, "{peak} bytes");
}

/// Regression (found by the harness): `"width": 0` in `field.json` made building the
/// field panic (a uniform range of ±1/√0); now it is refused naming the file.
#[test]
fn field_of_width_zero_is_refused() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    save_model(dir.path());
    let path = dir.path().join("field.json");
    let text = fs::read_to_string(&path).unwrap();
    fs::write(&path, text.replace("\"width\": 8", "\"width\": 0")).unwrap();
    let msg = Model::load(dir.path()).unwrap_err().to_string();
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    assert!(msg.contains("field settings out of range"), "{msg}");
}
