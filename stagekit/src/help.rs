//! Help text that shows the default of each setting a flag overrides, taken from the
//! settings type's `Default` so that it cannot drift from the code. (clap's own
//! `default_value_t` does not fit: a flag overrides the `--config` file only when it is
//! given, so the flags stay `Option<T>` without a clap default.)

use super::settings::{Settings, tidy_floats};
use clap::{Arg, Command, Parser};

/// Append ` [default: VALUE]` to the help of each flag in `flags`: pairs of a clap
/// argument id (the field name, `lr_start`) and the setting it overrides, a dotted path
/// into the TOML of `S::default()` (`field.width`). Strings show without quotes.
///
/// Panics when an id is not an argument of `cmd` or a key is not a setting of `S` with
/// a value (a programming error; any test that builds the command finds it).
pub fn show_defaults<S: Settings>(cmd: Command, flags: &[(&str, &str)]) -> Command {
    let mut defaults = toml::Value::try_from(S::default()).expect("settings serialise to TOML");
    tidy_floats(&mut defaults);
    let shown: Vec<(&str, String)> = flags
        .iter()
        .map(|&(id, key)| {
            let value = key
                .split('.')
                .try_fold(&defaults, |v, k| v.get(k))
                .unwrap_or_else(|| panic!("--{id}: `{key}` is not a setting with a default"));
            let text = match value {
                toml::Value::String(s) => s.clone(),
                v => v.to_string(),
            };
            (id, text)
        })
        .collect();
    let mut found = vec![false; shown.len()];
    let cmd = cmd.mut_args(|a| {
        let Some(k) = shown.iter().position(|(id, _)| a.get_id() == *id) else {
            return a;
        };
        found[k] = true;
        with_default(a, &shown[k].1)
    });
    if let Some(k) = found.iter().position(|f| !f) {
        panic!(
            "--{} is not an argument of `{}`",
            shown[k].0,
            cmd.get_name()
        );
    }
    cmd
}

/// `arg` with ` [default: VALUE]` after its help (and its long help, if it has one),
/// for a default that is not a setting (a constant the code falls back to).
pub fn with_default(arg: Arg, value: impl std::fmt::Display) -> Arg {
    let tail = format!(" [default: {value}]");
    let help = arg.get_help().map(ToString::to_string).unwrap_or_default();
    let long = arg.get_long_help().map(|h| format!("{h}{tail}"));
    let arg = arg.help(format!("{help}{tail}"));
    match long {
        Some(l) => arg.long_help(l),
        None => arg,
    }
}

/// Parse the command line into `P` after `patch` adjusted its clap command (e.g. with
/// [`show_defaults`]); bad arguments, `--help` and `--version` exit as `P::parse()` does.
pub fn parse_with<P: Parser>(patch: impl FnOnce(Command) -> Command) -> P {
    let mut cmd = patch(P::command());
    let mut matches = cmd.get_matches_mut();
    P::from_arg_matches_mut(&mut matches).unwrap_or_else(|e| e.format(&mut cmd).exit())
}

/// The help of `--flag` in a rendered `--help` text: its line and the wrapped lines after
/// it, joined by spaces (for tests that check what a user reads). Panics naming the flag
/// when the text lacks it.
pub fn flag_help(help: &str, flag: &str) -> String {
    let mut lines = help
        .lines()
        .skip_while(|l| !l.contains(&format!("{flag} <")));
    let first = lines
        .next()
        .unwrap_or_else(|| panic!("{flag} missing from\n{help}"));
    let rest = lines.take_while(|l| !l.trim_start().starts_with('-'));
    std::iter::once(first)
        .chain(rest)
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;
    use serde::{Deserialize, Serialize};

    #[derive(Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    struct Demo {
        rate: f32,
        mode: String,
        inner: Inner,
    }
    #[derive(Default, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    struct Inner {
        width: usize,
    }
    impl Default for Demo {
        fn default() -> Self {
            Demo {
                rate: 2e-4,
                mode: "lora".into(),
                inner: Inner { width: 64 },
            }
        }
    }
    impl Settings for Demo {
        fn validate(&self) -> Result<(), String> {
            Ok(())
        }
    }

    #[derive(Parser)]
    struct Cli {
        /// Learning rate.
        #[arg(long)]
        rate: Option<f32>,
        /// What to train.
        ///
        /// A second paragraph makes a long help.
        #[arg(long)]
        mode: Option<String>,
        /// Hidden width.
        #[arg(long)]
        width: Option<usize>,
        /// Not a setting.
        #[arg(long)]
        out: Option<String>,
    }

    const FLAGS: &[(&str, &str)] = &[("rate", "rate"), ("mode", "mode"), ("width", "inner.width")];

    #[test]
    fn help_shows_the_defaults_of_the_settings_type() {
        let mut cmd = show_defaults::<Demo>(Cli::command(), FLAGS);
        let help = cmd.render_help().to_string();
        // (clap drops the final full stop of a one-paragraph doc comment)
        assert!(help.contains("Learning rate [default: 0.0002]"), "{help}");
        assert!(help.contains("What to train [default: lora]"), "{help}");
        assert!(help.contains("Hidden width [default: 64]"), "{help}");
        assert!(help.contains("Not a setting\n"), "{help}");
        let long = cmd.render_long_help().to_string();
        assert!(
            long.contains("makes a long help. [default: lora]"),
            "{long}"
        );
        // The flags keep their places.
        let order: Vec<_> = cmd
            .get_arguments()
            .map(|a| a.get_id().to_string())
            .collect();
        assert_eq!(order[..4], ["rate", "mode", "width", "out"]);
    }

    #[test]
    #[should_panic(expected = "`inner.depth` is not a setting")]
    fn an_unknown_key_is_a_programming_error() {
        let _ = show_defaults::<Demo>(Cli::command(), &[("width", "inner.depth")]);
    }

    #[test]
    #[should_panic(expected = "--depth is not an argument")]
    fn an_unknown_flag_is_a_programming_error() {
        let _ = show_defaults::<Demo>(Cli::command(), &[("depth", "inner.width")]);
    }
}
