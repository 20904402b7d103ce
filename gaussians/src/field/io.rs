//! `field.safetensors` (weights, tensors `layers.{i}.weight` `[in, out]` and
//! `layers.{i}.bias`; the last layer is the 10-output head) + `field.json` (settings).

use super::mlp::Mlp;
use super::settings::FieldSettings;
use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use scene::error::{Error, Result};
use std::path::Path;

pub const WEIGHTS_FILE: &str = "field.safetensors";
pub(crate) const SETTINGS_FILE: &str = "field.json";

/// Write `dir/field.safetensors` and `dir/field.json` atomically.
pub fn save(mlp: &Mlp<f32>, dir: &Path) -> Result<()> {
    let bytes: Vec<u8> = mlp.params.iter().flat_map(|v| v.to_le_bytes()).collect();
    let mut views = Vec::new();
    for (i, l) in mlp.layers.iter().enumerate() {
        let w = &bytes[l.weight * 4..l.bias * 4];
        let b = &bytes[l.bias * 4..(l.bias + l.fan_out) * 4];
        let tw = TensorView::new(Dtype::F32, vec![l.fan_in, l.fan_out], w)
            .map_err(|e| Error::Other(format!("field tensor: {e}")))?;
        let tb = TensorView::new(Dtype::F32, vec![l.fan_out], b)
            .map_err(|e| Error::Other(format!("field tensor: {e}")))?;
        views.push((format!("layers.{i}.weight"), tw));
        views.push((format!("layers.{i}.bias"), tb));
    }
    let path = dir.join(WEIGHTS_FILE);
    let data = safetensors::serialize(views, None)
        .map_err(|e| Error::invalid(&path, format!("serialising: {e}")))?;
    scene::atomic::write_bytes_atomic(&path, &data)?;
    scene::atomic::write_json_atomic(&dir.join(SETTINGS_FILE), &mlp.settings)
}

/// Read a field saved by [`save`]; checks names, shapes, dtype and finiteness.
pub fn load(dir: &Path) -> Result<Mlp<f32>> {
    let spath = dir.join(SETTINGS_FILE);
    let text = std::fs::read_to_string(&spath).map_err(|e| Error::io(&spath, e))?;
    let settings: FieldSettings =
        serde_json::from_str(&text).map_err(|e| Error::invalid(&spath, e.to_string()))?;
    if settings.depth > 64
        || settings.width == 0
        || settings.width > 8192
        || settings.pos_freqs > 32
        || settings.time_freqs > 32
    {
        return Err(Error::invalid(&spath, "field settings out of range"));
    }
    let path = dir.join(WEIGHTS_FILE);
    let data = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
    let st = SafeTensors::deserialize(&data)
        .map_err(|e| Error::invalid(&path, format!("not a safetensors file: {e}")))?;
    // The settings size the network: 4 bytes per parameter must be in the weights file
    // before they are allocated (64 layers of 8192 would be 17 GB).
    let params = Mlp::<f32>::param_count(&settings);
    if params.saturating_mul(4) > data.len() {
        return Err(Error::invalid(
            &spath,
            format!(
                "settings describe {params} parameters but {} holds {} bytes",
                WEIGHTS_FILE,
                data.len()
            ),
        ));
    }
    let mut mlp = Mlp::<f32>::new(settings, 0);
    let layers = mlp.layers.clone();
    for (i, l) in layers.iter().enumerate() {
        for (name, shape, off) in [
            (
                format!("layers.{i}.weight"),
                vec![l.fan_in, l.fan_out],
                l.weight,
            ),
            (format!("layers.{i}.bias"), vec![l.fan_out], l.bias),
        ] {
            let t = st
                .tensor(&name)
                .map_err(|_| Error::invalid(&path, format!("missing tensor {name}")))?;
            if t.dtype() != Dtype::F32 || t.shape() != shape.as_slice() {
                // The expected shape comes from the settings: name both files.
                return Err(Error::invalid(
                    &path,
                    format!(
                        "tensor {name}: expected f32 {shape:?} (from {}), found {:?} {:?}",
                        spath.display(),
                        t.dtype(),
                        t.shape()
                    ),
                ));
            }
            let count: usize = shape.iter().product();
            for (k, c) in t.data().chunks_exact(4).enumerate().take(count) {
                let v = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                if !v.is_finite() {
                    return Err(Error::invalid(
                        &path,
                        format!("tensor {name} has a non-finite value"),
                    ));
                }
                mlp.params[off + k] = v;
            }
        }
    }
    if st.len() != 2 * layers.len() {
        return Err(Error::invalid(&path, "unexpected extra tensors"));
    }
    Ok(mlp)
}
