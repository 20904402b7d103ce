//! `STAGE settings`: each stage binary is the one authority on its settings. The
//! runner (`degs`) links no stage library; it asks the binary:
//!
//! - `STAGE settings --defaults` prints every default as TOML (f32 values as their
//!   shortest decimal, [`super::settings::to_toml`]);
//! - `STAGE settings --check FILE` (`-`: standard input) reads a settings table, merges
//!   it over the defaults, reads it as the binary reads its `--config` and validates it;
//!   on success it prints, as TOML `name = "path"` lines, the files outside the stage
//!   graph that these settings make the stage read (evflow's base weights), whose
//!   content belongs in the stage's cache key; on failure it exits 1 with one line
//!   naming the key.

use super::settings::{Settings, from_table_naming_key, to_toml, toml_error};
use scene::error::{Error, Result};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The flags of `STAGE settings`.
#[derive(clap::Args, Debug, Clone)]
#[group(required = true, multiple = false)]
pub struct SettingsArgs {
    /// Print every setting's default as TOML.
    #[arg(long)]
    pub defaults: bool,
    /// Check a settings file (`-`: standard input) against the defaults and the
    /// stage's rules; print the files outside the graph these settings read.
    #[arg(long, value_name = "FILE")]
    pub check: Option<PathBuf>,
}

/// Files outside the stage graph that settings `S` make the stage read, by name.
pub(crate) type InputFiles<S> = fn(&S) -> Vec<(&'static str, PathBuf)>;

/// No files outside the graph.
pub fn no_files<S>(_: &S) -> Vec<(&'static str, PathBuf)> {
    Vec::new()
}

/// Merge `over` into `base`: nested tables merge, other values replace.
pub fn merge(base: &mut toml::Table, over: &toml::Table) {
    for (k, v) in over {
        match (base.get_mut(k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            _ => {
                base.insert(k.clone(), v.clone());
            }
        }
    }
}

/// The check of `table`: merged over the defaults of `S`, read as `S` (an error names
/// the key), then [`Settings::validate`].
pub(crate) fn check_table<S: Settings>(table: &toml::Table) -> std::result::Result<S, String> {
    let mut full: toml::Table = to_toml(&S::default())
        .map_err(|e| e.to_string())?
        .parse()
        .map_err(|e: toml::de::Error| e.message().to_string())?;
    merge(&mut full, table);
    let s: S = from_table_naming_key(full)?;
    s.validate()?;
    Ok(s)
}

/// Read the table of `--check FILE` (`-`: standard input); errors name the file.
fn read_table(file: &Path) -> Result<toml::Table> {
    let stdin = file == Path::new("-");
    let mut text = String::new();
    if stdin {
        std::io::stdin()
            .read_to_string(&mut text)
            .map_err(|e| Error::io(Path::new("standard input"), e))?;
    } else {
        text = std::fs::read_to_string(file).map_err(|e| Error::io(file, e))?;
    }
    text.parse().map_err(|e: toml::de::Error| {
        let origin = if stdin {
            Path::new("standard input")
        } else {
            file
        };
        Error::invalid(origin, toml_error(&text, &e))
    })
}

/// Run `STAGE settings` for settings `S`: print the defaults, or check a file and print
/// the files it makes the stage read.
pub fn run<S: Settings>(args: &SettingsArgs, files: InputFiles<S>) -> Result<ExitCode> {
    if args.defaults {
        print!("{}", to_toml(&S::default())?);
        return Ok(ExitCode::SUCCESS);
    }
    let Some(file) = &args.check else {
        return Err(Error::Other(
            "settings: give --defaults or --check FILE".into(),
        ));
    };
    let table = read_table(file)?;
    let s = check_table::<S>(&table).map_err(|e| {
        if file == Path::new("-") {
            Error::Other(e)
        } else {
            Error::invalid(file, e)
        }
    })?;
    let mut out = toml::Table::new();
    for (name, path) in files(&s) {
        out.insert(
            name.to_string(),
            toml::Value::String(path.display().to_string()),
        );
    }
    print!("{}", toml::to_string(&out).unwrap_or_default());
    Ok(ExitCode::SUCCESS)
}

/// For a binary without sub-commands: when its arguments are `settings …`, run that
/// (exiting as [`super::exit_on_error`] does) and return its exit code; None otherwise.
pub fn intercept<S: Settings>(binary: &'static str, files: InputFiles<S>) -> Option<ExitCode> {
    use clap::{Args, Command, FromArgMatches};
    let mut argv = std::env::args_os();
    let exe = argv.next()?;
    let rest: Vec<_> = argv.collect();
    if rest.first().map(|a| a != "settings").unwrap_or(true) {
        return None;
    }
    let cmd = SettingsArgs::augment_args(
        Command::new("settings")
            .bin_name(format!("{binary} settings"))
            .about("Print the defaults of the settings, or check a settings file"),
    );
    let matches = cmd.get_matches_from(std::iter::once(exe).chain(rest.into_iter().skip(1)));
    Some(super::exit_on_error(binary, || {
        let args = SettingsArgs::from_arg_matches(&matches).map_err(|e| e.to_string())?;
        run::<S>(&args, files).map_err(|e| e.to_string())
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::{Deserialize, Serialize};

    #[derive(Serialize, Deserialize)]
    #[serde(default, deny_unknown_fields)]
    struct Outer {
        rate: f32,
        inner: Inner,
    }
    impl Default for Outer {
        fn default() -> Self {
            Outer {
                rate: 2e-4,
                inner: Inner { on: true, n: 3 },
            }
        }
    }
    #[derive(Default, Serialize, Deserialize)]
    #[serde(default, deny_unknown_fields)]
    struct Inner {
        on: bool,
        n: u32,
    }
    impl Settings for Outer {
        fn validate(&self) -> std::result::Result<(), String> {
            if self.inner.n == 0 {
                return Err("inner.n must be at least 1".into());
            }
            Ok(())
        }
    }

    #[test]
    fn a_partial_nested_table_keeps_the_outer_defaults() {
        // Inner::default() has on = false, n = 0; the merge keeps Outer's on = true.
        let s: Outer = check_table(&"[inner]\nn = 5".parse().unwrap()).unwrap();
        assert!(s.inner.on);
        assert_eq!((s.inner.n, s.rate), (5, 2e-4));
    }

    #[test]
    fn errors_name_the_key_or_the_rule() {
        let e = check_table::<Outer>(&"[inner]\nnn = 5".parse().unwrap())
            .err()
            .unwrap();
        assert!(e.contains("nn"), "{e}");
        let e = check_table::<Outer>(&"rate = \"fast\"".parse().unwrap())
            .err()
            .unwrap();
        assert!(e.contains("`rate`"), "{e}");
        let e = check_table::<Outer>(&"[inner]\nn = 0".parse().unwrap())
            .err()
            .unwrap();
        assert_eq!(e, "inner.n must be at least 1");
    }
}
