//! Stage settings as `degs` sees them: each stage binary is the one authority on its
//! settings, asked through its `settings` verb ([`stagekit::verb`]): `STAGE settings
//! --defaults` for every default, `STAGE settings --check -` for the check of an
//! experiment's table (and the files outside the graph it makes the stage read, which
//! enter the stage's key). `degs` links no stage library. Answers are remembered per
//! binary (path, size, modification time) for the life of the process, so a sweep asks
//! each binary once per distinct table. Also: a table written out as a `[stage]` TOML
//! section.

use crate::canon;
use anyhow::{Context as _, Result, anyhow, bail};
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Mutex, OnceLock};
use toml::{Table, Value};

/// A file outside the stage graph that a stage's settings make it read (its base
/// weights), by the name it enters the key under.
pub(crate) type InputFile = (String, PathBuf);

type Memo = HashMap<(PathBuf, String), std::result::Result<String, String>>;

fn memo() -> &'static Mutex<Memo> {
    static MEMO: OnceLock<Mutex<Memo>> = OnceLock::new();
    MEMO.get_or_init(|| Mutex::new(HashMap::new()))
}

/// `binary settings ARGS` with `stdin` on standard input: Ok(stdout) when it exits 0,
/// Err(its error line, without the `binary: error: ` prefix) when it exits non-zero; an
/// error when it cannot be started or answers with something that is not text.
fn ask(binary: &Path, args: &[&str], stdin: &str) -> Result<std::result::Result<String, String>> {
    let stamp = std::fs::metadata(binary)
        .ok()
        .and_then(|m| Some((m.len(), m.modified().ok()?)))
        .map(|(len, t)| format!("{len}:{t:?}"))
        .unwrap_or_default();
    let memo_key = (
        binary.to_path_buf(),
        format!("{stamp}\0{}\0{stdin}", args.join(" ")),
    );
    if let Some(hit) = memo().lock().unwrap().get(&memo_key) {
        return Ok(hit.clone());
    }
    let mut child = Command::new(binary)
        .arg("settings")
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("{}: cannot start", binary.display()))?;
    if let Some(mut input) = child.stdin.take() {
        // A binary that exits without reading closes the pipe: its exit status tells.
        let _ = input.write_all(stdin.as_bytes());
    }
    let out = child
        .wait_with_output()
        .with_context(|| format!("{}: cannot run `settings`", binary.display()))?;
    let name = binary
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    let answer = if out.status.success() {
        Ok(String::from_utf8(out.stdout)
            .map_err(|_| anyhow!("{}: `settings` printed non-UTF-8 text", binary.display()))?)
    } else {
        let err = String::from_utf8_lossy(&out.stderr);
        let line = err
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .unwrap_or("")
            .trim();
        let prefix = format!("{name}: error: ");
        Err(match line.strip_prefix(&prefix) {
            Some(rest) => rest.to_string(),
            None if line.is_empty() => format!("`{name} settings` failed ({})", out.status),
            None => line.to_string(),
        })
    };
    memo().lock().unwrap().insert(memo_key, answer.clone());
    Ok(answer)
}

/// Every default of the stage `binary` (`binary settings --defaults`).
pub fn defaults(binary: &Path) -> Result<Table> {
    match ask(binary, &["--defaults"], "")? {
        Ok(text) => text.parse().map_err(|e: toml::de::Error| {
            anyhow!(
                "{}: `settings --defaults` printed no TOML: {}",
                binary.display(),
                e.message().trim()
            )
        }),
        Err(e) => bail!(
            "{}: does not answer `settings --defaults` ({e}); is it a degs stage of \
             this version?",
            binary.display()
        ),
    }
}

/// Check `table` against the stage `binary`'s settings (`binary settings --check -`):
/// Ok(the files outside the graph it makes the stage read), or Err(why, naming the key)
/// for a table the stage refuses; an error when the binary cannot answer.
pub fn check(binary: &Path, table: &Table) -> Result<std::result::Result<Vec<InputFile>, String>> {
    let text = canon::to_toml(table);
    Ok(match ask(binary, &["--check", "-"], &text)? {
        Ok(out) => {
            let files: Table = out.parse().map_err(|e: toml::de::Error| {
                anyhow!(
                    "{}: `settings --check` printed no TOML: {}",
                    binary.display(),
                    e.message().trim()
                )
            })?;
            Ok(files
                .into_iter()
                .filter_map(|(k, v)| Some((k, PathBuf::from(v.as_str()?))))
                .collect())
        }
        Err(e) => Err(e),
    })
}

/// `[name]` with `table` under it (nested tables as `[name.sub]`).
pub(crate) fn toml_section(name: &str, table: &Table) -> String {
    let scalars: Table = table
        .iter()
        .filter(|(_, v)| !v.is_table())
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    let mut out = format!("[{name}]\n");
    out += &canon::to_toml(&scalars);
    let mut subs: Vec<(&String, &Value)> = table.iter().filter(|(_, v)| v.is_table()).collect();
    subs.sort_by(|a, b| a.0.cmp(b.0));
    for (k, v) in subs {
        if let Value::Table(t) = v {
            out += "\n";
            out += &toml_section(&format!("{name}.{k}"), t);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f32_fields_become_their_shortest_decimal() {
        // What a stage's `settings --defaults` prints for an f32 field of 0.0002.
        let t: Table = "rate = 0.0002\ncount = 0\n[inner]\non = false\n"
            .parse()
            .unwrap();
        assert_eq!(t["rate"].as_float(), Some(0.0002));
        assert_eq!(toml_section("x", &t).lines().nth(2), Some("rate = 0.0002"));
    }
}
