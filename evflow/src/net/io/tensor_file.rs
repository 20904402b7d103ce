//! Named f32 tensors in safetensors files, and the JSON sidecar beside such a file.

use scene::error::{Error, Result};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// A named f32 tensor for safetensors I/O: name, shape, values.
pub type NamedF32 = (String, Vec<usize>, Vec<f32>);

/// Write named f32 tensors as safetensors, atomically.
pub fn write_safetensors(path: &Path, tensors: &[NamedF32]) -> Result<()> {
    let bytes: Vec<Vec<u8>> = tensors
        .iter()
        .map(|(_, _, v)| v.iter().flat_map(|x| x.to_le_bytes()).collect())
        .collect();
    let views = tensors
        .iter()
        .zip(&bytes)
        .map(|((name, shape, _), b)| {
            safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape.clone(), b)
                .map(|v| (name.clone(), v))
        })
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(|e| Error::invalid(path, format!("safetensors: {e}")))?;
    let out = safetensors::serialize(views, None)
        .map_err(|e| Error::invalid(path, format!("safetensors: {e}")))?;
    scene::atomic::write_bytes_atomic(path, &out)
}

/// Tensors by name: (shape, values as f32).
pub type TensorMap = HashMap<String, (Vec<usize>, Vec<f32>)>;

/// Read every tensor of a safetensors file as f32 (F32 or F64 stored), checking
/// finiteness.
pub fn read_safetensors(path: &Path) -> Result<TensorMap> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let st = safetensors::SafeTensors::deserialize(&bytes)
        .map_err(|e| Error::invalid(path, format!("not a safetensors file: {e}")))?;
    let mut out = HashMap::new();
    for (name, view) in st.tensors() {
        let data = view.data();
        let values: Vec<f32> = match view.dtype() {
            safetensors::Dtype::F32 => data
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
            safetensors::Dtype::F64 => data
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")) as f32)
                .collect(),
            d => {
                return Err(Error::invalid(
                    path,
                    format!("tensor {name} has dtype {d:?}; only F32/F64 are supported"),
                ));
            }
        };
        if values.iter().any(|x| !x.is_finite()) {
            return Err(Error::invalid(
                path,
                format!("tensor {name} has non-finite values"),
            ));
        }
        out.insert(name, (view.shape().to_vec(), values));
    }
    Ok(out)
}

/// The values of tensor `name`, which must have exactly `shape`.
pub fn take(
    tensors: &HashMap<String, (Vec<usize>, Vec<f32>)>,
    path: &Path,
    name: &str,
    shape: &[usize],
) -> Result<Vec<f32>> {
    let (s, v) = tensors
        .get(name)
        .ok_or_else(|| Error::invalid(path, format!("missing tensor {name}")))?;
    if s != shape {
        return Err(Error::invalid(
            path,
            format!("tensor {name} has shape {s:?}, expected {shape:?}"),
        ));
    }
    Ok(v.clone())
}

/// Path of the JSON sidecar of a safetensors file.
pub fn sidecar(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".json");
    s.into()
}
