//! The command line of a stage node, and quoting it for a shell (`degs plan`, logs).

use crate::cache::Cache;
use crate::graph::{Node, output_dir};
use std::path::{Path, PathBuf};

/// Path of the settings file a node is run with.
pub(crate) fn settings_path(cache: &Cache, exp: &str, stage: &str) -> PathBuf {
    cache.run_dir(exp).join(format!("{stage}.settings.toml"))
}

/// The command line of node `i`, writing to `out` with settings from `config`.
pub fn command(nodes: &[Node], i: usize, cache: &Cache, out: &Path, config: &Path) -> Vec<String> {
    let n = &nodes[i];
    let bin = n
        .binary
        .as_ref()
        .map(|b| b.display().to_string())
        .unwrap_or_else(|| n.stage.clone());
    let mut args = vec![bin];
    if let Some(verb) = n.verb {
        args.push(verb.into());
    }
    for input in &n.inputs {
        args.push(input.flag.into());
        let dir = output_dir(nodes, input.node, cache).unwrap_or_default();
        args.push(dir.display().to_string());
    }
    args.push("--out".into());
    args.push(out.display().to_string());
    args.push("--config".into());
    args.push(config.display().to_string());
    args
}

/// Quote a word for a POSIX shell.
pub(crate) fn shell_quote(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:+,@%".contains(c))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quoting() {
        assert_eq!(shell_quote("a/b.toml"), "a/b.toml");
        assert_eq!(shell_quote("it's here"), "'it'\\''s here'");
        assert_eq!(shell_quote(""), "''");
    }
}
