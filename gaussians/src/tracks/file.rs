//! The moving tracks of a warm-up that used `L_track` ([`super::loss`]), saved beside its
//! model in `tracks.safetensors` so that the joint training keeps the term: tensor
//! `track`, `I32 [n]` (per Gaussian in PLY order, the index of the track that pulls it,
//! −1 for none) and tensor `seen`, `F32 [tracks, views, 2]` (each track's position in
//! each train view in camera pixels, NaN where it was lost).

use glam::DVec2;
use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use scene::error::{Error, IoContext, Result};
use std::path::Path;

pub const TRACKS_FILE: &str = "tracks.safetensors";

/// Write the tracks `table` and the Gaussians' `ids` ([`super::loss::NONE`]: none) to
/// `path` atomically.
pub fn write(path: &Path, ids: &[u32], table: &[Vec<Option<DVec2>>]) -> Result<()> {
    let views = table.first().map_or(0, Vec::len);
    if table.iter().any(|r| r.len() != views) {
        return Err(Error::invalid(path, "tracks of different lengths"));
    }
    let ids_bytes: Vec<u8> = ids
        .iter()
        .map(|&i| if i == super::loss::NONE { -1 } else { i as i32 })
        .flat_map(i32::to_le_bytes)
        .collect();
    let seen: Vec<u8> = (table.iter().flatten())
        .flat_map(|p| p.map_or([f32::NAN; 2], |p| [p.x as f32, p.y as f32]))
        .flat_map(f32::to_le_bytes)
        .collect();
    let bad = |e| Error::invalid(path, format!("tracks tensor: {e}"));
    let track = TensorView::new(Dtype::I32, vec![ids.len()], &ids_bytes).map_err(bad)?;
    let seen = TensorView::new(Dtype::F32, vec![table.len(), views, 2], &seen).map_err(bad)?;
    let data = safetensors::serialize([("track", track), ("seen", seen)], None)
        .map_err(|e| Error::invalid(path, format!("serialising: {e}")))?;
    scene::atomic::write_bytes_atomic(path, &data)
}

/// Read what [`write()`] wrote for a model of `n` Gaussians and `views` train views;
/// errors name the file and what is wrong.
pub fn read(path: &Path, n: usize, views: usize) -> Result<(Vec<u32>, super::loss::Table)> {
    let data = std::fs::read(path).at(path)?;
    let st = SafeTensors::deserialize(&data)
        .map_err(|e| Error::invalid(path, format!("not a safetensors file: {e}")))?;
    let get = |name: &str| {
        st.tensor(name)
            .map_err(|_| Error::invalid(path, format!("missing tensor {name}")))
    };
    let (track, seen) = (get("track")?, get("seen")?);
    let count = seen.shape().first().copied().unwrap_or(0);
    if track.dtype() != Dtype::I32 || track.shape() != [n] {
        return Err(Error::invalid(
            path,
            format!(
                "tensor track: expected I32 [{n}], found {:?} {:?}",
                track.dtype(),
                track.shape()
            ),
        ));
    }
    if seen.dtype() != Dtype::F32 || seen.shape() != [count, views, 2] {
        return Err(Error::invalid(
            path,
            format!(
                "tensor seen: expected F32 [tracks, {views}, 2] (one row per train view), \
                 found {:?} {:?}",
                seen.dtype(),
                seen.shape()
            ),
        ));
    }
    let mut ids = Vec::with_capacity(n);
    for (g, b) in track.data().chunks_exact(4).enumerate() {
        let v = i32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        if v < -1 || v >= count as i32 {
            return Err(Error::invalid(
                path,
                format!("Gaussian {g}: track {v} (of {count})"),
            ));
        }
        ids.push(if v < 0 { super::loss::NONE } else { v as u32 });
    }
    let xy: Vec<f32> = (seen.data().chunks_exact(4))
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let table = xy
        .chunks_exact(2 * views.max(1))
        .take(count)
        .map(|row| {
            (row.chunks_exact(2))
                .map(|p| {
                    (p[0].is_finite() && p[1].is_finite())
                        .then(|| DVec2::new(p[0] as f64, p[1] as f64))
                })
                .collect()
        })
        .collect();
    Ok((ids, table))
}

/// The warm-up's aligned depth priors ([`super::prior_loss`]), saved beside its model so
/// that the joint training keeps `L_depth`: tensor `z`, `F32 [views, height, width]`
/// (camera depth in the poses' units; a view without a map is all 0).
pub const PRIORS_FILE: &str = "depth_prior.safetensors";

/// Write the aligned priors `maps` (one per train view, `width × height` each) to `path`
/// atomically.
pub fn write_priors(
    path: &Path,
    maps: &[Option<super::depth::Aligned>],
    width: usize,
    height: usize,
) -> Result<()> {
    let n = width * height;
    if maps.iter().flatten().any(|m| m.z.len() != n) {
        return Err(Error::invalid(path, "aligned priors of different sizes"));
    }
    let bytes: Vec<u8> = (maps.iter())
        .flat_map(|m| m.as_ref().map_or(vec![0.0; n], |m| m.z.clone()))
        .flat_map(f32::to_le_bytes)
        .collect();
    let bad = |e| Error::invalid(path, format!("priors tensor: {e}"));
    let z = TensorView::new(Dtype::F32, vec![maps.len(), height, width], &bytes).map_err(bad)?;
    let data = safetensors::serialize([("z", z)], None)
        .map_err(|e| Error::invalid(path, format!("serialising: {e}")))?;
    scene::atomic::write_bytes_atomic(path, &data)
}

/// Read what [`write_priors`] wrote for `views` train views of `width × height`; errors
/// name the file and what is wrong.
pub fn read_priors(
    path: &Path,
    views: usize,
    width: usize,
    height: usize,
) -> Result<Vec<Option<super::depth::Aligned>>> {
    let data = std::fs::read(path).at(path)?;
    let st = SafeTensors::deserialize(&data)
        .map_err(|e| Error::invalid(path, format!("not a safetensors file: {e}")))?;
    let z = (st.tensor("z")).map_err(|_| Error::invalid(path, "missing tensor z"))?;
    if z.dtype() != Dtype::F32 || z.shape() != [views, height, width] {
        return Err(Error::invalid(
            path,
            format!(
                "tensor z: expected F32 [{views}, {height}, {width}] (one map per train view), \
                 found {:?} {:?}",
                z.dtype(),
                z.shape()
            ),
        ));
    }
    let values: Vec<f32> = (z.data().chunks_exact(4))
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let maps = (values.chunks_exact((width * height).max(1)).take(views))
        .map(|m| {
            m.iter().any(|&v| v > 0.0).then(|| super::depth::Aligned {
                width,
                height,
                z: m.to_vec(),
                median_rel_error: f64::NAN,
                points: 0,
            })
        })
        .collect();
    Ok(maps)
}
