//! Novel-view PSNR on the pixels of moving objects (issue #30, "metrics that see it"): a
//! model that is right along the recorded path but wrong in 3D smears its moving
//! objects seen from a new viewpoint, which the whole-image PSNR hides behind the
//! static background. Where the scene holds object ids for its novel views
//! (`gt/novel/object_NNNN.png`, written by `degs synth`) and says which objects move
//! (`synth.json`, [`synth::ObjectSpec::moves`]), each novel frame also gets the PSNR
//! over the pixels a moving object covers in the ground truth.

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

/// A novel frame's score on its moving-object pixels: how many pixels, and their PSNR
/// (None when there are none).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MovingScore {
    pub pixels: usize,
    pub psnr: Option<f64>,
}

/// The moving-object score of each novel `(ground truth, render)` pair, in order (novel
/// view k has `gt/novel/object_kkkk.png`); empty where the scene lacks what it takes.
pub fn moving_scores(
    scene_dir: &Path,
    pairs: &[(&Path, &Path)],
    cap: f64,
) -> Result<Vec<MovingScore>> {
    let Some(ids) = moving_ids(scene_dir) else {
        return Ok(Vec::new());
    };
    let mut out = Vec::with_capacity(pairs.len());
    for (k, (test, render)) in pairs.iter().enumerate() {
        let path = scene_dir.join(format!("gt/novel/object_{k:04}.png"));
        if !path.is_file() {
            return Ok(Vec::new());
        }
        let (_, _, objects) = synth::gt::read_object_png(&path)?;
        let mask: Vec<bool> = objects.iter().map(|o| ids.contains(o)).collect();
        out.push(MovingScore {
            pixels: mask.iter().filter(|m| **m).count(),
            psnr: masked_psnr(test, render, &mask, cap)?,
        });
    }
    Ok(out)
}
