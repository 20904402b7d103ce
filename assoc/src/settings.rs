//! The settings of the `assoc` stage (`assoc settings --defaults`).

use serde::{Deserialize, Serialize};

/// Settings of the association (all have defaults that work on the synthetic scenes).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AssocSettings {
    /// Half-width of the event window around the frame time t0, in seconds.
    pub delta_t: f64,
    /// Number of events each Gaussian binds to.
    pub k: usize,
    /// Search radius in pixels; converted per Gaussian to world units through its depth
    /// (`r = radius_px · depth / fx`) so it means the same footprint at every distance.
    pub radius_px: f64,
    /// Events on pixels whose rendered alpha is below this are dropped.
    pub min_alpha: f32,
}

impl Default for AssocSettings {
    fn default() -> Self {
        Self {
            delta_t: 0.01,
            k: 3,
            radius_px: 2.0,
            min_alpha: 0.5,
        }
    }
}

impl stagekit::Settings for AssocSettings {
    /// Checks every setting is in range; the message names the setting.
    fn validate(&self) -> Result<(), String> {
        if !(self.delta_t.is_finite() && self.delta_t > 0.0) {
            return Err(format!(
                "delta_t = {} must be a positive number of seconds",
                self.delta_t
            ));
        }
        if self.k == 0 || self.k > 64 {
            return Err(format!("k = {} must be in 1..=64", self.k));
        }
        if !(self.radius_px.is_finite() && self.radius_px > 0.0) {
            return Err(format!("radius_px = {} must be positive", self.radius_px));
        }
        if !(0.0..=1.0).contains(&self.min_alpha) {
            return Err(format!("min_alpha = {} must be in [0, 1]", self.min_alpha));
        }
        Ok(())
    }
}
