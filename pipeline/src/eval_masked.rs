//! Novel-view PSNR on two masks (issue #30, "metrics that see it"). A model that is
//! right along the recorded path but wrong in 3D smears its moving objects seen from a
//! new viewpoint, which the whole-image PSNR hides behind the static background; and
//! regions no train view saw weigh on every model alike. Where the scene holds them
//! (`degs synth` writes both), each novel frame also gets the PSNR over
//! - the pixels a moving object covers in the ground truth (`gt/novel/object_NNNN.png`,
//!   the objects that move by `synth.json` and [`synth::ObjectSpec::moves`]);
//! - the co-visible pixels, those some train view saw (`gt/novel/covisible_NNNN.png`,
//!   [`synth::covis`]; the masked PSNR of Gao et al., NeurIPS 2022).

use anyhow::{Result, bail};
use scene::image_io::read_image;
use std::path::Path;

/// Object ids (`k + 1` for `objects[k]`) of the objects that move; None when the scene
/// does not say (no `synth.json`: a recording).
pub fn moving_ids(scene_dir: &Path) -> Option<Vec<u16>> {
    let text = std::fs::read_to_string(scene_dir.join("synth.json")).ok()?;
    let cfg: synth::SynthConfig = serde_json::from_str(&text).ok()?;
    Some(
        cfg.objects
            .iter()
            .enumerate()
            .filter(|(_, o)| o.moves())
            .map(|(k, _)| k as u16 + 1)
            .collect(),
    )
}

/// PSNR (dB, 8-bit levels, every channel, at most `cap`) of `render` against `test`
/// over the pixels where `mask` holds; None when it holds nowhere.
pub fn masked_psnr(test: &Path, render: &Path, mask: &[bool], cap: f64) -> Result<Option<f64>> {
    let (a, b) = (read_image(test)?, read_image(render)?);
    let n = (a.width * a.height) as usize;
    if (b.width, b.height, b.channels) != (a.width, a.height, a.channels) || mask.len() != n {
        bail!(
            "{}: {}x{} does not match {} ({}x{}, mask of {} pixels)",
            render.display(),
            b.width,
            b.height,
            test.display(),
            a.width,
            a.height,
            mask.len()
        );
    }
    let c = a.channels as usize;
    let level = |v: f32| f64::from((v.clamp(0.0, 1.0) * 255.0).round());
    let (mut sum, mut count) = (0.0, 0usize);
    for (p, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
        for k in p * c..(p + 1) * c {
            sum += (level(a.data[k]) - level(b.data[k])).powi(2);
        }
        count += c;
    }
    Ok((count > 0).then(|| {
        let mse = sum / count as f64;
        if mse == 0.0 {
            cap
        } else {
            (10.0 * (255.0f64.powi(2) / mse).log10()).min(cap)
        }
    }))
}

/// A novel frame's score on one mask: how many pixels it holds, and their PSNR (None
/// when it holds none).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaskScore {
    pub pixels: usize,
    pub psnr: Option<f64>,
}

/// Each novel frame's scores on its moving-object and co-visible pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NovelMasks {
    pub moving: Option<MaskScore>,
    pub covisible: Option<MaskScore>,
}

/// The masked scores of each novel `(ground truth, render)` pair, in order (novel view k
/// has `gt/novel/*_kkkk.png`); a mask the scene lacks is None.
pub fn novel_masks(
    scene_dir: &Path,
    pairs: &[(&Path, &Path)],
    cap: f64,
) -> Result<Vec<NovelMasks>> {
    let ids = moving_ids(scene_dir);
    let mut out = Vec::with_capacity(pairs.len());
    for (k, (test, render)) in pairs.iter().enumerate() {
        let score = |name: &str, keep: &dyn Fn(u16) -> bool| -> Result<Option<MaskScore>> {
            let path = scene_dir.join(format!("gt/novel/{name}_{k:04}.png"));
            if !path.is_file() {
                return Ok(None);
            }
            let (_, _, values) = synth::gt::read_object_png(&path)?;
            let mask: Vec<bool> = values.iter().map(|&v| keep(v)).collect();
            Ok(Some(MaskScore {
                pixels: mask.iter().filter(|m| **m).count(),
                psnr: masked_psnr(test, render, &mask, cap)?,
            }))
        };
        let moving = match &ids {
            Some(ids) => score("object", &|o| ids.contains(&o))?,
            None => None,
        };
        out.push(NovelMasks {
            moving,
            covisible: score("covisible", &|v| v != 0)?,
        });
    }
    Ok(out)
}
