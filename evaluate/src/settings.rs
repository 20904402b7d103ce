//! The settings of the `evaluate` stage (`[eval]` of nothing: `degs eval` writes them).

use crate::lpips_use::LpipsUse;
use serde::{Deserialize, Serialize};

/// What the evaluation computes beyond PSNR and SSIM.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EvalSettings {
    /// LPIPS (VGG): `fetch` the weights at first use, use only `cached` ones, or `off`.
    pub lpips: LpipsUse,
}

impl stagekit::Settings for EvalSettings {
    fn validate(&self) -> Result<(), String> {
        Ok(())
    }
}
