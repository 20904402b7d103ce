//! Canonical form of stage settings: keys sorted at every level, numbers normalised,
//! so that two experiment files that mean the same settings hash to the same key.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use toml::{Table, Value};

/// A copy of `table` with keys inserted in sorted order at every level and floats
/// normalised (`-0.0` → `0.0`). Integers stay integers: a stage may parse them as such.
pub fn canonical_table(table: &Table) -> Table {
    let sorted: BTreeMap<&String, &Value> = table.iter().collect();
    let mut out = Table::new();
    for (k, v) in sorted {
        out.insert(k.clone(), canonical_value(v));
    }
    out
}

fn canonical_value(v: &Value) -> Value {
    match v {
        Value::Float(f) if *f == 0.0 => Value::Float(0.0),
        Value::Table(t) => Value::Table(canonical_table(t)),
        Value::Array(a) => Value::Array(a.iter().map(canonical_value).collect()),
        other => other.clone(),
    }
}

/// One-line canonical text of a table (JSON-like, sorted keys, shortest round-trip
/// floats): the bytes that enter a cache key.
pub fn canonical_string(table: &Table) -> String {
    let mut s = String::new();
    write_table(&mut s, table);
    s
}

fn write_table(s: &mut String, t: &Table) {
    let sorted: BTreeMap<&String, &Value> = t.iter().collect();
    s.push('{');
    for (i, (k, v)) in sorted.into_iter().enumerate() {
        if i > 0 {
            s.push(',');
        }
        write_str(s, k);
        s.push(':');
        write_value(s, v);
    }
    s.push('}');
}

fn write_value(s: &mut String, v: &Value) {
    match v {
        Value::String(x) => write_str(s, x),
        Value::Integer(i) => {
            let _ = write!(s, "{i}");
        }
        Value::Float(f) => {
            let f = if *f == 0.0 { 0.0 } else { *f };
            let _ = write!(s, "{f:?}");
        }
        Value::Boolean(b) => {
            let _ = write!(s, "{b}");
        }
        Value::Datetime(d) => write_str(s, &d.to_string()),
        Value::Array(a) => {
            s.push('[');
            for (i, x) in a.iter().enumerate() {
                if i > 0 {
                    s.push(',');
                }
                write_value(s, x);
            }
            s.push(']');
        }
        Value::Table(t) => write_table(s, t),
    }
}

fn write_str(s: &mut String, x: &str) {
    s.push_str(&serde_json::to_string(x).unwrap_or_default());
}

/// The table as TOML text (sorted keys), for the `settings.toml` handed to a stage.
pub fn to_toml(table: &Table) -> String {
    toml::to_string(&canonical_table(table)).unwrap_or_default()
}

/// Flatten a table to `dotted.key → canonical value text`, for "which setting changed".
pub fn flatten(table: &Table) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    flatten_into(&mut out, "", table);
    out
}

fn flatten_into(out: &mut BTreeMap<String, String>, prefix: &str, t: &Table) {
    for (k, v) in t {
        let key = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            Value::Table(sub) => flatten_into(out, &key, sub),
            other => {
                let mut s = String::new();
                write_value(&mut s, other);
                out.insert(key, s);
            }
        }
    }
}

/// A TOML table as JSON (for run records).
pub(crate) fn to_json(table: &Table) -> serde_json::Value {
    serde_json::to_value(canonical_table(table)).unwrap_or(serde_json::Value::Null)
}

/// Back from the JSON stored in a run record.
pub(crate) fn from_json(v: &serde_json::Value) -> Table {
    serde_json::from_value::<Table>(v.clone()).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Table {
        s.parse::<Table>().unwrap()
    }

    #[test]
    fn order_and_spelling_do_not_change_the_canonical_text() {
        let a = parse("b = 1\na = 0.001\n[sub]\nz = -0.0\ny = [1, 2]\n");
        let b = parse("a = 1e-3\n[sub]\ny = [1, 2]\nz = 0.0\n[b_dummy]\n");
        let mut b2 = b.clone();
        b2.remove("b_dummy");
        b2.insert("b".into(), Value::Integer(1));
        assert_eq!(canonical_string(&a), canonical_string(&b2));
        assert_eq!(
            canonical_string(&a),
            r#"{"a":0.001,"b":1,"sub":{"y":[1,2],"z":0.0}}"#
        );
    }

    #[test]
    fn integer_and_float_stay_distinct() {
        assert_ne!(
            canonical_string(&parse("n = 100")),
            canonical_string(&parse("n = 100.0"))
        );
    }

    #[test]
    fn flatten_names_nested_keys() {
        let f = flatten(&parse("a = 1\n[opt]\nlr = 0.5\n"));
        assert_eq!(f.get("opt.lr").map(String::as_str), Some("0.5"));
        assert_eq!(f.get("a").map(String::as_str), Some("1"));
    }

    #[test]
    fn toml_text_is_sorted_and_round_trips() {
        let t = parse("z = 1\na = \"x\"\n");
        let text = to_toml(&t);
        assert!(text.find("a =").unwrap() < text.find("z =").unwrap());
        assert_eq!(canonical_string(&parse(&text)), canonical_string(&t));
    }
}
