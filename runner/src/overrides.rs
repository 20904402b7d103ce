//! Overrides of nested TOML tables: merging one table into another, and
//! `--set key.path=value` assignments.

use toml::{Table, Value};

/// Merge `over` into `base`: nested tables merge, other values replace.
pub fn merge(base: &mut Table, over: &Table) {
    for (k, v) in over {
        match (base.get_mut(k), v) {
            (Some(Value::Table(b)), Value::Table(o)) => merge(b, o),
            _ => {
                base.insert(k.clone(), v.clone());
            }
        }
    }
}

/// Parse `--set key.path=value` into a nested table. The value is read as TOML
/// (`3`, `0.5`, `true`, `[1, 2]`, `"text"`), else taken as a bare string.
pub fn parse_set(assignments: &[String]) -> std::result::Result<Table, String> {
    let mut out = Table::new();
    for a in assignments {
        let (key, raw) = a
            .split_once('=')
            .ok_or_else(|| format!("--set {a:?}: expected key=value"))?;
        let key = key.trim();
        if key.is_empty() || key.split('.').any(str::is_empty) {
            return Err(format!("--set {a:?}: empty key"));
        }
        let value = format!("v = {}", raw.trim())
            .parse::<Table>()
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| Value::String(raw.trim().to_string()));
        let parts: Vec<&str> = key.split('.').collect();
        let mut nested = value;
        for p in parts[1..].iter().rev() {
            let mut t = Table::new();
            t.insert(p.to_string(), nested);
            nested = Value::Table(t);
        }
        let mut one = Table::new();
        one.insert(parts[0].to_string(), nested);
        merge(&mut out, &one);
    }
    Ok(out)
}
