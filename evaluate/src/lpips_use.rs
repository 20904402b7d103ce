//! LPIPS (VGG16, as the paper reports) in the evaluation: per held-out image beside PSNR
//! and SSIM, when the weights can be had (`lpips` crate: fetched and converted at first
//! use). The setting `lpips` = `fetch` (default: download at first use), `cached` (only
//! weights already in the cache) or `off`; `degs eval` sets it from `DEGS_LPIPS`.

use anyhow::{Context, Result};
use lpips::{Lpips, Rgb, Variant};
use scene::image_io::{Image, read_image};
use std::path::Path;

/// The network the evaluation reports.
pub(crate) const EVAL_VARIANT: Variant = Variant::Vgg;

/// How the evaluation gets the LPIPS weights.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LpipsUse {
    Off,
    Cached,
    #[default]
    Fetch,
}

/// The metric, or why there is none.
pub fn metric(how: LpipsUse) -> std::result::Result<Lpips, String> {
    let loaded = match how {
        LpipsUse::Off => return Err("LPIPS off (DEGS_LPIPS=off)".into()),
        LpipsUse::Cached => Lpips::load_cached(EVAL_VARIANT),
        LpipsUse::Fetch => Lpips::load(EVAL_VARIANT),
    };
    loaded.map_err(|e| format!("LPIPS unavailable: {e}"))
}

fn rgb(img: &Image) -> Vec<f32> {
    let c = img.channels as usize;
    img.data
        .chunks_exact(c)
        .flat_map(|p| {
            let g = |k: usize| p[k.min(c - 1)].clamp(0.0, 1.0);
            [g(0), g(1), g(2)]
        })
        .collect()
}

/// LPIPS and its spatial map of two image files (the first three channels; grey images
/// repeated).
pub(crate) fn scored_files(m: &Lpips, test: &Path, render: &Path) -> Result<lpips::Scored> {
    let (a, b) = (read_image(test)?, read_image(render)?);
    let (ra, rb) = (rgb(&a), rgb(&b));
    let d = m.distance_and_map(
        Rgb {
            data: &ra,
            width: a.width as usize,
            height: a.height as usize,
        },
        Rgb {
            data: &rb,
            width: b.width as usize,
            height: b.height as usize,
        },
    );
    d.with_context(|| format!("LPIPS of {} against {}", render.display(), test.display()))
}

/// LPIPS (and its map) of every (held-out image, render) pair of each set, and the
/// network's name;
/// `Err` says why there are none (no weights, or a pair that cannot be scored).
pub(crate) fn score_sets(
    sets: &[Vec<(&Path, &Path)>],
    how: LpipsUse,
) -> std::result::Result<(String, Vec<Vec<lpips::Scored>>), String> {
    let m = metric(how)?;
    let scores: Result<Vec<Vec<lpips::Scored>>> = sets
        .iter()
        .map(|set| set.iter().map(|(t, r)| scored_files(&m, t, r)).collect())
        .collect();
    let scores = scores.map_err(|e| format!("LPIPS not computed: {e:#}"))?;
    Ok((EVAL_VARIANT.name().to_string(), scores))
}

/// The mean of values that are all present (None when any is missing, or none).
pub(crate) fn mean_all(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let v: Option<Vec<f64>> = values.collect();
    v.filter(|v| !v.is_empty())
        .map(|v| v.iter().sum::<f64>() / v.len() as f64)
}
