//! How a [`SynthConfig`] is read and written (TOML, JSON, any serde format).
//!
//! Written: the fields of [`SynthConfig`] as keys, the event simulator's settings as the
//! nested table `events` ([`crate::sim::SimConfig`]'s keys).
//!
//! Read: the same, every key optional. A missing key takes the value of
//! `SynthConfig::default()` (the `rigid` preset), inside `events` too. The flat keys of
//! the files written before the simulator's settings moved into `events` are still read
//! ([`FLAT_EVENT_KEYS`]: `contrast_threshold` sets `events.threshold_pos` and
//! `events.threshold_neg`, the others keep their name inside `events`); given with the
//! same key under `events`, the flat one wins (it is applied last, as an override).
//! Unknown keys are errors that name the key.

use crate::config::SynthConfig;
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use toml::{Table, Value};

/// The flat keys of older files and the keys of the `events` table each one sets.
pub const FLAT_EVENT_KEYS: [(&str, &[&str]); 6] = [
    ("contrast_threshold", &["threshold_pos", "threshold_neg"]),
    ("threshold_sigma", &["threshold_sigma"]),
    ("refractory_s", &["refractory_s"]),
    ("shot_noise_hz", &["shot_noise_hz"]),
    ("hot_pixel_fraction", &["hot_pixel_fraction"]),
    ("hot_pixel_hz", &["hot_pixel_hz"]),
];

impl Serialize for SynthConfig {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        // The derived (`remote = "Self"`) serialiser of the struct.
        SynthConfig::serialize(self, serializer)
    }
}

impl<'de> Deserialize<'de> for SynthConfig {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let mut value = Value::deserialize(deserializer)?;
        if let Value::Table(table) = &mut value {
            complete_events(table).map_err(D::Error::custom)?;
        }
        // The derived (`remote = "Self"`) deserialiser of the struct.
        SynthConfig::deserialize(value).map_err(|e| D::Error::custom(e.message().trim()))
    }
}

/// Make `table["events"]` complete: the default config's simulator settings, overlaid
/// with the given `events` table, then with the flat keys (removed from `table`).
/// A non-table `events` is left for the struct's deserialiser to reject.
fn complete_events(table: &mut Table) -> Result<(), String> {
    let flat: Vec<(&[&str], Value)> = FLAT_EVENT_KEYS
        .iter()
        .filter_map(|&(key, targets)| table.remove(key).map(|v| (targets, v)))
        .collect();
    let given = match table.remove("events") {
        None => Table::new(),
        Some(Value::Table(t)) => t,
        Some(other) => {
            table.insert("events".into(), other);
            return Ok(());
        }
    };
    let mut events = match Value::try_from(SynthConfig::default().events) {
        Ok(Value::Table(t)) => t,
        Ok(_) => return Err("the default simulator settings are not a table".into()),
        Err(e) => return Err(e.to_string()),
    };
    events.extend(given);
    for (targets, v) in flat {
        for key in targets {
            events.insert((*key).to_string(), v.clone());
        }
    }
    table.insert("events".into(), Value::Table(events));
    Ok(())
}
