//! Experiment files: a scene (a directory, or a synthetic preset with its settings)
//! and the settings of each stage.
//!
//! ```toml
//! name = "rigid-baseline"          # names runs/<name>/
//!
//! [scene]
//! synth = "rigid"                  # a preset of `degs synth` …
//! # dir = "../data/shapes"         # … or a scene directory (relative to this file)
//!
//! [scene.settings]                 # only with `synth`: overrides of the preset
//! width = 64
//! camera.sway_hz = 0.5
//!
//! [evflow]                         # handed to the stage as its settings.toml
//! [gaussians]
//! [assoc]
//! [deform]
//! ```
//!
//! The stage tables are those of the stage registry ([`crate::stages`]). Unknown keys
//! are errors that name the key and the file; a stage table is checked by its stage's
//! binary (`STAGE settings --check`, [`Experiment::check_stage_settings`]), which also
//! fills its own defaults.

use crate::canon;
use crate::context;
/// Re-exported: `synth` reads its overrides through these.
pub use crate::overrides::{merge, parse_set};
use crate::settings::{InputFile, toml_section};
use crate::stages::{self, STAGES};
use anyhow::{Context, Result, anyhow, bail};
use serde::Deserialize;
use serde::de::{self, Deserializer, MapAccess, Visitor};
use stagekit::Settings;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::LazyLock;
use synth::{PRESETS, SynthConfig};
use toml::{Table, Value};

/// The top level of an experiment file: `name`, `[scene]` and one table per stage of
/// the registry.
struct RawExperiment {
    name: String,
    scene: RawScene,
    stages: BTreeMap<String, Table>,
}

/// Every top-level key an experiment file may hold.
static TOP_LEVEL_KEYS: LazyLock<Vec<&'static str>> = LazyLock::new(|| {
    ["name", "scene"]
        .into_iter()
        .chain(STAGES.iter().map(|s| s.name))
        .collect()
});

impl<'de> Deserialize<'de> for RawExperiment {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        d.deserialize_map(RawExperimentVisitor)
    }
}

/// A top-level key of an experiment file. An unknown key is an error of the key's own
/// deserialisation, so that it carries the key's position in the file.
enum TopLevelKey {
    Name,
    Scene,
    Stage(String),
}

impl<'de> Deserialize<'de> for TopLevelKey {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let key = String::deserialize(d)?;
        match key.as_str() {
            "name" => Ok(TopLevelKey::Name),
            "scene" => Ok(TopLevelKey::Scene),
            k if stages::find(k).is_some() => Ok(TopLevelKey::Stage(key)),
            k => Err(de::Error::unknown_field(k, &TOP_LEVEL_KEYS[..])),
        }
    }
}

struct RawExperimentVisitor;

impl<'de> Visitor<'de> for RawExperimentVisitor {
    type Value = RawExperiment;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("an experiment: `name`, [scene] and stage tables")
    }

    fn visit_map<A: MapAccess<'de>>(
        self,
        mut map: A,
    ) -> std::result::Result<RawExperiment, A::Error> {
        let (mut name, mut scene, mut stages) = (None, None, BTreeMap::new());
        while let Some(key) = map.next_key::<TopLevelKey>()? {
            match key {
                TopLevelKey::Name => name = Some(map.next_value()?),
                TopLevelKey::Scene => scene = Some(map.next_value()?),
                TopLevelKey::Stage(stage) => {
                    stages.insert(stage, map.next_value::<Table>()?);
                }
            }
        }
        Ok(RawExperiment {
            name: name.ok_or_else(|| de::Error::missing_field("name"))?,
            scene: scene.ok_or_else(|| de::Error::missing_field("scene"))?,
            stages,
        })
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    dir: Option<PathBuf>,
    synth: Option<String>,
    settings: Option<Table>,
}

/// Where the scene comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum SceneSource {
    /// An existing scene directory (docs/DESIGN.md §3 layout).
    Dir(PathBuf),
    /// A synthetic scene, built by the `synth` stage.
    Synth(Box<SynthConfig>),
}

/// A resolved experiment.
#[derive(Clone, Debug)]
pub struct Experiment {
    pub name: String,
    /// The file it was read from (None when built in code, e.g. by `degs demo`).
    pub file: Option<PathBuf>,
    pub scene: SceneSource,
    /// Settings of each stage of [`STAGES`] (empty table when not given).
    pub stages: BTreeMap<String, Table>,
}

impl Experiment {
    /// Read and resolve an experiment file.
    pub fn load(path: &Path) -> Result<Experiment> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read experiment file", path.display()))?;
        Self::parse(&text, path)
    }

    /// Parse experiment text; `path` names it in errors and anchors relative `dir`s.
    pub fn parse(text: &str, path: &Path) -> Result<Experiment> {
        let raw: RawExperiment = toml::from_str(text).map_err(|e| {
            let where_what = stagekit::settings::toml_error(text, &e);
            anyhow!("{}: {where_what}", path.display())
        })?;
        check_name(&raw.name).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let scene = match (raw.scene.dir, raw.scene.synth, raw.scene.settings) {
            (Some(dir), None, None) => {
                let base = path.parent().unwrap_or(Path::new(""));
                SceneSource::Dir(if dir.is_absolute() {
                    dir
                } else {
                    base.join(dir)
                })
            }
            (None, Some(preset), settings) => {
                let cfg = synth_config(&preset, &settings.unwrap_or_default())
                    .map_err(|e| anyhow!("{}: [scene.settings]: {e}", path.display()))?;
                SceneSource::Synth(Box::new(cfg))
            }
            (Some(_), _, _) => bail!(
                "{}: [scene] takes either `dir` or `synth` (with optional [scene.settings]), not both",
                path.display()
            ),
            (None, None, _) => bail!(
                "{}: [scene] needs `dir = \"path\"` or `synth = \"preset\"` (presets: {})",
                path.display(),
                PRESETS.join(", ")
            ),
        };
        let stages = STAGES
            .iter()
            .map(|s| {
                let table = raw.stages.get(s.name).cloned().unwrap_or_default();
                (s.name.to_string(), canon::canonical_table(&table))
            })
            .collect();
        Ok(Experiment {
            name: raw.name,
            file: Some(path.to_path_buf()),
            scene,
            stages,
        })
    }

    /// An experiment on a synthetic scene with default stage settings.
    pub fn synthetic(name: &str, cfg: SynthConfig) -> Experiment {
        let stages = STAGES
            .iter()
            .map(|s| (s.name.to_string(), Table::new()))
            .collect();
        Experiment {
            name: name.to_string(),
            file: None,
            scene: SceneSource::Synth(Box::new(cfg)),
            stages,
        }
    }

    /// Read an experiment file and check every stage table against its stage's
    /// settings (see [`Experiment::check_stage_settings`]).
    pub fn load_checked(path: &Path, ctx: &context::Context) -> Result<Experiment> {
        let exp = Self::load(path)?;
        exp.check_stage_settings(ctx)?;
        for w in exp.check_scene()? {
            eprintln!("[degs] warning: {w}");
        }
        Ok(exp)
    }

    /// The scene checks ([`scene::check`]) on a scene directory, before any stage runs:
    /// an error names the experiment file and the scene; the warnings are returned. A
    /// synthetic scene's settings were checked when it was parsed (a test time on a
    /// train time is an error there).
    pub fn check_scene(&self) -> Result<Vec<String>> {
        let SceneSource::Dir(dir) = &self.scene else {
            return Ok(Vec::new());
        };
        let file = self
            .file
            .as_deref()
            .map(|f| format!("{}: ", f.display()))
            .unwrap_or_default();
        let scene = scene::Scene::open(dir).map_err(|e| anyhow!("{file}scene: {e}"))?;
        let findings =
            scene::check::check_scene(&scene).map_err(|e| anyhow!("{file}scene: {e}"))?;
        if let Some(e) = scene::check::first_error(dir, &findings) {
            bail!("{file}scene {e}");
        }
        Ok(findings
            .into_iter()
            .map(|f| format!("{file}scene {}: {}", dir.display(), f.message))
            .collect())
    }

    /// Check every stage table against its stage's settings, as its binary reads them
    /// (`STAGE settings --check`, [`crate::settings::check`]), so that a typo in
    /// `[gaussians]` is an error naming the file, the stage and the key before any
    /// stage runs. A stage whose binary is not built is not checked here: the run
    /// says it is not built.
    pub fn check_stage_settings(&self, ctx: &context::Context) -> Result<()> {
        // One process per stage, asked at once; the answers are remembered for the
        // graph's resolution ([`crate::settings`]).
        let checks: Vec<Result<Vec<InputFile>>> = std::thread::scope(|scope| {
            let handles: Vec<_> = STAGES
                .iter()
                .filter_map(|stage| Some((stage, ctx.stage_binary(stage.binary)?)))
                .map(|(stage, binary)| scope.spawn(move || self.check_stage(stage.name, &binary)))
                .collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join()
                        .unwrap_or_else(|_| Err(anyhow!("a settings check panicked")))
                })
                .collect()
        });
        for c in checks {
            c?;
        }
        Ok(())
    }

    /// Check the table of `stage` with its binary: Ok(the files outside the graph the
    /// settings make it read), or an error naming the file, the stage and the key.
    pub(crate) fn check_stage(&self, stage: &str, binary: &Path) -> Result<Vec<InputFile>> {
        match crate::settings::check(binary, &self.settings(stage))? {
            Ok(files) => Ok(files),
            Err(e) => {
                let file = self
                    .file
                    .as_deref()
                    .map(|f| format!("{}: ", f.display()))
                    .unwrap_or_default();
                bail!("{file}[{stage}]: {e}")
            }
        }
    }

    /// Settings of `stage` (empty when the experiment has none).
    pub fn settings(&self, stage: &str) -> Table {
        self.stages.get(stage).cloned().unwrap_or_default()
    }

    /// The resolved experiment as TOML, every synthetic-scene default written out
    /// (`degs config show` adds each stage's defaults as comments).
    pub fn to_toml(&self) -> String {
        let mut out = self.scene_toml();
        for stage in STAGES.iter().map(|s| s.name) {
            out += &format!(
                "\n# {stage}: keys not set here take the defaults of the `{stage}` binary \
                 (its resolved settings land in the cache entry's settings.toml)\n"
            );
            out += &toml_section(stage, &self.settings(stage));
        }
        out
    }

    /// `name` and the `[scene]` part of [`Experiment::to_toml`].
    pub(crate) fn scene_toml(&self) -> String {
        let mut out = format!("name = {}\n\n[scene]\n", Value::String(self.name.clone()));
        match &self.scene {
            SceneSource::Dir(d) => {
                out += &format!("dir = {}\n", Value::String(d.display().to_string()));
            }
            SceneSource::Synth(cfg) => {
                out += &format!("synth = {}\n\n", Value::String(cfg.preset.clone()));
                let mut wrap = Table::new();
                let mut scene = Table::new();
                let cfg_value = Value::try_from(cfg.as_ref()).unwrap_or(Value::Table(Table::new()));
                scene.insert("settings".into(), cfg_value);
                wrap.insert("scene".into(), Value::Table(scene));
                out += &toml::to_string(&wrap).unwrap_or_default();
            }
        }
        out
    }
}

fn check_name(name: &str) -> std::result::Result<(), String> {
    let ok = !name.is_empty()
        && name.len() <= 100
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'));
    if ok {
        Ok(())
    } else {
        Err(format!(
            "name {name:?} must be 1-100 characters of A-Z a-z 0-9 - _ . (it names runs/<name>/)"
        ))
    }
}

/// The preset `preset` with `overrides` merged in (nested tables merge, other values
/// replace). Unknown keys are errors that name the key.
pub fn synth_config(preset: &str, overrides: &Table) -> std::result::Result<SynthConfig, String> {
    let base = SynthConfig::preset(preset).ok_or_else(|| {
        format!(
            "unknown synthetic preset {preset:?} (presets: {})",
            PRESETS.join(", ")
        )
    })?;
    let mut value = Value::try_from(&base).map_err(|e| e.to_string())?;
    if let Value::Table(t) = &mut value {
        merge(t, overrides);
    }
    let cfg: SynthConfig = value
        .try_into()
        .map_err(|e: toml::de::Error| e.message().trim().to_string())?;
    cfg.validate()?;
    Ok(cfg)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Experiment> {
        Experiment::parse(text, Path::new("/exp/a.toml"))
    }

    #[test]
    fn synthetic_scene_with_overrides() {
        let e = parse(
            "name = \"a\"\n[scene]\nsynth = \"rigid\"\n[scene.settings]\nwidth = 64\n\
             [gaussians]\niters = 10\n",
        )
        .unwrap();
        let SceneSource::Synth(cfg) = &e.scene else {
            panic!("expected a synthetic scene")
        };
        assert_eq!((cfg.width, cfg.height), (64, 128));
        assert_eq!(
            e.settings("gaussians").get("iters"),
            Some(&Value::Integer(10))
        );
        assert!(e.settings("evflow").is_empty());
    }

    #[test]
    fn relative_dir_is_anchored_at_the_file() {
        let e = parse("name = \"a\"\n[scene]\ndir = \"scenes/x\"\n").unwrap();
        assert_eq!(e.scene, SceneSource::Dir(PathBuf::from("/exp/scenes/x")));
    }

    #[test]
    fn unknown_keys_name_the_key_and_file() {
        for (text, key) in [
            (
                "name = \"a\"\nbogus = 1\n[scene]\nsynth = \"rigid\"\n",
                "bogus",
            ),
            ("name = \"a\"\n[scene]\nsynth = \"rigid\"\nwat = 2\n", "wat"),
            (
                "name = \"a\"\n[scene]\nsynth = \"rigid\"\n[scene.settings]\nwidht = 3\n",
                "widht",
            ),
            (
                "name = \"a\"\n[scene]\nsynth = \"rigid\"\n[deformm]\n",
                "deformm",
            ),
        ] {
            let msg = parse(text).unwrap_err().to_string();
            assert!(msg.contains(key), "{msg}");
            assert!(msg.contains("/exp/a.toml"), "{msg}");
        }
    }

    #[test]
    fn bad_scene_specs_are_errors() {
        assert!(parse("name = \"a\"\n[scene]\n").is_err());
        assert!(parse("name = \"a\"\n[scene]\ndir = \"x\"\nsynth = \"rigid\"\n").is_err());
        let msg = parse("name = \"a\"\n[scene]\nsynth = \"nope\"\n")
            .unwrap_err()
            .to_string();
        assert!(msg.contains("nope") && msg.contains("rigid"), "{msg}");
        assert!(parse("name = \"../x\"\n[scene]\nsynth = \"rigid\"\n").is_err());
        assert!(parse("").is_err());
        assert!(parse("name = ").is_err());
        assert!(parse("\u{0}\u{1}garbage").is_err());
    }

    #[test]
    fn config_show_round_trips() {
        let e = parse(
            "name = \"a\"\n[scene]\nsynth = \"fast\"\n[scene.settings]\nseed = 7\n[deform]\nlr = 0.01\n",
        )
        .unwrap();
        let again = parse(&e.to_toml()).unwrap();
        assert_eq!(again.scene, e.scene);
        assert_eq!(again.stages, e.stages);
        // nested stage tables stay under their stage
        let e = parse(
            "name = \"a\"\n[scene]\nsynth = \"rigid\"\n[gaussians]\niterations = 5\n\
             [gaussians.field]\nwidth = 32\n",
        )
        .unwrap();
        let again = parse(&e.to_toml()).unwrap();
        assert_eq!(again.stages, e.stages);
    }

    #[test]
    fn set_assignments_nest_and_type() {
        let t = parse_set(&[
            "width=64".into(),
            "camera.sway_hz=0.5".into(),
            "preset=x".into(),
        ])
        .unwrap();
        assert_eq!(t.get("width"), Some(&Value::Integer(64)));
        assert_eq!(
            t["camera"].as_table().unwrap().get("sway_hz"),
            Some(&Value::Float(0.5))
        );
        assert_eq!(t.get("preset"), Some(&Value::String("x".into())));
        assert!(parse_set(&["novalue".into()]).is_err());
        let cfg = synth_config("rigid", &t).unwrap();
        assert_eq!(cfg.camera.sway_hz, 0.5);
        assert!(synth_config("rigid", &parse_set(&["nosuch=1".into()]).unwrap()).is_err());
    }
}
