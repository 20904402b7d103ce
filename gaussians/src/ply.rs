//! Gaussians as PLY in the layout of the original 3DGS code (`docs/DESIGN.md` §3): one
//! `vertex` element of float32 properties `x y z [nx ny nz] f_dc_0..2 f_rest_* opacity
//! scale_0..2 rot_0..3`, binary little-endian. `f_rest` is channel-major in the file
//! (all red coefficients 1..15, then green, then blue); [`Splats::sh_rest`] is
//! coefficient-major. Degree d has `3·((d+1)² − 1)` `f_rest` fields. Stored raw: logit
//! opacity, log scale, w-first unnormalised quaternion. The normals of the 3DGS layout
//! are always zero there and unused: files written here leave them out (viewers find
//! properties by name), files with them are read.
//!
//! Parsing uses `ply-rs-bw` with a typed element ([`Vertex`]), not the generic map.

use crate::raster::sh::num_coeffs;
use crate::splats::{Gaussian, Splats};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    Addable, ElementDef, Encoding, Ply, PropertyAccess, PropertyAccessResult, PropertyDef,
    PropertyType, ScalarType,
};
use ply_rs_bw::writer::Writer;
use scene::{Error, IoContext, Result};
use std::path::Path;

/// Float slots of one vertex: x y z, nx ny nz, f_dc ×3, f_rest ×45, opacity, scale ×3,
/// rot ×4.
const SLOTS: usize = 62;
const OPACITY: usize = 54;
const SCALE: usize = 55;
const ROT: usize = 58;

/// One 3DGS vertex, parsed straight into fixed slots.
#[derive(Clone, Debug)]
pub(crate) struct Vertex(pub [f32; SLOTS]);

/// Slot of a 3DGS property name.
fn slot(name: &str) -> Option<usize> {
    let idx = |prefix: &str, n: usize| {
        name.strip_prefix(prefix)
            .and_then(|s| s.parse::<usize>().ok())
            .filter(|&k| k < n && name.len() == prefix.len() + k.to_string().len())
    };
    Some(match name {
        "x" => 0,
        "y" => 1,
        "z" => 2,
        "nx" => 3,
        "ny" => 4,
        "nz" => 5,
        "opacity" => OPACITY,
        _ => {
            if let Some(k) = idx("f_dc_", 3) {
                6 + k
            } else if let Some(k) = idx("f_rest_", 45) {
                9 + k
            } else if let Some(k) = idx("scale_", 3) {
                SCALE + k
            } else {
                ROT + idx("rot_", 4)?
            }
        }
    })
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Vertex([0.0; SLOTS])
    }
    fn set_float(&mut self, name: &str, value: f32) -> PropertyAccessResult {
        match slot(name) {
            Some(k) => {
                self.0[k] = value;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::Ignored,
        }
    }
    fn get_float(&self, name: &str) -> Option<f32> {
        slot(name).map(|k| self.0[k])
    }
}

/// The property names this crate writes, in file order, for SH `degree` (0..=3): the
/// 3DGS layout without its unused normals.
pub fn property_names(degree: u32) -> Vec<String> {
    layout(degree, false)
}

/// The 3DGS property names in file order for SH `degree`, with or without the normals
/// `nx ny nz` after the position.
pub fn layout(degree: u32, normals: bool) -> Vec<String> {
    let mut v: Vec<String> = ["x", "y", "z"].map(String::from).into();
    if normals {
        v.extend(["nx", "ny", "nz"].map(String::from));
    }
    v.extend((0..3).map(|k| format!("f_dc_{k}")));
    v.extend((0..3 * (num_coeffs(degree) - 1)).map(|k| format!("f_rest_{k}")));
    v.push("opacity".into());
    v.extend((0..3).map(|k| format!("scale_{k}")));
    v.extend((0..4).map(|k| format!("rot_{k}")));
    v
}

/// Write `s` at SH `degree` atomically. Refuses non-finite parameters.
pub fn write(path: &Path, s: &Splats, degree: u32) -> Result<()> {
    let degree = degree.min(3);
    let n = s.len();
    let consistent = [
        s.log_scales.len(),
        s.rotations.len(),
        s.opacity_logits.len(),
        s.sh_dc.len(),
        s.sh_rest.len(),
    ]
    .iter()
    .all(|&l| l == n);
    if !consistent {
        return Err(Error::invalid(path, "Splats arrays have different lengths"));
    }
    let nr = num_coeffs(degree) - 1;
    let mut verts = Vec::with_capacity(n);
    for i in 0..n {
        let mut v = [0.0f32; SLOTS];
        v[0..3].copy_from_slice(&s.means[i]);
        v[6..9].copy_from_slice(&s.sh_dc[i]);
        for c in 0..3 {
            for j in 0..nr {
                v[9 + c * nr + j] = s.sh_rest[i][j * 3 + c];
            }
        }
        v[OPACITY] = s.opacity_logits[i];
        v[SCALE..SCALE + 3].copy_from_slice(&s.log_scales[i]);
        v[ROT..ROT + 4].copy_from_slice(&s.rotations[i]);
        if let Some(k) = v.iter().position(|x| !x.is_finite()) {
            return Err(Error::invalid(
                path,
                format!("Gaussian {i} has a non-finite value in slot {k}; not written"),
            ));
        }
        verts.push(Vertex(v));
    }
    let mut el = ElementDef::new("vertex".to_string());
    for name in property_names(degree) {
        el.properties.add(PropertyDef::new(
            name,
            PropertyType::Scalar(ScalarType::Float),
        ));
    }
    el.count = n;
    let mut ply = Ply::<Vertex>::new();
    ply.header.encoding = Encoding::BinaryLittleEndian;
    ply.header.elements.add(el);
    ply.payload.insert("vertex".to_string(), verts);
    scene::atomic::write_atomic(path, |w| {
        Writer::<Vertex>::new().write_ply(w, &mut ply).map(|_| ())
    })
}

/// A PLY as read: the Gaussians, their SH degree, and how many were dropped.
#[derive(Debug)]
pub struct PlyCloud {
    pub splats: Splats,
    pub degree: u32,
    /// Gaussians whose opacity logit is −inf (fully transparent: other 3DGS tools write
    /// these for pruned points); dropped, not an error.
    pub dropped_transparent: usize,
}

/// Read a 3DGS PLY; returns the Gaussians and their SH degree (from the number of
/// `f_rest` fields). Errors name the file: unreadable, not PLY, wrong property list,
/// zero vertices, truncated payload, non-finite values (NaN anywhere, ±inf except an
/// opacity logit of −inf, whose Gaussian is dropped: [`read_counted`] counts them).
pub fn read(path: &Path) -> Result<(Splats, u32)> {
    let c = read_counted(path)?;
    Ok((c.splats, c.degree))
}

/// [`read`] with the count of dropped fully transparent Gaussians.
pub fn read_counted(path: &Path) -> Result<PlyCloud> {
    let bytes = std::fs::read(path).at(path)?;
    parse_counted(path, &bytes)
}

/// [`read`] from bytes already in memory (`path` only names them in errors).
pub fn parse(path: &Path, bytes: &[u8]) -> Result<(Splats, u32)> {
    let c = parse_counted(path, bytes)?;
    Ok((c.splats, c.degree))
}

/// [`read_counted`] from bytes already in memory.
pub(crate) fn parse_counted(path: &Path, bytes: &[u8]) -> Result<PlyCloud> {
    let bad = |msg: String| Error::invalid(path, msg);
    if bytes.is_empty() {
        return Err(bad("empty file, not a PLY".into()));
    }
    if !bytes.starts_with(b"ply") {
        return Err(bad("not a PLY file (no `ply` magic)".into()));
    }
    let header_len = find(bytes, b"end_header\n")
        .map(|p| p + 11)
        .or_else(|| find(bytes, b"end_header\r\n").map(|p| p + 12))
        .ok_or_else(|| bad("PLY header has no `end_header` line".into()))?;
    let parser = Parser::<Vertex>::new();
    let mut reader = Reader::new(std::io::Cursor::new(bytes));
    let header = parser
        .read_header(&mut reader)
        .map_err(|e| bad(format!("bad PLY header: {e}")))?;
    if header.elements.len() != 1 || !header.elements.contains_key("vertex") {
        let names: Vec<&String> = header.elements.keys().collect();
        return Err(bad(format!(
            "expected exactly one element `vertex` (3DGS layout), found {names:?}"
        )));
    }
    let el = &header.elements["vertex"];
    let found: Vec<&str> = el.properties.keys().map(String::as_str).collect();
    let degree = match (0..=3u32)
        .flat_map(|d| [(d, false), (d, true)])
        .find(|&(d, normals)| layout(d, normals) == found)
    {
        Some((d, _)) => d,
        None => {
            // Name the first property that differs from the closest 3DGS layout.
            let n_rest = found.iter().filter(|n| n.starts_with("f_rest_")).count();
            let has_normals = found.get(3) == Some(&"nx");
            let d = [0u32, 1, 2, 3]
                .into_iter()
                .min_by_key(|&d| (3 * (num_coeffs(d) - 1)).abs_diff(n_rest))
                .unwrap_or(3);
            let want = layout(d, has_normals);
            let k = (0..want.len().max(found.len()))
                .find(|&k| want.get(k).map(String::as_str) != found.get(k).copied())
                .unwrap_or(0);
            return Err(bad(format!(
                "vertex properties are not the 3DGS layout (x y z [nx ny nz] f_dc_0..2 \
                 f_rest_* opacity scale_0..2 rot_0..3): property {k} is {:?}, expected {:?} \
                 ({} properties found)",
                found.get(k).copied().unwrap_or("<none>"),
                want.get(k).map(String::as_str).unwrap_or("<none>"),
                found.len()
            )));
        }
    };
    if let Some((name, _)) = el
        .properties
        .iter()
        .find(|(_, p)| p.data_type != PropertyType::Scalar(ScalarType::Float))
    {
        return Err(bad(format!("property `{name}` is not float32")));
    }
    if el.count == 0 {
        return Err(bad("the PLY holds zero Gaussians".into()));
    }
    if header.encoding != Encoding::Ascii {
        let need = (el.count as u128) * (found.len() as u128) * 4;
        let have = (bytes.len() - header_len.min(bytes.len())) as u128;
        if have < need {
            return Err(bad(format!(
                "truncated: header declares {} Gaussians ({need} bytes) but {have} bytes follow",
                el.count
            )));
        }
    }
    let verts = parser
        .read_payload_for_element(&mut reader, el, &header)
        .map_err(|e| bad(format!("cannot read the vertex data: {e}")))?;
    if verts.len() != el.count {
        return Err(bad(format!(
            "read {} of {} Gaussians",
            verts.len(),
            el.count
        )));
    }
    let nr = num_coeffs(degree) - 1;
    let mut s = Splats::with_capacity(verts.len());
    let mut dropped = 0;
    for (i, Vertex(v)) in verts.iter().enumerate() {
        // exp(−inf) = 0: a Gaussian that renders nothing. Drop it (NaN stays an error).
        let transparent = v[OPACITY] == f32::NEG_INFINITY;
        if let Some(k) = v
            .iter()
            .enumerate()
            .position(|(k, x)| !x.is_finite() && (!transparent || k != OPACITY))
        {
            let name = layout(3, true)
                .into_iter()
                .find(|n| slot(n) == Some(k))
                .unwrap_or_default();
            return Err(bad(format!(
                "Gaussian {i}: `{name}` is not finite ({})",
                v[k]
            )));
        }
        if transparent {
            dropped += 1;
            continue;
        }
        let mut sh_rest = [0.0f32; 45];
        for c in 0..3 {
            for j in 0..nr {
                sh_rest[j * 3 + c] = v[9 + c * nr + j];
            }
        }
        s.push(Gaussian {
            mean: [v[0], v[1], v[2]],
            log_scale: [v[SCALE], v[SCALE + 1], v[SCALE + 2]],
            rotation: [v[ROT], v[ROT + 1], v[ROT + 2], v[ROT + 3]],
            opacity_logit: v[OPACITY],
            sh_dc: [v[6], v[7], v[8]],
            sh_rest,
            dynamic: true,
        });
    }
    if s.is_empty() {
        return Err(bad(format!(
            "all {dropped} Gaussians have opacity −inf (fully transparent): nothing to load"
        )));
    }
    // The PLY carries no dynamic flags: none (every Gaussian counts as dynamic).
    s.dynamic.clear();
    Ok(PlyCloud {
        splats: s,
        degree,
        dropped_transparent: dropped,
    })
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_cover_every_property_once() {
        let names = layout(3, true);
        assert_eq!(names.len(), SLOTS);
        let mut seen = [false; SLOTS];
        for n in &names {
            let k = slot(n).unwrap();
            assert!(!seen[k], "{n}");
            seen[k] = true;
        }
        assert_eq!(slot("f_rest_45"), None);
        assert_eq!(slot("f_rest_01"), None);
        assert_eq!(slot("rot_4"), None);
        assert_eq!(slot("red"), None);
    }
}
