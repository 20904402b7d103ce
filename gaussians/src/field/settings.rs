//! Hyper-parameters of the deformation field (`field.json`).

use serde::{Deserialize, Serialize};

/// Number of geometric head outputs: δx (3), δq (4), δs (3); a colour field adds δc
/// (3) after them ([`FieldSettings::head_out`]).
pub const HEAD_OUT: usize = 10;

/// Field hyper-parameters (saved as `field.json`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FieldSettings {
    /// Hidden layers D.
    pub depth: usize,
    /// Hidden width W.
    pub width: usize,
    /// Positional-encoding frequencies for x (Deform-GS: 10 → 63 dims).
    pub pos_freqs: usize,
    /// Positional-encoding frequencies for t (Deform-GS synthetic: 6 → 13 dims).
    pub time_freqs: usize,
    /// Initialisation seed.
    pub seed: u64,
    /// Start the output head at zero (weights and bias), so the field is the identity
    /// when it is switched on and the static phase's model is not disturbed. Off: the
    /// PyTorch/Deform-GS default init, whose random head moves every Gaussian by
    /// ~0.1–0.3 units and perturbs its scale and rotation at the switch.
    pub zero_head_init: bool,
    /// A colour that changes with time: three more outputs `δc` added to each
    /// Gaussian's SH DC coefficients (the view-independent colour), so that shading on
    /// a turning object and what the events record of it can be drawn without motion.
    pub color: bool,
}

impl FieldSettings {
    /// Outputs of the head: δx (3), δq (4), δs (3), and δc (3) with [`Self::color`].
    pub fn head_out(&self) -> usize {
        HEAD_OUT + if self.color { 3 } else { 0 }
    }
}

impl Default for FieldSettings {
    fn default() -> Self {
        FieldSettings {
            depth: 4,
            width: 64,
            pos_freqs: 10,
            time_freqs: 6,
            seed: 0,
            zero_head_init: true,
            color: false,
        }
    }
}
