//! The per-Gaussian trajectories of a saved model ([`crate::Splats::motion`],
//! [`crate::motion`]) in `motion.safetensors`: one tensor `motion`, dtype `F32`, shape
//! `[n, 6]` (velocity then acceleration, world units per normalised time, about
//! [`crate::motion::T0`]), rows in PLY order. Also the `--init-motion` file of `gaussians
//! train`, beside an `--init-ply`.

use crate::motion::WIDTH;
use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use scene::error::{Error, IoContext, Result};
use std::path::Path;

pub const MOTION_FILE: &str = "motion.safetensors";
/// Name of the tensor inside [`MOTION_FILE`].
pub(crate) const MOTION_TENSOR: &str = "motion";

/// Write `motion` to `path` atomically; refuses non-finite values.
pub fn write(path: &Path, motion: &[[f32; WIDTH]]) -> Result<()> {
    if let Some(i) = motion.iter().position(|m| m.iter().any(|v| !v.is_finite())) {
        return Err(Error::invalid(
            path,
            format!("Gaussian {i}: non-finite trajectory"),
        ));
    }
    let bytes: Vec<u8> = motion
        .as_flattened()
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let tensor = TensorView::new(Dtype::F32, vec![motion.len(), WIDTH], &bytes)
        .map_err(|e| Error::invalid(path, format!("motion tensor: {e}")))?;
    let data = safetensors::serialize([(MOTION_TENSOR, tensor)], None)
        .map_err(|e| Error::invalid(path, format!("serialising: {e}")))?;
    scene::atomic::write_bytes_atomic(path, &data)
}

/// Read the trajectories of `n` Gaussians written by [`write()`] (or by any tool that
/// writes an `F32 [n, 6]` tensor `motion`); errors name the file (missing, not
/// safetensors, wrong tensor, dtype or shape, a non-finite value).
pub fn read(path: &Path, n: usize) -> Result<Vec<[f32; WIDTH]>> {
    let data = std::fs::read(path).at(path)?;
    let st = SafeTensors::deserialize(&data)
        .map_err(|e| Error::invalid(path, format!("not a safetensors file: {e}")))?;
    let t = st
        .tensor(MOTION_TENSOR)
        .map_err(|_| Error::invalid(path, format!("missing tensor {MOTION_TENSOR}")))?;
    if t.dtype() != Dtype::F32 || t.shape() != [n, WIDTH] {
        return Err(Error::invalid(
            path,
            format!(
                "tensor {MOTION_TENSOR}: expected F32 [{n}, {WIDTH}] (one row per Gaussian), \
                 found {:?} {:?}",
                t.dtype(),
                t.shape()
            ),
        ));
    }
    let values: Vec<f32> = t
        .data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if let Some(k) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid(
            path,
            format!("Gaussian {}: non-finite trajectory", k / WIDTH),
        ));
    }
    Ok(values
        .chunks_exact(WIDTH)
        .map(|c| std::array::from_fn(|k| c[k]))
        .collect())
}
