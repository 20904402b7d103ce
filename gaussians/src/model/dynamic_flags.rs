//! The per-Gaussian dynamic flags of a saved model ([`crate::Splats::dynamic`]) in
//! `dynamic.safetensors`: one tensor `dynamic`, dtype `BOOL`, shape `[n]` (one byte per
//! Gaussian, 0 or 1, in PLY order; numpy and PyTorch read it as a bool array).
//!
//! Format 1 of `model.json` held them as a string of `'0'`/`'1'`; [`parse_legacy`]
//! still reads it.

use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use scene::error::{Error, IoContext, Result};
use std::path::Path;

pub const FLAGS_FILE: &str = "dynamic.safetensors";
/// Name of the tensor inside [`FLAGS_FILE`].
pub(crate) const FLAGS_TENSOR: &str = "dynamic";

/// Write `flags` to `path` atomically.
pub fn write(path: &Path, flags: &[bool]) -> Result<()> {
    let bytes: Vec<u8> = flags.iter().map(|&d| d as u8).collect();
    let tensor = TensorView::new(Dtype::BOOL, vec![flags.len()], &bytes)
        .map_err(|e| Error::invalid(path, format!("dynamic flags tensor: {e}")))?;
    let data = safetensors::serialize([(FLAGS_TENSOR, tensor)], None)
        .map_err(|e| Error::invalid(path, format!("serialising: {e}")))?;
    scene::atomic::write_bytes_atomic(path, &data)
}

/// Read the flags of `n` Gaussians written by [`write()`]; errors name the file (missing,
/// not safetensors, truncated, wrong tensor, dtype or length, a byte other than 0/1).
pub fn read(path: &Path, n: usize) -> Result<Vec<bool>> {
    let data = std::fs::read(path).at(path)?;
    let st = SafeTensors::deserialize(&data)
        .map_err(|e| Error::invalid(path, format!("not a safetensors file: {e}")))?;
    let t = st
        .tensor(FLAGS_TENSOR)
        .map_err(|_| Error::invalid(path, format!("missing tensor {FLAGS_TENSOR}")))?;
    if t.dtype() != Dtype::BOOL || t.shape() != [n] {
        return Err(Error::invalid(
            path,
            format!(
                "tensor {FLAGS_TENSOR}: expected bool [{n}] (one per Gaussian), found {:?} {:?}",
                t.dtype(),
                t.shape()
            ),
        ));
    }
    if st.len() != 1 {
        return Err(Error::invalid(path, "unexpected extra tensors"));
    }
    t.data()
        .iter()
        .enumerate()
        .map(|(i, &b)| match b {
            0 => Ok(false),
            1 => Ok(true),
            _ => Err(Error::invalid(
                path,
                format!("Gaussian {i}: flag byte {b} (expected 0 or 1)"),
            )),
        })
        .collect()
}

/// The format-1 string of `'1'` (dynamic) / `'0'` (static) for `n` Gaussians; errors
/// name `path` (the `model.json` it came from).
pub(crate) fn parse_legacy(path: &Path, text: &str, n: usize) -> Result<Vec<bool>> {
    if text.len() != n || text.bytes().any(|b| b != b'0' && b != b'1') {
        return Err(Error::invalid(
            path,
            format!("`dynamic` must be {n} characters '0'/'1'"),
        ));
    }
    Ok(text.bytes().map(|b| b == b'1').collect())
}
