//! Stage settings as `degs` sees them: a settings type's defaults and the check of an
//! experiment's table against it, and a table written out as a `[stage]` TOML section.

use crate::canon;
use crate::overrides::merge;
use scene::cli::Settings;
use serde::Serialize;
use toml::{Table, Value};

/// The settings type of a stage whose library this build links.
#[derive(Clone, Copy)]
pub struct SettingsType {
    /// Every default, as the binary reads them from an empty `--config`.
    pub defaults: fn() -> Table,
    /// Check a table against the type: unknown keys and wrong types are errors naming
    /// the key.
    pub check: fn(&Table) -> Result<(), String>,
}

impl SettingsType {
    /// The settings type `T` (deserialised by the stage binary from its `--config` with
    /// [`scene::cli::settings::resolve`]).
    pub const fn of<T: Settings>() -> SettingsType {
        SettingsType {
            defaults: defaults_of::<T>,
            check: check_as::<T>,
        }
    }
}

fn defaults_of<T: Serialize + Default>() -> Table {
    to_table(&T::default()).unwrap_or_default()
}

/// The stage's own check: the table over the defaults, read as the binary reads its
/// `--config` (a wrong type names the key), then the type's [`Settings::validate`].
fn check_as<T: Settings>(settings: &Table) -> Result<(), String> {
    let mut full = defaults_of::<T>();
    merge(&mut full, settings);
    scene::cli::settings::from_table_naming_key::<T>(full)?.validate()
}

/// `settings` as a TOML table, through TOML text: the text writer prints an `f32`
/// field as the shortest decimal that reads back to the same `f32` (`0.0002`), which
/// then parses to the `f64` of that decimal. `toml::Value::try_from` would widen the
/// `f32` instead (`0.00019999999494757503`).
pub fn to_table<T: Serialize>(settings: &T) -> Option<Table> {
    toml::to_string(settings).ok()?.parse().ok()
}

/// `[name]` with `table` under it (nested tables as `[name.sub]`).
pub fn toml_section(name: &str, table: &Table) -> String {
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
    use serde::Deserialize;

    #[derive(Default, Serialize, Deserialize)]
    #[serde(default, deny_unknown_fields)]
    struct Example {
        rate: f32,
        count: u32,
        inner: Inner,
    }

    #[derive(Default, Serialize, Deserialize)]
    #[serde(default, deny_unknown_fields)]
    struct Inner {
        on: bool,
    }

    impl Settings for Example {
        fn validate(&self) -> Result<(), String> {
            Ok(())
        }
    }

    #[test]
    fn defaults_and_check_follow_the_type() {
        let ty = SettingsType::of::<Example>();
        let d = (ty.defaults)();
        assert_eq!(d.get("count"), Some(&Value::Integer(0)));
        assert!(d["inner"].is_table());
        (ty.check)(&"count = 3\n[inner]\non = true".parse().unwrap()).unwrap();
        let err = (ty.check)(&"cuont = 3".parse().unwrap()).unwrap_err();
        assert!(err.contains("cuont"), "{err}");
        assert!((ty.check)(&"count = \"three\"".parse().unwrap()).is_err());
    }

    #[test]
    fn f32_fields_become_their_shortest_decimal() {
        let t = to_table(&Example {
            rate: 0.0002,
            ..Example::default()
        })
        .unwrap();
        assert_eq!(t["rate"].as_float(), Some(0.0002));
        assert_eq!(toml_section("x", &t).lines().nth(2), Some("rate = 0.0002"));
    }
}
