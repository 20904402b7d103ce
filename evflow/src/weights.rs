//! Loading flow-network weights, with or without the JSON sidecar.
//!
//! Weights written by `evflow pretrain` / [`FlowNet::save`] carry a sidecar
//! (`FILE.safetensors.json`) with the [`NetConfig`]. External weights are often a bare
//! safetensors file; then the network settings come from the tensors themselves:
//!
//! - base width `C` and time bins `B` from `enc1.weight`, which is `[C, B, 3, 3]`
//!   (`--width C` checks it);
//! - `max_flow` (the scale of the tanh heads, px per window) cannot be read from the
//!   tensors: `--max-flow PX`, default [`DEFAULT_MAX_FLOW`].
//!
//! Every tensor is then checked by name and shape against [`crate::net::layout`]; see
//! [`TENSOR_NAMES_HELP`] for the names.

use crate::net::{FlowNet, NetConfig, TensorMap, read_safetensors};
use burn::tensor::{DType, Device};
use scene::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// `max_flow` assumed for bare weights when `--max-flow` is not given (the shipped
/// weights' value).
pub const DEFAULT_MAX_FLOW: f64 = 32.0;

/// Documentation of the tensor names and shapes (printed by `evflow --help`).
pub const TENSOR_NAMES_HELP: &str = "\
Flow-network weights (--weights FILE): safetensors, F32 or F64, one tensor per name below
(C = base width, B = voxel bins, 5 by default; kernels [out, in, k, k], biases [out]):
  enc1.weight [C,B,3,3]      enc2.weight [2C,C,3,3]     enc3.weight [4C,2C,3,3]
  enc4.weight [8C,4C,3,3]    res1a, res1b, res2a, res2b .weight [8C,8C,3,3]
  dec0.weight [4C,16C,3,3]   dec1.weight [2C,8C+2,3,3]  dec2.weight [C,4C+2,3,3]
  dec3.weight [C/2,2C+2,3,3] flow0..flow3 .weight [2,OUT,1,1] (OUT of dec0..dec3)
  and NAME.bias [out] for every NAME above (encoders stride 2, the rest stride 1).
A JSON sidecar FILE.json ({\"format\":\"degs-evflownet-v1\",\"net\":{\"base\":C,
\"bins\":B,\"max_flow\":PX}}) gives the settings; without one, C and B are read from
enc1.weight (--width C checks it) and max_flow is --max-flow (default 32 px/window).
LoRA adapters (--adapter): NAME.lora_a [r, in*k*k], NAME.lora_b [out, r] + sidecar.";

/// Settings for weights without a sidecar (both optional).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BareWeights {
    /// Expected base width C (checked against the tensors).
    pub base: Option<usize>,
    /// Scale of the tanh heads, px per window.
    pub max_flow: Option<f64>,
}

/// Network settings read from the tensors of a bare weights file.
pub fn infer_config(tensors: &TensorMap, path: &Path, bare: &BareWeights) -> Result<NetConfig> {
    let (shape, _) = tensors.get("enc1.weight").ok_or_else(|| {
        Error::invalid(
            path,
            "no tensor enc1.weight: not EV-FlowNet weights (see `evflow --help` for the names)",
        )
    })?;
    let (base, bins) = match shape.as_slice() {
        [c, b, 3, 3] if *c > 0 && *b > 0 => (*c, *b),
        s => {
            return Err(Error::invalid(
                path,
                format!("tensor enc1.weight has shape {s:?}, expected [C, B, 3, 3]"),
            ));
        }
    };
    if let Some(want) = bare.base
        && want != base
    {
        return Err(Error::invalid(
            path,
            format!("--width {want} given, but enc1.weight has C = {base}"),
        ));
    }
    let max_flow = bare.max_flow.unwrap_or(DEFAULT_MAX_FLOW);
    if !(max_flow.is_finite() && max_flow > 0.0) {
        return Err(Error::Other(format!(
            "--max-flow {max_flow} must be finite and > 0"
        )));
    }
    Ok(NetConfig {
        base,
        bins,
        max_flow,
    })
}

/// What [`load`] found.
#[derive(Clone, Debug)]
pub struct Loaded {
    pub net: FlowNet,
    /// `true` when there was no sidecar and the settings were inferred.
    pub inferred: bool,
}

impl Loaded {
    /// A one-line note for the user when the settings were inferred.
    pub fn note(&self, path: &Path) -> Option<String> {
        let c = &self.net.config;
        self.inferred.then(|| {
            format!(
                "{}: no JSON sidecar; network settings from the tensors: C = {}, B = {}, \
                 max_flow = {} px per window (--max-flow)",
                path.display(),
                c.base,
                c.bins,
                c.max_flow
            )
        })
    }
}

/// Load weights: with the sidecar's settings when there is one (`bare.base`, if given,
/// must agree), else with settings inferred from the tensors.
pub fn load(path: &Path, bare: &BareWeights, device: &Device, dtype: DType) -> Result<Loaded> {
    let side = crate::lora::sidecar(path);
    if side.is_file() {
        let net = FlowNet::load(path, None, device, dtype)?;
        if let Some(want) = bare.base
            && want != net.config.base
        {
            return Err(Error::invalid(
                &side,
                format!(
                    "--width {want} given, but the sidecar says C = {}",
                    net.config.base
                ),
            ));
        }
        if let Some(m) = bare.max_flow
            && m != net.config.max_flow
        {
            return Err(Error::invalid(
                &side,
                format!(
                    "--max-flow {m} given, but the sidecar says max_flow = {} \
                     (--max-flow is for weights without a sidecar)",
                    net.config.max_flow
                ),
            ));
        }
        return Ok(Loaded {
            net,
            inferred: false,
        });
    }
    if !path.is_file() {
        return Err(Error::invalid(
            path,
            "flow-network weights not found; pass --weights FILE",
        ));
    }
    let tensors = read_safetensors(path)?;
    let config = infer_config(&tensors, path, bare)?;
    let net = FlowNet::from_tensors(path, config, &tensors, device, dtype)?;
    Ok(Loaded {
        net,
        inferred: true,
    })
}
