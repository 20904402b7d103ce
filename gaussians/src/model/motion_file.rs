//! The per-Gaussian trajectories of a saved model ([`crate::Splats::motion`],
//! [`crate::motion`]) in `motion.safetensors`: one tensor `motion`, dtype `F32`, shape
//! `[n, 6]` (velocity then acceleration, world units per normalised time, about
//! [`crate::motion::T0`]), rows in PLY order; and, when the Gaussians have lives
//! ([`crate::Splats::life`]), a tensor `life`, `F32 [n, 2]` (the normalised time span
//! each exists in, `[from, to)`); when some belong to rigid parts ([`crate::parts`]),
//! `part` (`U32 [n]`, `u32::MAX` for none), `part_knots` (`F32 [K]`), `part_origin`
//! (`F32 [P, 3]`), `part_rot` (`F32 [P·K, 4]`, w first), `part_shift` (`F32 [P·K, 3]`)
//! and `part_fixed` (`U32 [1]`, the knot held at the identity). Also the
//! `--init-motion` file of `gaussians train`, beside an `--init-ply`.

use crate::motion::WIDTH;
use crate::parts::Parts;
use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use scene::error::{Error, IoContext, Result};
use std::path::Path;

pub const MOTION_FILE: &str = "motion.safetensors";
/// Name of the tensor inside [`MOTION_FILE`].
pub(crate) const MOTION_TENSOR: &str = "motion";
/// Name of the optional lives tensor inside [`MOTION_FILE`].
pub(crate) const LIFE_TENSOR: &str = "life";

/// Write `motion` (and `life` unless empty) to `path` atomically; refuses non-finite
/// values.
pub fn write(path: &Path, motion: &[[f32; WIDTH]], life: &[[f32; 2]]) -> Result<()> {
    write_with_parts(path, motion, life, &[], &Parts::default())
}

/// [`write()`] with the rigid parts (`part` one entry per Gaussian, or empty).
pub fn write_with_parts(
    path: &Path,
    motion: &[[f32; WIDTH]],
    life: &[[f32; 2]],
    part: &[u32],
    parts: &Parts,
) -> Result<()> {
    if !part.is_empty() {
        parts
            .check(part, motion.len())
            .map_err(|e| Error::invalid(path, e))?;
    }
    let poses = (parts.rot.iter().flatten()).chain(parts.shift.iter().flatten());
    if poses
        .chain(parts.origin.iter().flatten())
        .any(|v| !v.is_finite())
    {
        return Err(Error::invalid(path, "non-finite part pose"));
    }
    let rows = (motion.iter().map(|m| m.as_slice())).chain(life.iter().map(|l| l.as_slice()));
    if let Some(i) = rows.clone().position(|m| m.iter().any(|v| !v.is_finite())) {
        return Err(Error::invalid(
            path,
            format!(
                "Gaussian {}: non-finite trajectory",
                i % motion.len().max(1)
            ),
        ));
    }
    if !life.is_empty() && life.len() != motion.len() {
        return Err(Error::invalid(
            path,
            format!("{} lives for {} trajectories", life.len(), motion.len()),
        ));
    }
    let bytes = |v: &[f32]| -> Vec<u8> { v.iter().flat_map(|v| v.to_le_bytes()).collect() };
    let (m, l) = (bytes(motion.as_flattened()), bytes(life.as_flattened()));
    let mut tensors = vec![(MOTION_TENSOR, view(path, MOTION_TENSOR, WIDTH, &m)?)];
    if !life.is_empty() {
        tensors.push((LIFE_TENSOR, view(path, LIFE_TENSOR, 2, &l)?));
    }
    let u32s = |v: &[u32]| -> Vec<u8> { v.iter().flat_map(|v| v.to_le_bytes()).collect() };
    let blobs = match part.is_empty() {
        true => Vec::new(),
        false => vec![
            (u32s(part), 1),
            (bytes(&parts.knots), 1),
            (bytes(parts.origin.as_flattened()), 3),
            (bytes(parts.rot.as_flattened()), 4),
            (bytes(parts.shift.as_flattened()), 3),
            (u32s(&[parts.fixed as u32]), 1),
        ],
    };
    for ((data, width), name) in blobs.iter().zip(PART_TENSORS) {
        let dtype = if matches!(name, "part" | "part_fixed") {
            Dtype::U32
        } else {
            Dtype::F32
        };
        let shape = match *width {
            1 => vec![data.len() / 4],
            w => vec![data.len() / 4 / w, w],
        };
        let t = TensorView::new(dtype, shape, data)
            .map_err(|e| Error::invalid(path, format!("{name} tensor: {e}")))?;
        tensors.push((name, t));
    }
    let data = safetensors::serialize(tensors, None)
        .map_err(|e| Error::invalid(path, format!("serialising: {e}")))?;
    scene::atomic::write_bytes_atomic(path, &data)
}

/// The tensors of the rigid parts, in [`write_with_parts`]'s order.
const PART_TENSORS: [&str; 6] = [
    "part",
    "part_knots",
    "part_origin",
    "part_rot",
    "part_shift",
    "part_fixed",
];

/// The rigid parts of `n` Gaussians in a file of [`write_with_parts`] (empty when it has
/// none); errors name the file and the tensor.
pub fn read_parts(path: &Path, n: usize) -> Result<(Vec<u32>, Parts)> {
    with_file(path, |st| parts_from(st, path, n))
}

/// The trajectories, lives and rigid parts of `n` Gaussians into `s`, from one reading of
/// the file (what [`read`], [`read_life`] and [`read_parts`] give apart).
pub fn read_into(path: &Path, s: &mut crate::Splats) -> Result<()> {
    let n = s.len();
    with_file(path, |st| {
        s.motion = motion_from(st, path, n)?;
        s.life = life_from(st, path, n)?;
        (s.part, s.parts) = parts_from(st, path, n)?;
        Ok(())
    })
}

/// `f` on the file at `path` read as safetensors.
fn with_file<R>(path: &Path, f: impl FnOnce(&SafeTensors) -> Result<R>) -> Result<R> {
    let data = std::fs::read(path).at(path)?;
    let st = SafeTensors::deserialize(&data)
        .map_err(|e| Error::invalid(path, format!("not a safetensors file: {e}")))?;
    f(&st)
}

fn parts_from(st: &SafeTensors, path: &Path, n: usize) -> Result<(Vec<u32>, Parts)> {
    if st.tensor("part").is_err() {
        return Ok((Vec::new(), Parts::default()));
    }
    let get = |name: &str, dtype: Dtype| -> Result<Vec<[u8; 4]>> {
        let t = (st.tensor(name))
            .map_err(|_| Error::invalid(path, format!("missing tensor {name}")))?;
        if t.dtype() != dtype {
            return Err(Error::invalid(
                path,
                format!("tensor {name}: expected {dtype:?}, found {:?}", t.dtype()),
            ));
        }
        Ok(t.data()
            .chunks_exact(4)
            .map(|b| [b[0], b[1], b[2], b[3]])
            .collect())
    };
    let f = |name: &str| -> Result<Vec<f32>> {
        let v: Vec<f32> = get(name, Dtype::F32)?
            .into_iter()
            .map(f32::from_le_bytes)
            .collect();
        match v.iter().all(|v| v.is_finite()) {
            true => Ok(v),
            false => Err(Error::invalid(
                path,
                format!("tensor {name}: a non-finite value"),
            )),
        }
    };
    let part: Vec<u32> = get("part", Dtype::U32)?
        .into_iter()
        .map(u32::from_le_bytes)
        .collect();
    let fixed = get("part_fixed", Dtype::U32)?
        .first()
        .map_or(0, |b| u32::from_le_bytes(*b));
    fn rows<const W: usize>(v: Vec<f32>) -> Vec<[f32; W]> {
        v.chunks_exact(W)
            .map(|c| std::array::from_fn(|k| c[k]))
            .collect()
    }
    let parts = Parts {
        knots: f("part_knots")?,
        origin: rows(f("part_origin")?),
        rot: rows(f("part_rot")?),
        shift: rows(f("part_shift")?),
        fixed: fixed as usize,
    };
    parts.check(&part, n).map_err(|e| Error::invalid(path, e))?;
    Ok((part, parts))
}

/// An `F32 [rows, width]` view of `data` (little-endian values).
fn view<'d>(path: &Path, name: &str, width: usize, data: &'d [u8]) -> Result<TensorView<'d>> {
    TensorView::new(Dtype::F32, vec![data.len() / 4 / width, width], data)
        .map_err(|e| Error::invalid(path, format!("{name} tensor: {e}")))
}

/// The lives of `n` Gaussians in a file of [`write()`]; empty when it has none. Errors
/// name the file (not safetensors, wrong dtype or shape, a non-finite value).
pub fn read_life(path: &Path, n: usize) -> Result<Vec<[f32; 2]>> {
    with_file(path, |st| life_from(st, path, n))
}

fn life_from(st: &SafeTensors, path: &Path, n: usize) -> Result<Vec<[f32; 2]>> {
    let Ok(t) = st.tensor(LIFE_TENSOR) else {
        return Ok(Vec::new());
    };
    if t.dtype() != Dtype::F32 || t.shape() != [n, 2] {
        return Err(Error::invalid(
            path,
            format!(
                "tensor {LIFE_TENSOR}: expected F32 [{n}, 2], found {:?} {:?}",
                t.dtype(),
                t.shape()
            ),
        ));
    }
    let v: Vec<f32> = (t.data().chunks_exact(4))
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if let Some(k) = v.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid(
            path,
            format!("Gaussian {}: non-finite life", k / 2),
        ));
    }
    Ok(v.chunks_exact(2).map(|c| [c[0], c[1]]).collect())
}

/// Read the trajectories of `n` Gaussians written by [`write()`] (or by any tool that
/// writes an `F32 [n, 6]` tensor `motion`); errors name the file (missing, not
/// safetensors, wrong tensor, dtype or shape, a non-finite value).
pub fn read(path: &Path, n: usize) -> Result<Vec<[f32; WIDTH]>> {
    with_file(path, |st| motion_from(st, path, n))
}

fn motion_from(st: &SafeTensors, path: &Path, n: usize) -> Result<Vec<[f32; WIDTH]>> {
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
