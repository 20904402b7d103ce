//! PSNR and SSIM of image files on 8-bit levels, and the pairing of held-out images
//! with a stage's renders.

use anyhow::{Result, bail};
use rayon::prelude::*;
use scene::evaluation::{FrameMetrics, PSNR_CAP};
use scene::image_io::{Image, read_image};
use std::path::{Path, PathBuf};

fn to_u8_levels(img: &Image) -> Vec<f32> {
    img.data
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round())
        .collect()
}

/// PSNR (dB) of two 8-bit images given as 0–255 levels; `f64::INFINITY` when equal.
/// The formula is `scene::metrics::psnr_u8`'s (levels ÷ 255 quantise back to the
/// same levels), so `degs eval` and the `gaussians` report agree.
pub fn psnr_u8(a: &[f32], b: &[f32]) -> f64 {
    let unit = |x: &[f32]| x.iter().map(|v| v / 255.0).collect::<Vec<f32>>();
    scene::metrics::psnr_u8(&unit(a), &unit(b))
}

/// Mean SSIM of interleaved images given as 0–255 levels: `scene::metrics::ssim_u8`
/// (11×11 Gaussian window, σ = 1.5, K1 = 0.01, K2 = 0.03, zero-padded windows averaged
/// over every pixel and channel, as the 3DGS/Deform-GS evaluation computes it), so
/// `degs eval` and the `gaussians` report give the same figure for the same renders.
pub fn ssim_u8(a: &[f32], b: &[f32], width: usize, height: usize, channels: usize) -> f64 {
    let planar = |x: &[f32]| {
        let unit: Vec<f32> = x.iter().map(|v| v / 255.0).collect();
        scene::metrics::interleaved_to_planar(&unit, width, height, channels)
    };
    scene::metrics::ssim_u8(&planar(a), &planar(b), width, height)
}

/// Compare two images (3 channels after reading) on 8-bit levels: (PSNR, SSIM).
pub(crate) fn compare_images(test: &Path, render: &Path) -> Result<(f64, f64)> {
    let a = read_image(test)?;
    let b = read_image(render)?;
    if (a.width, a.height, a.channels) != (b.width, b.height, b.channels) {
        bail!(
            "{}: {}x{}x{} but the test image {} is {}x{}x{}",
            render.display(),
            b.width,
            b.height,
            b.channels,
            test.display(),
            a.width,
            a.height,
            a.channels
        );
    }
    let (qa, qb) = (to_u8_levels(&a), to_u8_levels(&b));
    Ok((
        psnr_u8(&qa, &qb).min(PSNR_CAP),
        ssim_u8(
            &qa,
            &qb,
            a.width as usize,
            a.height as usize,
            a.channels as usize,
        ),
    ))
}

/// Image files of `dir`, sorted by name.
pub(crate) fn images_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            matches!(
                p.extension()
                    .and_then(|e| e.to_str())
                    .map(str::to_ascii_lowercase)
                    .as_deref(),
                Some("png" | "jpg" | "jpeg")
            )
        })
        .collect();
    v.sort();
    v
}

/// Pair each test frame with a render: same file stem when the stage kept the names,
/// else in order when the counts agree.
pub(crate) fn pair_renders(
    tests: &[PathBuf],
    renders: &[PathBuf],
) -> Result<Vec<(PathBuf, PathBuf)>> {
    let stem = |p: &Path| p.file_stem().map(|s| s.to_string_lossy().to_string());
    let by_stem: Vec<_> = tests
        .iter()
        .filter_map(|t| {
            renders
                .iter()
                .find(|r| stem(r) == stem(t))
                .map(|r| (t.clone(), r.clone()))
        })
        .collect();
    if by_stem.len() == tests.len() {
        return Ok(by_stem);
    }
    if renders.len() == tests.len() {
        return Ok(tests.iter().cloned().zip(renders.iter().cloned()).collect());
    }
    bail!(
        "{} test frames but {} renders, and their names do not match",
        tests.len(),
        renders.len()
    )
}

/// PSNR/SSIM of each (held-out image, render) pair.
pub(crate) fn score_pairs(pairs: &[(PathBuf, PathBuf)]) -> Result<Vec<FrameMetrics>> {
    pairs
        .par_iter()
        .map(|(t, r)| {
            let (psnr, ssim) = compare_images(t, r)?;
            Ok(FrameMetrics {
                test_image: t.clone(),
                render: r.clone(),
                psnr,
                ssim,
                lpips: None,
                masks: Default::default(),
            })
        })
        .collect()
}

#[cfg(test)]
#[path = "images_tests.rs"]
mod tests;
