//! Sweep files: a base experiment and axes whose cartesian product expands to
//! experiments (`degs sweep`, `degs plan SWEEP.toml`).
//!
//! ```toml
//! name = "iters-x-field"          # runs/<name>/sweep.json; prefixes every experiment
//! base = "nonrigid.toml"          # an experiment file (relative to this file) …
//! # [base]                        # … or the experiment inline (its `name` optional)
//! [axes]                          # dotted paths into the experiment → values
//! "deform.iterations" = [2000, 5000]
//! "gaussians.field.width" = [32, 64]
//! "scene.settings.width" = [64, 96]
//! ```
//!
//! An axis is any key of the experiment file below `[scene]` or a stage table; each
//! expanded experiment is the base file's TOML with the axis values set, parsed and
//! checked like an experiment file ([`Experiment::parse`]; its stage tables by the
//! stage binaries, [`Sweep::check_stages`]), so an unknown or mistyped key is an error
//! naming the sweep file and the axis before anything runs.

use anyhow::{Context, Result, anyhow, bail};
use runner::experiment::Experiment;
use runner::stages;
use std::path::{Path, PathBuf};
use toml::{Table, Value};

/// One axis: a dotted key into the experiment and the values it takes.
#[derive(Clone, Debug, PartialEq)]
pub struct Axis {
    pub key: String,
    pub values: Vec<Value>,
}

/// A parsed sweep file.
#[derive(Clone, Debug)]
pub struct Sweep {
    pub name: String,
    pub file: PathBuf,
    /// The base experiment's TOML (before any axis is applied).
    base: Table,
    /// The file that anchors the base's relative scene `dir`.
    base_file: PathBuf,
    /// In key order.
    pub axes: Vec<Axis>,
}

/// One experiment of a sweep: its axis values (in axis order) and the experiment.
#[derive(Clone, Debug)]
pub struct Point {
    pub values: Vec<(String, Value)>,
    pub experiment: Experiment,
}

const SWEEP_KEYS: [&str; 3] = ["name", "base", "axes"];

/// A sweep-like file's top-level table and its `name` (default: the file's stem), after
/// checking it has only `keys` (`what` names the file's kind in the error).
pub(crate) fn parse_named_table(
    text: &str,
    path: &Path,
    keys: &[&str],
    what: &str,
) -> Result<(Table, String)> {
    let at = |e: String| anyhow!("{}: {e}", path.display());
    let mut top: Table = text
        .parse()
        .map_err(|e: toml::de::Error| at(e.message().trim().to_string()))?;
    if let Some(k) = top.keys().find(|k| !keys.contains(&k.as_str())) {
        return Err(at(format!(
            "unknown key `{k}` ({what} has {})",
            keys.join(", ")
        )));
    }
    let name = match top.remove("name") {
        Some(Value::String(s)) => s,
        Some(_) => return Err(at("`name` must be a string".into())),
        None => path
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default(),
    };
    Ok((top, name))
}

impl Sweep {
    pub fn load(path: &Path) -> Result<Sweep> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read sweep file", path.display()))?;
        Self::parse(&text, path)
    }

    /// Parse sweep text; `path` names it in errors and anchors a relative `base`.
    pub fn parse(text: &str, path: &Path) -> Result<Sweep> {
        let at = |e: String| anyhow!("{}: {e}", path.display());
        let (mut top, name) = parse_named_table(text, path, &SWEEP_KEYS, "a sweep file")?;
        let (base, base_file) = take_base(&mut top, path)?;
        let axes = match top.remove("axes") {
            None => Vec::new(),
            Some(Value::Table(t)) => t
                .into_iter()
                .map(|(key, v)| match v {
                    Value::Array(values) if !values.is_empty() => Ok(Axis { key, values }),
                    _ => Err(at(format!(
                        "axis \"{key}\" must be a non-empty list of values"
                    ))),
                })
                .collect::<Result<_>>()?,
            Some(_) => return Err(at("[axes] must be a table of key = [values]".into())),
        };
        let sweep = Sweep {
            name,
            file: path.to_path_buf(),
            base,
            base_file,
            axes,
        };
        sweep.check_axes()?;
        Ok(sweep)
    }

    /// A sweep of no axes over `base` (read from `base_file`): the experiments of a
    /// file that expands its own way (`degs stress`) made with [`Sweep::experiment`].
    pub(crate) fn over_base(name: &str, file: &Path, base: Table, base_file: PathBuf) -> Sweep {
        Sweep {
            name: name.into(),
            file: file.to_path_buf(),
            base,
            base_file,
            axes: Vec::new(),
        }
    }

    /// Every axis key names a setting of the scene or of a stage, and each of its
    /// values is accepted there (checked on the base experiment, one axis at a time).
    fn check_axes(&self) -> Result<()> {
        let file = self.file.display();
        for axis in &self.axes {
            let parts: Vec<&str> = axis.key.split('.').collect();
            let known = parts[0] == "scene" || stages::find(parts[0]).is_some();
            if !known || parts.len() < 2 || parts.iter().any(|p| p.is_empty()) {
                bail!(
                    "{file}: axis \"{}\": not a setting; an axis is a dotted key below \
                     scene or a stage: scene.settings.<key>, {}.<key>",
                    axis.key,
                    stages::STAGES
                        .iter()
                        .map(|s| s.name)
                        .collect::<Vec<_>>()
                        .join(".<key>, ")
                );
            }
            let mut seen: Vec<String> = Vec::new();
            for v in &axis.values {
                let text =
                    runner::canon::canonical_string(&Table::from_iter([("v".into(), v.clone())]));
                if seen.contains(&text) {
                    bail!("{file}: axis \"{}\": value {v} appears twice", axis.key);
                }
                seen.push(text);
                self.experiment(&self.name, &[(axis.key.clone(), v.clone())])
                    .map_err(|e| anyhow!("{file}: axis \"{}\" = {v}: {e:#}", axis.key))?;
            }
        }
        Ok(())
    }

    /// Every stage table of the base and of each axis value, checked by the stage's
    /// binary ([`Experiment::check_stage_settings`]); an error names the file, the
    /// axis and its value, the stage and the key.
    pub fn check_stages(&self, ctx: &runner::context::Context) -> Result<()> {
        let file = self.file.display();
        self.experiment(&self.name, &[])?
            .check_stage_settings(ctx)
            .map_err(|e| anyhow!("{file}: base: {e:#}"))?;
        for axis in &self.axes {
            for v in &axis.values {
                self.experiment(&self.name, &[(axis.key.clone(), v.clone())])?
                    .check_stage_settings(ctx)
                    .map_err(|e| anyhow!("{file}: axis \"{}\" = {v}: {e:#}", axis.key))?;
            }
        }
        Ok(())
    }

    /// The base with `values` (dotted keys) set, named `name`, parsed (its scene
    /// checked; its stage tables are checked by [`Sweep::check_stages`]).
    pub fn experiment(&self, name: &str, values: &[(String, Value)]) -> Result<Experiment> {
        let mut t = self.base.clone();
        t.insert("name".into(), Value::String(name.into()));
        for (key, v) in values {
            set_dotted(&mut t, key, v.clone())?;
        }
        let text = toml::to_string(&t).map_err(|e| anyhow!("{e}"))?;
        let mut exp = Experiment::parse(&text, &self.base_file)?;
        if let runner::experiment::SceneSource::Dir(d) = &exp.scene {
            let abs = std::path::absolute(d).unwrap_or_else(|_| d.clone());
            exp.scene = runner::experiment::SceneSource::Dir(abs);
        }
        exp.file = None;
        Ok(exp)
    }

    /// The cartesian product of the axes (the last axis varies fastest), each point an
    /// experiment named `<sweep>_<key>-<value>_…` ([`point_name`]).
    pub fn expand(&self) -> Result<Vec<Point>> {
        let short = short_keys(&self.axes.iter().map(|a| a.key.clone()).collect::<Vec<_>>());
        let total: usize = self.axes.iter().map(|a| a.values.len()).product();
        let mut points = Vec::with_capacity(total);
        let mut names = std::collections::BTreeSet::new();
        for index in 0..total {
            // mixed-radix digits of `index`, the last axis least significant
            let mut rest = index;
            let mut digits = vec![0; self.axes.len()];
            for (d, a) in digits.iter_mut().zip(&self.axes).rev() {
                *d = rest % a.values.len();
                rest /= a.values.len();
            }
            let values: Vec<(String, Value)> = self
                .axes
                .iter()
                .zip(&digits)
                .map(|(a, &d)| (a.key.clone(), a.values[d].clone()))
                .collect();
            let labelled: Vec<(&str, &Value)> = short
                .iter()
                .map(String::as_str)
                .zip(values.iter().map(|(_, v)| v))
                .collect();
            let mut name = point_name(&self.name, &labelled);
            if name.len() > 100 || names.contains(&name) {
                name = format!("{}_{index:03}", self.name);
            }
            names.insert(name.clone());
            let experiment = self
                .experiment(&name, &values)
                .map_err(|e| anyhow!("{}: experiment {name}: {e:#}", self.file.display()))?;
            points.push(Point { values, experiment });
        }
        Ok(points)
    }
}

/// Remove `base` from a sweep-like file's top table and read it: an experiment file
/// relative to `path`, or an inline table. The base's TOML and the file that anchors
/// its relative scene `dir`.
pub(crate) fn take_base(top: &mut Table, path: &Path) -> Result<(Table, PathBuf)> {
    let at = |e: String| anyhow!("{}: {e}", path.display());
    match top.remove("base") {
        Some(Value::String(file)) => {
            let dir = path.parent().unwrap_or(Path::new(""));
            let file = dir.join(file);
            let text = std::fs::read_to_string(&file).map_err(|e| {
                at(format!(
                    "base experiment {}: cannot read: {e}",
                    file.display()
                ))
            })?;
            let t: Table = text.parse().map_err(|e: toml::de::Error| {
                anyhow!("{}: {}", file.display(), e.message().trim())
            })?;
            Ok((t, file))
        }
        Some(Value::Table(t)) => Ok((t, path.to_path_buf())),
        Some(_) => Err(at("`base` must be a file name or a [base] table".into())),
        None => Err(at(
            "needs `base = \"experiment.toml\"` or a [base] table".into()
        )),
    }
}

/// Whether `path` holds a sweep (a TOML file with `base` or `[axes]`) rather than an
/// experiment; false when it cannot be read or parsed (the experiment reader then says
/// what is wrong).
pub fn is_sweep_file(path: &Path) -> bool {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| t.parse::<Table>().ok())
        .is_some_and(|t| t.contains_key("base") || t.contains_key("axes"))
}

/// Set `key` (dotted) in `t`, creating tables on the way.
fn set_dotted(t: &mut Table, key: &str, v: Value) -> Result<()> {
    let parts: Vec<&str> = key.split('.').collect();
    let mut cur = t;
    for p in &parts[..parts.len() - 1] {
        let next = cur
            .entry(p.to_string())
            .or_insert_with(|| Value::Table(Table::new()));
        cur = match next {
            Value::Table(sub) => sub,
            _ => bail!("`{p}` in \"{key}\" is a value, not a table"),
        };
    }
    cur.insert(parts[parts.len() - 1].to_string(), v);
    Ok(())
}

/// For each key the fewest trailing segments that no other key ends with
/// (`deform.iterations`, `gaussians.field.width`, `scene.settings.width` →
/// `iterations`, `field.width`, `settings.width`).
pub(crate) fn short_keys(keys: &[String]) -> Vec<String> {
    let suffix = |k: &str, n: usize| {
        let parts: Vec<&str> = k.split('.').collect();
        parts[parts.len().saturating_sub(n)..].join(".")
    };
    keys.iter()
        .enumerate()
        .map(|(i, k)| {
            let len = k.split('.').count();
            (1..=len)
                .map(|n| suffix(k, n))
                .find(|s| {
                    keys.iter().enumerate().all(|(j, other)| {
                        j == i || !(other == s || other.ends_with(&format!(".{s}")))
                    })
                })
                .unwrap_or_else(|| k.clone())
        })
        .collect()
}

/// `<sweep>_<key>-<value>_…`; characters a run name cannot hold become `-`.
pub(crate) fn point_name(sweep: &str, values: &[(&str, &Value)]) -> String {
    let clean = |s: &str| -> String {
        s.chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || matches!(c, '.' | '-') {
                    c
                } else {
                    '-'
                }
            })
            .collect()
    };
    let mut name = sweep.to_string();
    for (k, v) in values {
        name += &format!("_{}-{}", clean(k), clean(&value_text(v)));
    }
    // runs of `-` (from cleaned characters) collapse to one
    let mut out = String::with_capacity(name.len());
    for c in name.chars() {
        if !(c == '-' && out.ends_with('-')) {
            out.push(c);
        }
    }
    out
}

/// A value as it appears in a name: strings bare, tables as `key-value-…`, lists as
/// `item-…`.
fn value_text(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        Value::Table(t) => t
            .iter()
            .map(|(k, v)| format!("{k}-{}", value_text(v)))
            .collect::<Vec<_>>()
            .join("-"),
        Value::Array(a) => a.iter().map(value_text).collect::<Vec<_>>().join("-"),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BASE: &str = "name = \"b\"\n[scene]\nsynth = \"rigid\"\n[scene.settings]\nwidth = 32\n\
                        [deform]\niterations = 10\n";

    fn sweep(body: &str) -> Result<Sweep> {
        Sweep::parse(
            &format!(
                "name = \"s\"\n[base]\n{}\n{body}",
                BASE.replace("[", "[base.")
            ),
            Path::new("/sw/s.toml"),
        )
    }

    #[test]
    fn the_product_is_named_from_the_axis_values() {
        let s = sweep(
            "[axes]\n\"deform.iterations\" = [20, 50]\n\"gaussians.field.width\" = [32, 64]\n\
             \"scene.settings.width\" = [16]\n",
        )
        .unwrap();
        let pts = s.expand().unwrap();
        // keys in sorted order: deform.iterations, gaussians.field.width, scene.settings.width
        let names: Vec<&str> = pts.iter().map(|p| p.experiment.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "s_iterations-20_field.width-32_settings.width-16",
                "s_iterations-20_field.width-64_settings.width-16",
                "s_iterations-50_field.width-32_settings.width-16",
                "s_iterations-50_field.width-64_settings.width-16",
            ]
        );
        let p = &pts[2].experiment;
        assert_eq!(p.settings("deform")["iterations"].as_integer(), Some(50));
        assert_eq!(
            p.settings("gaussians")["field"]["width"].as_integer(),
            Some(32)
        );
        let runner::experiment::SceneSource::Synth(cfg) = &p.scene else {
            panic!("synthetic scene expected")
        };
        assert_eq!(cfg.width, 16, "the axis overrides the base's 32");
        // the base's other settings stay
        assert_eq!(pts[0].experiment.settings("deform").len(), 1);
    }

    #[test]
    fn the_preset_is_an_axis_too_and_keeps_the_base_overrides() {
        let s = sweep("[axes]\n\"scene.synth\" = [\"rigid\", \"nonrigid\"]\n").unwrap();
        let pts = s.expand().unwrap();
        let presets: Vec<(String, u32)> = pts
            .iter()
            .map(|p| match &p.experiment.scene {
                runner::experiment::SceneSource::Synth(c) => (c.preset.clone(), c.width),
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(presets, [("rigid".into(), 32), ("nonrigid".into(), 32)]);
        assert_eq!(pts[1].experiment.name, "s_synth-nonrigid");
    }

    #[test]
    fn no_axes_is_one_experiment_and_strings_name_cleanly() {
        let s = sweep("").unwrap();
        let pts = s.expand().unwrap();
        assert_eq!(pts.len(), 1);
        assert_eq!(pts[0].experiment.name, "s");
        let s = sweep("[axes]\n\"evflow.mode\" = [\"none\", \"lora\"]\n").unwrap();
        let names: Vec<String> = s
            .expand()
            .unwrap()
            .into_iter()
            .map(|p| p.experiment.name)
            .collect();
        assert_eq!(names, ["s_mode-none", "s_mode-lora"]);
        assert_eq!(
            point_name(
                "x",
                &[("a", &Value::Float(0.5)), ("b c", &Value::Boolean(true))]
            ),
            "x_a-0.5_b-c-true"
        );
        let table: Value = "gamma1 = 0.0\ngamma2_max = 1.5"
            .parse::<Table>()
            .unwrap()
            .into();
        assert_eq!(
            point_name(
                "x",
                &[
                    ("schedule", &table),
                    ("list", &Value::Array(vec![1.into(), 2.into()]))
                ]
            ),
            "x_schedule-gamma1-0.0-gamma2-max-1.5_list-1-2"
        );
    }

    #[test]
    fn bad_axes_name_the_file_and_the_key() {
        for (body, want) in [
            (
                "[axes]\n\"deformx.iterations\" = [1]\n",
                "deformx.iterations",
            ),
            ("[axes]\n\"deform\" = [1]\n", "\"deform\""),
            ("[axes]\n\"name\" = [\"x\"]\n", "\"name\""),
            ("[axes]\n\"scene.settings.widht\" = [1]\n", "widht"),
            ("[axes]\n\"deform.iterations\" = []\n", "deform.iterations"),
            ("[axes]\n\"deform.iterations\" = 5\n", "deform.iterations"),
            ("[axes]\n\"deform.iterations\" = [5, 5]\n", "twice"),
            ("[axis]\n", "axis"),
        ] {
            let msg = format!("{:#}", sweep(body).unwrap_err());
            assert!(msg.contains("/sw/s.toml"), "{msg}");
            assert!(msg.contains(want), "{want}: {msg}");
        }
        let msg = Sweep::parse("name = \"s\"\n", Path::new("/sw/s.toml"))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("base"), "{msg}");
        let msg = Sweep::parse("base = \"nope.toml\"\n", Path::new("/sw/s.toml"))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("/sw/nope.toml"), "{msg}");
        assert!(Sweep::parse("\u{0}garbage", Path::new("/sw/s.toml")).is_err());
    }

    #[test]
    fn a_base_file_is_read_relative_to_the_sweep_and_anchors_its_scene_dir() {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(
            d.path().join("exp.toml"),
            "name = \"e\"\n[scene]\ndir = \"scenes/x\"\n",
        )
        .unwrap();
        let sweep_file = d.path().join("s.toml");
        let text = "base = \"exp.toml\"\n[axes]\n\"assoc.k\" = [2, 4]\n";
        std::fs::write(&sweep_file, text).unwrap();
        let s = Sweep::load(&sweep_file).unwrap();
        assert_eq!(s.name, "s", "the file stem when no name is given");
        let pts = s.expand().unwrap();
        assert_eq!(pts.len(), 2);
        assert_eq!(
            pts[1].experiment.scene,
            runner::experiment::SceneSource::Dir(d.path().join("scenes/x"))
        );
        assert_eq!(
            short_keys(&["a.k".into(), "b.k".into(), "c.j".into()]),
            ["a.k", "b.k", "j"]
        );
    }
}
