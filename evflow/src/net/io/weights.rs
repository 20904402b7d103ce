//! Base weights of the flow network: saving and loading them, with or without the JSON
//! sidecar, and finding the shipped ones.
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
//! Every tensor is then checked by name and shape against [`layout`]; see
//! [`TENSOR_NAMES_HELP`] for the names.

use super::tensor_file::{TensorMap, read_safetensors, sidecar, take, write_safetensors};
use crate::net::flownet::{Conv, FlowNet, NetConfig, layout};
use crate::net::tensor::{tensor4, to_f32};
use burn::tensor::{DType, Device, Tensor, TensorData};
use scene::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Largest base width C and number of voxel bins B a weights file may declare.
const MAX_BASE: usize = 1 << 14;
const MAX_BINS: usize = 1024;

/// Sidecar of a weights file.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct WeightsMeta {
    pub format: String,
    pub net: NetConfig,
    /// Free-form provenance (command line that produced the weights).
    #[serde(default)]
    pub trained_by: String,
}

impl FlowNet {
    /// Save the base weights (`NAME.weight` `[out,in,k,k]`, `NAME.bias` `[out]`, names
    /// from [`layout`]) to safetensors plus a JSON sidecar with the [`NetConfig`].
    /// Adapters are not included (merge first, or use [`super::save_adapters`]).
    pub fn save(&self, path: &Path, trained_by: &str) -> Result<()> {
        let mut t = Vec::new();
        for c in &self.convs {
            t.push((
                format!("{}.weight", c.name),
                c.shape().to_vec(),
                to_f32(c.weight.clone()),
            ));
            t.push((
                format!("{}.bias", c.name),
                vec![c.shape()[0]],
                to_f32(c.bias.clone()),
            ));
        }
        write_safetensors(path, &t)?;
        let meta = WeightsMeta {
            format: "degs-evflownet-v1".into(),
            net: self.config,
            trained_by: trained_by.into(),
        };
        scene::atomic::write_json_atomic(&sidecar(path), &meta)
    }

    /// Load weights saved by [`FlowNet::save`] (or external safetensors with the same
    /// tensor names; then `config` must be given since there is no sidecar).
    pub fn load(
        path: &Path,
        config: Option<NetConfig>,
        device: &Device,
        dtype: DType,
    ) -> Result<FlowNet> {
        let side = sidecar(path);
        // Errors about the settings name the file they came from.
        let mut origin = path;
        let config = match std::fs::read_to_string(&side) {
            Ok(text) => {
                let meta: WeightsMeta = serde_json::from_str(&text)
                    .map_err(|e| Error::invalid(&side, format!("bad weights sidecar: {e}")))?;
                origin = &side;
                meta.net
            }
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(Error::io(&side, e));
            }
            Err(_) => config.ok_or_else(|| {
                Error::invalid(
                    path,
                    "no JSON sidecar; give the network settings explicitly \
                     (or load with evflow::net::io::load, which infers them)",
                )
            })?,
        };
        if config.base == 0
            || config.base > MAX_BASE
            || config.bins == 0
            || config.bins > MAX_BINS
            || !config.max_flow.is_finite()
            || config.max_flow <= 0.0
        {
            return Err(Error::invalid(
                origin,
                format!("invalid network settings {config:?}"),
            ));
        }
        FlowNet::from_tensors(path, config, &read_safetensors(path)?, device, dtype)
    }

    /// A network with `config` whose parameters are taken from `tensors` (read from
    /// `path`, named in errors): every tensor of [`layout`] must be there with its shape.
    pub(crate) fn from_tensors(
        path: &Path,
        config: NetConfig,
        tensors: &TensorMap,
        device: &Device,
        dtype: DType,
    ) -> Result<FlowNet> {
        if config.base == 0 || config.base > MAX_BASE || config.bins == 0 || config.bins > MAX_BINS
        {
            return Err(Error::invalid(
                path,
                format!(
                    "network settings out of range: C = {}, B = {}",
                    config.base, config.bins
                ),
            ));
        }
        // Check every tensor before allocating anything (a hostile sidecar or shape
        // must not make us allocate a huge network).
        let mut convs = Vec::new();
        for (name, out, inp, k, stride) in layout(&config) {
            let shape = [out, inp, k, k];
            let w = take(tensors, path, &format!("{name}.weight"), &shape)?;
            let b = take(tensors, path, &format!("{name}.bias"), &[out])?;
            convs.push((name, shape, w, b, stride));
        }
        let convs = convs
            .into_iter()
            .map(|(name, shape, w, b, stride)| Conv {
                name,
                weight: tensor4(w, shape, device, dtype),
                bias: Tensor::<1>::from_data(
                    TensorData::new(b, [shape[0]]).convert_dtype(dtype),
                    (device, dtype),
                ),
                stride,
                lora: None,
            })
            .collect();
        Ok(FlowNet {
            config,
            convs,
            device: device.clone(),
            dtype,
        })
    }
}

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
    let side = sidecar(path);
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

/// Environment variable that overrides the shipped weights' location.
pub const WEIGHTS_ENV: &str = "EVFLOW_WEIGHTS";

/// Directory of the weights shipped with the project.
pub fn shipped_weights_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/weights"))
}

/// The base weights to use: `explicit` if given, else `$EVFLOW_WEIGHTS`, else the shipped
/// `evflow/weights/default.safetensors` (or the only `*.safetensors` there).
pub fn resolve_weights(explicit: Option<&Path>) -> Result<PathBuf> {
    if let Some(p) = explicit {
        return Ok(p.to_path_buf());
    }
    if let Some(p) = std::env::var_os(WEIGHTS_ENV) {
        return Ok(PathBuf::from(p));
    }
    let dir = shipped_weights_dir();
    let default = dir.join("default.safetensors");
    if default.is_file() {
        return Ok(default);
    }
    let mut found: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "safetensors"))
                .collect()
        })
        .unwrap_or_default();
    found.sort();
    match found.len() {
        1 => Ok(found.remove(0)),
        0 => Err(Error::invalid(
            &dir,
            format!(
                "no shipped flow-network weights here; pass --weights FILE \
                 (or set {WEIGHTS_ENV}), or run `evflow pretrain`"
            ),
        )),
        _ => Err(Error::invalid(
            &dir,
            "several weight files and no default.safetensors; pass --weights FILE",
        )),
    }
}

/// Load base weights onto `device` (which may be an autodiff device); without a
/// sidecar the settings are inferred from the tensors ([`load`]).
pub fn load_base(path: &Path, device: &Device) -> Result<FlowNet> {
    load(path, &Default::default(), device, DType::F32).map(|l| l.net)
}
