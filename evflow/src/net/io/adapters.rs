//! LoRA adapters on their own: safetensors `NAME.lora_a` `[r, in·k·k]`, `NAME.lora_b`
//! `[out, r]` for every convolution, and a JSON sidecar with the rank, α and the network
//! settings they were trained for.

use super::tensor_file::{read_safetensors, sidecar, take, write_safetensors};
use crate::net::flownet::{FlowNet, NetConfig};
use crate::net::lora::Lora;
use crate::net::tensor::to_f32;
use burn::tensor::{Tensor, TensorData};
use scene::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// File name of the adapters in the output directory of `evflow finetune --mode lora`
/// (its sidecar is this name + `.json`).
pub const ADAPTER_FILE: &str = "adapter.safetensors";

/// The adapter file `--adapter PATH` means: `PATH/adapter.safetensors` when `PATH` is a
/// directory (the output of `evflow finetune`), else `PATH` itself. Its JSON sidecar
/// must be beside it; otherwise the error says what `--adapter` expects.
pub fn adapter_file(path: &Path) -> Result<PathBuf> {
    let expects = format!(
        "--adapter takes the output directory of `evflow finetune` (mode lora), or the \
         {ADAPTER_FILE} in it with its sidecar {ADAPTER_FILE}.json"
    );
    let file = if path.is_dir() {
        let file = path.join(ADAPTER_FILE);
        if !file.is_file() {
            return Err(Error::invalid(
                path,
                format!("directory has no {ADAPTER_FILE}; {expects}"),
            ));
        }
        file
    } else if path.is_file() {
        path.to_path_buf()
    } else {
        return Err(Error::invalid(path, format!("not found; {expects}")));
    };
    let side = sidecar(&file);
    if !side.is_file() {
        return Err(Error::invalid(
            &side,
            format!("adapter sidecar not found; {expects}"),
        ));
    }
    Ok(file)
}

/// Sidecar of an adapter file.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AdapterMeta {
    pub format: String,
    pub rank: usize,
    pub alpha: f64,
    pub net: NetConfig,
}

/// Save the adapters of `net` to `path` (safetensors) and `path.json` (sidecar).
pub fn save_adapters(net: &FlowNet, path: &Path) -> Result<()> {
    let mut tensors = Vec::new();
    let mut meta = None;
    for c in &net.convs {
        let Some(l) = &c.lora else {
            return Err(Error::invalid(
                path,
                format!("conv {} has no LoRA adapter", c.name),
            ));
        };
        meta.get_or_insert(AdapterMeta {
            format: "degs-lora-v1".into(),
            rank: l.rank,
            alpha: l.alpha,
            net: net.config,
        });
        let [r, f] = l.a.dims();
        let [o, _] = l.b.dims();
        tensors.push((
            format!("{}.lora_a", c.name),
            vec![r, f],
            to_f32(l.a.clone()),
        ));
        tensors.push((
            format!("{}.lora_b", c.name),
            vec![o, r],
            to_f32(l.b.clone()),
        ));
    }
    let meta = meta.ok_or_else(|| Error::invalid(path, "network has no convolutions"))?;
    write_safetensors(path, &tensors)?;
    scene::atomic::write_json_atomic(&sidecar(path), &meta)
}

/// Load adapters saved by [`save_adapters`] into `net` (replacing any it has).
pub fn load_adapters(net: &mut FlowNet, path: &Path) -> Result<()> {
    let side = sidecar(path);
    let text = std::fs::read_to_string(&side).map_err(|e| Error::io(&side, e))?;
    let meta: AdapterMeta = serde_json::from_str(&text)
        .map_err(|e| Error::invalid(&side, format!("bad adapter sidecar: {e}")))?;
    // The settings come from the sidecar: its errors name it.
    if meta.net != net.config {
        return Err(Error::invalid(
            &side,
            format!(
                "adapter is for network {:?}, not {:?}",
                meta.net, net.config
            ),
        ));
    }
    if meta.rank == 0 || !meta.alpha.is_finite() {
        return Err(Error::invalid(
            &side,
            "adapter rank must be > 0 and alpha finite",
        ));
    }
    let tensors = read_safetensors(path)?;
    // The expected shapes hold the sidecar's rank: a mismatch names both files.
    let with_rank = |e: Error| match e {
        Error::Invalid { path, msg } => Error::Invalid {
            path,
            msg: format!("{msg} (rank {} from {})", meta.rank, side.display()),
        },
        other => other,
    };
    for c in &mut net.convs {
        let [out, inp, kh, kw] = c.shape();
        let fan = inp * kh * kw;
        let a = take(
            &tensors,
            path,
            &format!("{}.lora_a", c.name),
            &[meta.rank, fan],
        )
        .map_err(with_rank)?;
        let b = take(
            &tensors,
            path,
            &format!("{}.lora_b", c.name),
            &[out, meta.rank],
        )
        .map_err(with_rank)?;
        let (dev, dt) = (&net.device, net.dtype);
        c.lora = Some(Lora {
            a: Tensor::<2>::from_data(
                TensorData::new(a, [meta.rank, fan]).convert_dtype(dt),
                (dev, dt),
            ),
            b: Tensor::<2>::from_data(
                TensorData::new(b, [out, meta.rank]).convert_dtype(dt),
                (dev, dt),
            ),
            rank: meta.rank,
            alpha: meta.alpha,
        });
    }
    Ok(())
}
