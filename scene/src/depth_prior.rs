//! Depth maps from outside the recording (a monocular depth network, a depth sensor):
//! `depth/<stem>.exr` beside the scene's manifests, one per train frame whose image is
//! `images/<stem>.png`, channel `Z`, with `depth/depth.json` saying what the values are:
//!
//! ```json
//! { "kind": "z" }            // camera-space depth along −Z, in the poses' units
//! { "kind": "affine" }       // a · z + b with a, b unknown per frame (relative depth)
//! { "kind": "inverse_affine" } // a / z + b per frame (disparity-like: MiDaS, Depth Anything)
//! ```
//!
//! Values ≤ 0 or not finite are holes. Frames without a file have no prior. A user of
//! a monocular network writes its output here; the tracks init aligns each frame's map
//! to the still scene it triangulated (`gaussians::tracks::depth`) and uses it for the
//! distance of moving points, which one moving camera cannot give (BENCHMARKS.md, "How
//! near must a moving object's distance be?").

use crate::{Error, Manifest, Result, image_io};
use std::path::{Path, PathBuf};

/// The folder beside the manifests.
pub const DIR: &str = "depth";
/// What the maps hold.
pub const KIND_FILE: &str = "depth.json";

/// How a prior's values relate to camera-space depth `z`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DepthKind {
    /// `z` itself.
    Z,
    /// `a·z + b`, `a > 0` and `b` unknown per frame.
    Affine,
    /// `a/z + b`, `a > 0` and `b` unknown per frame.
    InverseAffine,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct KindFile {
    kind: DepthKind,
}

/// The depth priors of a scene's train frames.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthPriors {
    pub kind: DepthKind,
    /// Per train frame (manifest order): the map, row-major at the camera's size.
    pub maps: Vec<Option<Vec<f32>>>,
}

/// The map file of a train frame: `depth/<stem of its image>.exr`.
pub fn map_path(root: &Path, image: &str) -> PathBuf {
    let stem = Path::new(image)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    root.join(DIR).join(format!("{stem}.exr"))
}

/// Whether the scene at `root` has depth priors (its `depth/depth.json`; [`load`] reads
/// and checks them).
pub fn exists(root: &Path) -> bool {
    root.join(DIR).join(KIND_FILE).exists()
}

/// Read the priors of `train` (the scene's train manifest, at `root`): `None` when the
/// scene has no `depth/depth.json`. A map of the wrong size, a kind file that does not
/// parse, or a `depth.json` with no map at all is an error naming the file.
pub fn load(root: &Path, train: &Manifest) -> Result<Option<DepthPriors>> {
    if !exists(root) {
        return Ok(None);
    }
    let kind_path = root.join(DIR).join(KIND_FILE);
    let text = std::fs::read_to_string(&kind_path).map_err(|e| Error::io(&kind_path, e))?;
    let kind = serde_json::from_str::<KindFile>(&text)
        .map_err(|e| {
            Error::invalid(
                &kind_path,
                format!("{e} (expected {{\"kind\": \"z\" | \"affine\" | \"inverse_affine\"}})"),
            )
        })?
        .kind;
    let (w, h) = (train.camera.width, train.camera.height);
    let mut maps = Vec::with_capacity(train.frames.len());
    for f in &train.frames {
        let path = map_path(root, &f.file_path);
        if !path.exists() {
            maps.push(None);
            continue;
        }
        let (mw, mh, z) = image_io::read_exr_depth(&path)?;
        if (mw, mh) != (w, h) {
            return Err(Error::invalid(
                &path,
                format!("depth map is {mw}×{mh}, the train frames {w}×{h}"),
            ));
        }
        maps.push(Some(z));
    }
    if maps.iter().all(Option::is_none) {
        return Err(Error::invalid(
            &kind_path,
            "no depth map for any train frame (expected depth/<image stem>.exr)",
        ));
    }
    Ok(Some(DepthPriors { kind, maps }))
}

/// Write a scene's priors (tests, scripts): the kind file and each frame's map, into a
/// `depth/` folder this creates; an existing one (a user's maps) is refused, not
/// overwritten.
pub fn write(root: &Path, train: &Manifest, priors: &DepthPriors) -> Result<()> {
    let dir = root.join(DIR);
    if dir.exists() {
        return Err(Error::invalid(
            &dir,
            "already exists: remove it to write new depth priors",
        ));
    }
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    let kind = match priors.kind {
        DepthKind::Z => "z",
        DepthKind::Affine => "affine",
        DepthKind::InverseAffine => "inverse_affine",
    };
    let kind_path = dir.join(KIND_FILE);
    std::fs::write(&kind_path, format!("{{\"kind\": \"{kind}\"}}\n"))
        .map_err(|e| Error::io(&kind_path, e))?;
    let (w, h) = (train.camera.width, train.camera.height);
    for (f, m) in train.frames.iter().zip(&priors.maps) {
        if let Some(m) = m {
            image_io::write_exr_depth(map_path(root, &f.file_path), w, h, m)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Frame, Intrinsics, Pose};

    fn manifest(n: usize) -> Manifest {
        Manifest {
            camera: Intrinsics::from_fov_x(6, 4, 1.0),
            frames: (0..n)
                .map(|k| Frame {
                    file_path: format!("images/train_{k:04}.png"),
                    timestamp: k as f64,
                    time: k as f64 / n as f64,
                    cam_to_world: Pose::default(),
                })
                .collect(),
            events: None,
            frame_encoding: None,
        }
    }

    #[test]
    fn priors_read_back_as_written_and_frames_without_a_map_have_none() {
        let dir = tempfile::tempdir().unwrap();
        let m = manifest(3);
        assert_eq!(
            load(dir.path(), &m).unwrap(),
            None,
            "no depth.json: no prior"
        );
        let map: Vec<f32> = (0..24).map(|i| 1.0 + i as f32 / 8.0).collect();
        let p = DepthPriors {
            kind: DepthKind::InverseAffine,
            maps: vec![Some(map.clone()), None, Some(vec![0.0; 24])],
        };
        write(dir.path(), &m, &p).unwrap();
        let again = write(dir.path(), &m, &p).unwrap_err().to_string();
        assert!(again.contains("already exists"), "{again}");
        assert!(dir.path().join("depth/train_0000.exr").is_file());
        assert!(!dir.path().join("depth/train_0001.exr").exists());
        assert_eq!(load(dir.path(), &m).unwrap(), Some(p));
    }

    #[test]
    fn errors_name_the_file_and_what_is_wrong() {
        let dir = tempfile::tempdir().unwrap();
        let m = manifest(2);
        std::fs::create_dir_all(dir.path().join(DIR)).unwrap();
        let kind = dir.path().join(DIR).join(KIND_FILE);
        std::fs::write(&kind, "{\"kind\": \"metres\"}").unwrap();
        let e = load(dir.path(), &m).unwrap_err().to_string();
        assert!(
            e.contains("depth.json") && e.contains("inverse_affine"),
            "{e}"
        );
        std::fs::write(&kind, "{\"kind\": \"z\"}").unwrap();
        let e = load(dir.path(), &m).unwrap_err().to_string();
        assert!(e.contains("no depth map for any train frame"), "{e}");
        let wrong = dir.path().join(DIR).join("train_0001.exr");
        image_io::write_exr_depth(&wrong, 5, 4, &[1.0; 20]).unwrap();
        let e = load(dir.path(), &m).unwrap_err().to_string();
        assert!(
            e.contains("train_0001.exr") && e.contains("5×4") && e.contains("6×4"),
            "{e}"
        );
    }
}
