//! Novel-view PSNR on two masks (issue #30, "metrics that see it"). A model that is
//! right along the recorded path but wrong in 3D smears its moving objects seen from a
//! new viewpoint, which the whole-image PSNR hides behind the static background; and
//! regions no train view saw weigh on every model alike. Where the scene holds them
//! (`degs synth` writes both), each novel frame also gets the PSNR over
//! - the pixels a moving object covers in the ground truth (`gt/novel/object_NNNN.png`,
//!   the objects that move by `synth.json` and [`synth::ObjectSpec::moves`]);
//! - the co-visible pixels, those some train view saw (`gt/novel/covisible_NNNN.png`,
//!   [`synth::covis`]; the masked PSNR of Gao et al., NeurIPS 2022);
//! - the co-visible pixels no moving object covers: the still scene from elsewhere, so
//!   that a loss there is not taken for the objects' (or hidden by their gain).

use anyhow::{Result, bail};
use scene::evaluation::{MaskFigures, Trajectory};
use scene::image_io::{Image, read_image};
use std::path::Path;

/// Which values of a `gt/novel/object_NNNN.png` mark a moving object.
pub(crate) enum Moving {
    /// A `degs synth` scene: ids `k + 1` of the `objects[k]` that move by `synth.json`.
    Ids(Vec<u16>),
    /// Any other scene (an outside renderer's, `scripts/outside_scene.py`): every
    /// nonzero value.
    NonZero,
}

impl Moving {
    fn keeps(&self, v: u16) -> bool {
        match self {
            Moving::Ids(ids) => ids.contains(&v),
            Moving::NonZero => v != 0,
        }
    }
}

/// What marks a moving object in the scene's object images: the ids of the objects
/// that move by `synth.json` when the scene has one, else every nonzero value; an error
/// when `synth.json` exists but cannot be read (never a silently missing mask).
pub(crate) fn moving_ids(scene_dir: &Path) -> Result<Moving> {
    let path = scene_dir.join("synth.json");
    if !path.is_file() {
        return Ok(Moving::NonZero);
    }
    let text =
        std::fs::read_to_string(&path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let cfg: synth::SynthConfig = serde_json::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{}: not a synth settings file: {e}", path.display()))?;
    Ok(Moving::Ids(
        cfg.objects
            .iter()
            .enumerate()
            .filter(|(_, o)| o.moves())
            .map(|(k, _)| k as u16 + 1)
            .collect(),
    ))
}

/// The two masks of view `k` of a split (`test` or `novel`), each None where the scene
/// lacks it.
pub(crate) struct ViewMasks {
    /// The pixels a moving object covers (`gt/SPLIT/object_kkkk.png`).
    pub moving: Option<Vec<bool>>,
    /// The pixels some train view saw (`gt/SPLIT/covisible_kkkk.png`).
    pub covisible: Option<Vec<bool>>,
}

impl ViewMasks {
    /// `moving`: which object values move ([`moving_ids`]).
    pub fn read(scene_dir: &Path, split: &str, k: usize, moving: &Moving) -> Result<ViewMasks> {
        let mask_of = |name: &str, keep: &dyn Fn(u16) -> bool| -> Result<Option<Vec<bool>>> {
            let path = scene_dir.join(format!("gt/{split}/{name}_{k:04}.png"));
            if !path.is_file() {
                return Ok(None);
            }
            let (_, _, values) = synth::gt::read_object_png(&path)?;
            Ok(Some(values.iter().map(|&v| keep(v)).collect()))
        };
        Ok(ViewMasks {
            moving: mask_of("object", &|o| moving.keeps(o))?,
            covisible: mask_of("covisible", &|v| v != 0)?,
        })
    }
}

/// The pixels no moving object covers: the complement of a moving mask.
pub(crate) fn still_of(moving: &[bool]) -> Vec<bool> {
    moving.iter().map(|m| !m).collect()
}

/// A novel view and its render, read once, with their per-pixel SSIM map
/// ([`scene::metrics::ssim_map_u8`]), to score on any number of masks.
struct Pair {
    test: Image,
    render: Image,
    ssim: Vec<f64>,
}

impl Pair {
    fn read(test: &Path, render: &Path) -> Result<Pair> {
        let (a, b) = (read_image(test)?, read_image(render)?);
        if (b.width, b.height, b.channels) != (a.width, a.height, a.channels) {
            bail!(
                "{}: {}x{} does not match {} ({}x{})",
                render.display(),
                b.width,
                b.height,
                test.display(),
                a.width,
                a.height
            );
        }
        let (w, h, c) = (a.width as usize, a.height as usize, a.channels as usize);
        let planar = |img: &Image| scene::metrics::interleaved_to_planar(&img.data, w, h, c);
        let ssim = scene::metrics::ssim_map_u8(&planar(&a), &planar(&b), w, h);
        Ok(Pair {
            test: a,
            render: b,
            ssim,
        })
    }

    /// PSNR (dB, 8-bit levels, every channel, at most `cap`) and SSIM (the map's mean)
    /// over the pixels where `mask` holds; None when it holds nowhere.
    fn scores(&self, mask: &[bool], cap: f64) -> Result<Option<(f64, f64)>> {
        let (a, b) = (&self.test, &self.render);
        if mask.len() != self.ssim.len() {
            bail!(
                "a mask of {} pixels for {}x{} images",
                mask.len(),
                a.width,
                a.height
            );
        }
        let c = a.channels as usize;
        let level = |v: f32| f64::from((v.clamp(0.0, 1.0) * 255.0).round());
        let (mut sum, mut ssim, mut pixels) = (0.0, 0.0, 0usize);
        for (p, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
            for k in p * c..(p + 1) * c {
                sum += (level(a.data[k]) - level(b.data[k])).powi(2);
            }
            ssim += self.ssim[p];
            pixels += 1;
        }
        if pixels == 0 {
            return Ok(None);
        }
        let mse = sum / (pixels * c) as f64;
        let psnr = if mse == 0.0 {
            cap
        } else {
            (10.0 * (255.0f64.powi(2) / mse).log10()).min(cap)
        };
        Ok(Some((psnr, ssim / pixels as f64)))
    }
}

/// Mean relative depth error over `mask` (see [`MaskFigures::moving_depth_error`]).
pub(crate) fn depth_error(render: &Path, gt: &Path, mask: &[bool]) -> Result<Option<f64>> {
    let (w, h, d) = scene::image_io::read_exr_depth(render)?;
    let (gw, gh, g) = scene::image_io::read_exr_depth(gt)?;
    if (w, h) != (gw, gh) || g.len() != mask.len() {
        bail!(
            "{}: {w}x{h} does not match {} ({gw}x{gh})",
            render.display(),
            gt.display()
        );
    }
    let (mut sum, mut n) = (0.0, 0usize);
    for ((&m, &dg), &dr) in mask.iter().zip(&g).zip(&d) {
        if m && dg > 0.0 {
            let e = if dr > 0.0 && dr.is_finite() {
                f64::from((dr - dg).abs() / dg)
            } else {
                1.0
            };
            sum += e;
            n += 1;
        }
    }
    Ok((n > 0).then(|| sum / n as f64))
}

/// The masked figures of each `(ground truth, render)` pair of a split (`test`, `novel`),
/// in order (view k has `gt/SPLIT/*_kkkk.png`); a mask the scene lacks leaves its
/// figures None. `depth_dir`: where the render stage wrote the views' depth (`NAME.exr`
/// for render `NAME.png`).
pub(crate) fn split_masks(
    scene_dir: &Path,
    split: &str,
    pairs: &[(&Path, &Path)],
    depth_dir: Option<&Path>,
    cap: f64,
) -> Result<Vec<MaskFigures>> {
    let ids = moving_ids(scene_dir)?;
    let mut out = Vec::with_capacity(pairs.len());
    for (k, (test, render)) in pairs.iter().enumerate() {
        let ViewMasks { moving, covisible } = ViewMasks::read(scene_dir, split, k, &ids)?;
        let mut f = MaskFigures::default();
        if moving.is_none() && covisible.is_none() {
            out.push(f);
            continue;
        }
        let pair = Pair::read(test, render)?;
        let count = |m: &[bool]| m.iter().filter(|v| **v).count();
        if let Some(mask) = &moving {
            let s = pair.scores(mask, cap)?;
            (f.moving_pixels, f.moving_psnr, f.moving_ssim) =
                (Some(count(mask)), s.map(|s| s.0), s.map(|s| s.1));
            let gt_depth = scene_dir.join(format!("gt/{split}/depth_{k:04}.exr"));
            let depth = depth_dir
                .and_then(|d| Some(d.join(render.file_stem()?).with_extension("exr")))
                .filter(|d| d.is_file() && gt_depth.is_file());
            if let Some(d) = depth {
                f.moving_depth_error = depth_error(&d, &gt_depth, mask)?;
            }
            let still = still_of(mask);
            (f.still_pixels, f.still_psnr) =
                (Some(count(&still)), pair.scores(&still, cap)?.map(|s| s.0));
        }
        if let Some(mask) = &covisible {
            let s = pair.scores(mask, cap)?;
            (f.covisible_pixels, f.covisible_psnr, f.covisible_ssim) =
                (Some(count(mask)), s.map(|s| s.0), s.map(|s| s.1));
        }
        if let (Some(cov), Some(mov)) = (&covisible, &moving) {
            let still: Vec<bool> = cov.iter().zip(mov).map(|(&c, &m)| c && !m).collect();
            let s = pair.scores(&still, cap)?;
            (
                f.covisible_still_pixels,
                f.covisible_still_psnr,
                f.covisible_still_ssim,
            ) = (Some(count(&still)), s.map(|s| s.0), s.map(|s| s.1));
        }
        out.push(f);
    }
    Ok(out)
}

/// The `trajectory` of the report in stage entry `entry`; None when absent.
pub fn trajectory(entry: &Path) -> Option<Trajectory> {
    let bytes = std::fs::read(entry.join("report.json")).ok()?;
    let v: serde_json::Value = serde_json::from_slice(&bytes).ok()?;
    serde_json::from_value(v.get("trajectory")?.clone()).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An outside renderer's scene (no `synth.json`) marks moving objects by any nonzero
    /// value; a `synth.json` that does not parse is an error naming it.
    #[test]
    fn object_images_without_synth_settings_mark_every_nonzero_pixel() {
        let d = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(d.path().join("gt/novel")).unwrap();
        synth::gt::write_object_png(
            d.path().join("gt/novel/object_0000.png"),
            4,
            1,
            &[0, 255, 7, 0],
        )
        .unwrap();
        let moving = moving_ids(d.path()).unwrap();
        let masks = ViewMasks::read(d.path(), "novel", 0, &moving).unwrap();
        assert_eq!(masks.moving, Some(vec![false, true, true, false]));
        assert!(masks.covisible.is_none());
        assert!(
            ViewMasks::read(d.path(), "novel", 1, &moving)
                .unwrap()
                .moving
                .is_none()
        );
        assert!(
            ViewMasks::read(d.path(), "test", 0, &moving)
                .unwrap()
                .moving
                .is_none()
        );
        std::fs::write(d.path().join("synth.json"), "{ not json").unwrap();
        let e = moving_ids(d.path()).err().unwrap().to_string();
        assert!(e.contains("synth.json"), "{e}");
    }
}
