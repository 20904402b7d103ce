//! The keys of a synthetic config: the simulator's settings nested under `events`, the
//! flat keys of older files still read, defaults from the `rigid` preset.

use stagekit::Settings;
use synth::{SimConfig, SynthConfig};

fn from_toml(text: &str) -> Result<SynthConfig, String> {
    toml::from_str(text).map_err(|e| e.message().to_string())
}

#[test]
fn the_simulator_settings_are_written_as_a_nested_table() {
    let cfg = SynthConfig::preset("fast").unwrap();
    let text = toml::to_string(&cfg).unwrap();
    let table: toml::Table = text.parse().unwrap();
    let events = table["events"].as_table().unwrap();
    assert_eq!(events["threshold_pos"].as_float(), Some(0.1));
    assert_eq!(events["threshold_neg"].as_float(), Some(0.1));
    assert_eq!(events["threshold_sigma"].as_float(), Some(0.0));
    for (flat, _) in synth::keys::FLAT_EVENT_KEYS {
        assert!(!table.contains_key(flat), "{flat} written flat");
    }
    assert_eq!(from_toml(&text).unwrap(), cfg);
    let json = serde_json::to_string(&cfg).unwrap();
    assert_eq!(serde_json::from_str::<SynthConfig>(&json).unwrap(), cfg);
}

#[test]
fn the_flat_keys_of_older_files_are_read() {
    let old = from_toml(
        "width = 64\ncontrast_threshold = 0.2\nthreshold_sigma = 0.01\nrefractory_s = 0.001\n\
         shot_noise_hz = 3.0\nhot_pixel_fraction = 0.02\nhot_pixel_hz = 40.0\n",
    )
    .unwrap();
    let new = from_toml(
        "width = 64\n[events]\nthreshold_pos = 0.2\nthreshold_neg = 0.2\n\
         threshold_sigma = 0.01\nrefractory_s = 0.001\nshot_noise_hz = 3.0\n\
         hot_pixel_fraction = 0.02\nhot_pixel_hz = 40.0\n",
    )
    .unwrap();
    assert_eq!(old, new);
    assert_eq!(
        old.events,
        SimConfig {
            threshold_pos: 0.2,
            threshold_neg: 0.2,
            threshold_sigma: 0.01,
            refractory_s: 0.001,
            shot_noise_hz: 3.0,
            hot_pixel_fraction: 0.02,
            hot_pixel_hz: 40.0,
            ..SynthConfig::default().events
        }
    );
    // A flat key is applied last, over the same setting in `events`.
    let both = from_toml("shot_noise_hz = 5.0\n[events]\nshot_noise_hz = 1.0\n").unwrap();
    assert_eq!(both.events.shot_noise_hz, 5.0);
    // JSON too.
    let json: SynthConfig = serde_json::from_str(r#"{"contrast_threshold": 0.3}"#).unwrap();
    assert_eq!(
        (json.events.threshold_pos, json.events.threshold_neg),
        (0.3, 0.3)
    );
}

#[test]
fn missing_keys_take_the_rigid_presets_values_inside_events_too() {
    let cfg = from_toml("[events]\nshot_noise_hz = 2.0\n").unwrap();
    let rigid = SynthConfig::default();
    assert_eq!(
        cfg.events,
        SimConfig {
            shot_noise_hz: 2.0,
            ..rigid.events.clone()
        }
    );
    // The preset's sensor has no threshold mismatch, unlike the simulator's default.
    assert_eq!(cfg.events.threshold_sigma, 0.0);
    assert_ne!(SimConfig::default().threshold_sigma, 0.0);
    assert_eq!(from_toml("").unwrap(), rigid);
}

#[test]
fn unknown_and_mistyped_keys_are_errors_that_name_the_key() {
    for (text, key) in [
        ("widht = 3\n", "widht"),
        ("[events]\nthreshold = 0.1\n", "threshold"),
        ("contrast_threshold = \"high\"\n", "high"),
    ] {
        let e = from_toml(text).unwrap_err();
        assert!(e.contains(key), "{text}: {e}");
    }
    assert!(from_toml("events = 3\n").is_err());
    let cfg = from_toml("[events]\nthreshold_pos = -1.0\n").unwrap();
    assert!(cfg.validate().unwrap_err().contains("events.threshold_pos"));
}

/// The LoCM benchmark scenes (`evflow/benches/scenes/*.toml`) are written with the flat
/// keys; they read as before.
#[test]
fn the_benchmark_scene_files_read_with_their_flat_keys() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../evflow/benches/scenes");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let cfg = from_toml(&std::fs::read_to_string(&path).unwrap()).unwrap();
        cfg.validate().unwrap();
        assert_eq!(
            cfg.events,
            SynthConfig::default().events,
            "{}",
            path.display()
        );
        n += 1;
    }
    assert!(n >= 2);
}
