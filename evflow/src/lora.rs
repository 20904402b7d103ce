//! LoRA adapters on convolutions (paper Eq. 7; REFERENCES "LoRA on convolutions").
//!
//! A kernel `W0` of shape `[out, in, k, k]` is seen as the matrix `[out, in·k·k]`; the
//! adapter adds `ΔW = (α/r)·B·A` with `A: [r, in·k·k]` Gaussian (std `1/√(in·k·k)`)
//! and `B: [out, r]` zero, so at initialisation the network is exactly the base one.
//! `W0` stays frozen during LoCM. Adapters are saved on their own (safetensors
//! `NAME.lora_a`, `NAME.lora_b`, JSON sidecar with rank and α) and can be merged.

use crate::net::{FlowNet, to_f32};
use burn::tensor::{DType, Device, Tensor, TensorData};
use rand_distr::{Distribution, Normal};
use scene::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One adapter.
#[derive(Clone, Debug)]
pub struct Lora {
    /// `[r, in·k·k]`.
    pub a: Tensor<2>,
    /// `[out, r]`.
    pub b: Tensor<2>,
    pub rank: usize,
    pub alpha: f64,
}

impl Lora {
    pub fn new(
        shape: [usize; 4],
        rank: usize,
        alpha: f64,
        rng: &mut impl rand::Rng,
        device: &Device,
        dtype: DType,
    ) -> Lora {
        let [out, inp, kh, kw] = shape;
        let fan = inp * kh * kw;
        let normal = Normal::new(0.0, 1.0 / (fan as f64).sqrt()).expect("finite std");
        let a: Vec<f64> = (0..rank * fan).map(|_| normal.sample(rng)).collect();
        let a = Tensor::<2>::from_data(
            TensorData::new(a, [rank, fan]).convert_dtype(dtype),
            (device, dtype),
        );
        let b = Tensor::<2>::zeros([out, rank], (device, dtype));
        Lora { a, b, rank, alpha }
    }

    /// `(α/r)·B·A` reshaped to the kernel.
    pub fn delta(&self, shape: [usize; 4]) -> Tensor<4> {
        self.b
            .clone()
            .matmul(self.a.clone())
            .mul_scalar(self.alpha / self.rank as f64)
            .reshape(shape)
    }
}

/// Sidecar of an adapter file.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AdapterMeta {
    pub format: String,
    pub rank: usize,
    pub alpha: f64,
    pub net: crate::net::NetConfig,
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
    crate::net::write_safetensors(path, &tensors)?;
    scene::atomic::write_json_atomic(&sidecar(path), &meta)
}

/// Path of the JSON sidecar of a safetensors file.
pub fn sidecar(path: &Path) -> std::path::PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".json");
    s.into()
}

/// Load adapters saved by [`save_adapters`] into `net` (replacing any it has).
pub fn load_adapters(net: &mut FlowNet, path: &Path) -> Result<()> {
    let text = std::fs::read_to_string(sidecar(path)).map_err(|e| Error::Io {
        path: sidecar(path),
        err: e,
    })?;
    let meta: AdapterMeta = serde_json::from_str(&text)
        .map_err(|e| Error::invalid(sidecar(path), format!("bad adapter sidecar: {e}")))?;
    if meta.net != net.config {
        return Err(Error::invalid(
            path,
            format!(
                "adapter is for network {:?}, not {:?}",
                meta.net, net.config
            ),
        ));
    }
    if meta.rank == 0 || !meta.alpha.is_finite() {
        return Err(Error::invalid(
            path,
            "adapter rank must be > 0 and alpha finite",
        ));
    }
    let tensors = crate::net::read_safetensors(path)?;
    for c in &mut net.convs {
        let [out, inp, kh, kw] = c.shape();
        let fan = inp * kh * kw;
        let a = crate::net::take(
            &tensors,
            path,
            &format!("{}.lora_a", c.name),
            &[meta.rank, fan],
        )?;
        let b = crate::net::take(
            &tensors,
            path,
            &format!("{}.lora_b", c.name),
            &[out, meta.rank],
        )?;
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
