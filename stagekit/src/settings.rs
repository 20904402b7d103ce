//! Stage settings files: read a TOML file (or take the defaults), apply the command
//! line's overrides, validate, and write the resolved settings beside the outputs. Every
//! stage binary does this the same way (docs/DESIGN.md §4).

use scene::atomic::write_bytes_atomic;
use scene::error::{Error, Result};
use serde::Serialize;
use serde::de::DeserializeOwned;
use std::path::Path;

/// A stage's settings: TOML with defaults for every key, unknown keys rejected
/// (`#[serde(deny_unknown_fields, default)]`), and a check of the values.
pub trait Settings: Serialize + DeserializeOwned + Default {
    /// Why the values cannot be used, if they cannot.
    fn validate(&self) -> std::result::Result<(), String>;
}

/// Parse settings from TOML text; errors name `origin`, the line and the offending key.
pub fn parse<S: Settings>(text: &str, origin: &Path) -> Result<S> {
    toml::from_str(text).map_err(|e| Error::invalid(origin, toml_error(text, &e)))
}

/// A TOML error in `text` as one line: where (`line L, column C`, and the key there as
/// `table.key` when the line holds one) and what.
pub fn toml_error(text: &str, e: &toml::de::Error) -> String {
    let msg = e.message().trim().replace('\n', " ");
    let Some(span) = e.span() else {
        return msg;
    };
    let at = span.start.min(text.len());
    let line_start = text[..at].rfind('\n').map_or(0, |i| i + 1);
    let line_no = text[..at].matches('\n').count() + 1;
    let column = text[line_start..at].chars().count() + 1;
    match key_at(text, at) {
        Some(key) => format!("line {line_no}, column {column}, key `{key}`: {msg}"),
        None => format!("line {line_no}, column {column}: {msg}"),
    }
}

/// The dotted key (`table.key`) of the `key = value` line holding byte `at` of `text`,
/// with the `[table]` header above it.
pub(crate) fn key_at(text: &str, at: usize) -> Option<String> {
    let at = at.min(text.len());
    let start = text[..at].rfind('\n').map_or(0, |i| i + 1);
    let end = text[at..].find('\n').map_or(text.len(), |i| at + i);
    let line = &text[start..end];
    let key = line.split_once('=')?.0.trim().trim_matches('"');
    if key.is_empty() || key.starts_with('[') || key.starts_with('#') {
        return None;
    }
    let table = text[..start]
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| l.starts_with('['))
        .map(|l| l.trim_matches(|c| c == '[' || c == ']').trim().to_string());
    Some(match table {
        Some(t) if !t.is_empty() => format!("{t}.{key}"),
        _ => key.to_string(),
    })
}

/// Settings read from the file `path` (e.g. the resolved `settings.toml` an earlier
/// stage wrote beside its output), then [`Settings::validate`]; errors name the file.
pub fn read_file<S: Settings>(path: &Path) -> Result<S> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let s: S = parse(&text, path)?;
    s.validate().map_err(|e| Error::invalid(path, e))?;
    Ok(s)
}

/// Settings from a TOML table (a file's keys with `--set key=value` overrides merged
/// in), then [`Settings::validate`]; errors name `origin`.
pub fn from_table<S: Settings>(table: toml::Table, origin: &Path) -> Result<S> {
    let s: S = from_table_naming_key(table).map_err(|e| Error::invalid(origin, e))?;
    s.validate().map_err(|e| Error::invalid(origin, e))?;
    Ok(s)
}

/// `table` read as `T` through TOML text, so that an error names the key it is about
/// (`key \`densify.interval\`: invalid type …`).
pub(crate) fn from_table_naming_key<T: DeserializeOwned>(
    table: toml::Table,
) -> std::result::Result<T, String> {
    let text = toml::to_string(&table).map_err(|e| e.to_string())?;
    toml::from_str(&text).map_err(|e| {
        let msg = e.message().trim().replace('\n', " ");
        match e.span().and_then(|sp| key_at(&text, sp.start)) {
            Some(key) => format!("key `{key}`: {msg}"),
            None => msg,
        }
    })
}

/// The settings of a run: `config` (or the defaults), then `overrides` (the flags),
/// then [`Settings::validate`]. Errors name the file, or "command line" when there is none.
pub fn resolve<S: Settings>(config: Option<&Path>, overrides: impl FnOnce(&mut S)) -> Result<S> {
    let mut s = match config {
        Some(p) => parse(&std::fs::read_to_string(p).map_err(|e| Error::io(p, e))?, p)?,
        None => S::default(),
    };
    overrides(&mut s);
    let origin = config.unwrap_or(Path::new("command line"));
    s.validate().map_err(|e| Error::invalid(origin, e))?;
    Ok(s)
}

/// TOML text of `s`, keys in the order of the fields, with values that came from `f32`
/// fields written as the shortest decimal that reads back to the same `f32` (`0.0002`,
/// not `0.00019999999494757503`: the text writer sees the `f32`, unlike
/// `toml::Value::try_from`, which widens it; see [`tidy_floats`]).
pub fn to_toml<S: Serialize>(s: &S) -> Result<String> {
    toml::to_string(s).map_err(|e| Error::Other(format!("cannot write settings: {e}")))
}

/// Write the resolved settings as `dir/settings.toml` (atomically).
pub fn write_resolved<S: Serialize>(dir: &Path, s: &S) -> Result<()> {
    write_bytes_atomic(&dir.join("settings.toml"), to_toml(s)?.as_bytes())
}

/// Replace every float that is exactly an `f32` by the shortest decimal of that `f32`.
/// A float read from TOML into an `f32` field and back gives the same `f32`; an `f64`
/// field's value changes only if it was exactly an `f32` with a long expansion.
pub(crate) fn tidy_floats(value: &mut toml::Value) {
    match value {
        toml::Value::Float(x) => {
            let f = *x as f32;
            if f.is_finite() && f as f64 == *x {
                *x = f.to_string().parse().unwrap_or(*x);
            }
        }
        toml::Value::Array(items) => items.iter_mut().for_each(tidy_floats),
        toml::Value::Table(t) => t.iter_mut().for_each(|(_, v)| tidy_floats(v)),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    struct Demo {
        rate: f32,
        span: f64,
        steps: u32,
    }
    impl Default for Demo {
        fn default() -> Self {
            Demo {
                rate: 2e-4,
                span: 0.1,
                steps: 10,
            }
        }
    }
    impl Settings for Demo {
        fn validate(&self) -> std::result::Result<(), String> {
            if self.steps == 0 {
                return Err("steps must be at least 1".into());
            }
            Ok(())
        }
    }

    #[test]
    fn f32_values_print_short_and_read_back_exactly() {
        let text = to_toml(&Demo::default()).unwrap();
        assert_eq!(text, "rate = 0.0002\nspan = 0.1\nsteps = 10\n", "{text}");
        // Keys come in the order of the fields, not sorted.
        #[derive(Serialize)]
        struct Ordered {
            zeta: f32,
            alpha: u8,
        }
        let ordered = to_toml(&Ordered {
            zeta: 0.3,
            alpha: 1,
        })
        .unwrap();
        assert_eq!(ordered, "zeta = 0.3\nalpha = 1\n");
        let back: Demo = parse(&text, Path::new("x.toml")).unwrap();
        assert_eq!(back, Demo::default());
        assert_eq!(back.rate.to_bits(), 2e-4f32.to_bits());
    }

    #[test]
    fn resolve_applies_overrides_then_validates_and_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.toml");
        std::fs::write(&p, "steps = 3\n").unwrap();
        let s: Demo = resolve(Some(&p), |s: &mut Demo| s.rate = 1.0).unwrap();
        assert_eq!((s.steps, s.rate), (3, 1.0));
        let e = resolve::<Demo>(Some(&p), |s| s.steps = 0)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with(&p.display().to_string()) && e.contains("at least 1"),
            "{e}"
        );
        let e = resolve::<Demo>(None, |s| s.steps = 0)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("command line:"), "{e}");
        std::fs::write(&p, "stepz = 3\n").unwrap();
        let e = resolve::<Demo>(Some(&p), |_| {}).unwrap_err().to_string();
        assert!(e.contains("stepz") && e.contains("s.toml"), "{e}");
        let e = resolve::<Demo>(Some(&dir.path().join("missing.toml")), |_| {}).unwrap_err();
        assert!(e.to_string().contains("missing.toml"), "{e}");
    }

    #[test]
    fn from_table_checks_keys_and_values_and_names_the_origin() {
        let origin = Path::new("d.toml");
        let s: Demo = from_table("steps = 4".parse().unwrap(), origin).unwrap();
        assert_eq!((s.steps, s.rate), (4, 2e-4));
        let e = from_table::<Demo>("stepz = 4".parse().unwrap(), origin).unwrap_err();
        assert!(e.to_string().starts_with("d.toml: ") && e.to_string().contains("stepz"));
        let e = from_table::<Demo>("steps = 0".parse().unwrap(), origin).unwrap_err();
        assert_eq!(e.to_string(), "d.toml: steps must be at least 1");
    }

    #[test]
    fn read_file_validates_and_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("settings.toml");
        std::fs::write(&p, "steps = 5\nrate = 0.5\n").unwrap();
        let s: Demo = read_file(&p).unwrap();
        assert_eq!((s.steps, s.rate), (5, 0.5));
        std::fs::write(&p, "steps = 0\n").unwrap();
        let e = read_file::<Demo>(&p).unwrap_err().to_string();
        assert_eq!(e, format!("{}: steps must be at least 1", p.display()));
        std::fs::write(&p, "steps = \"x\"\n").unwrap();
        let e = read_file::<Demo>(&p).unwrap_err().to_string();
        assert!(e.starts_with(&p.display().to_string()), "{e}");
        let e = read_file::<Demo>(&dir.path().join("none.toml")).unwrap_err();
        assert!(e.to_string().contains("none.toml"), "{e}");
    }
}
