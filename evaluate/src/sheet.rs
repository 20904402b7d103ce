//! Held-out frames at a glance (issues #30 and #32, "look at it"), with a gap of white
//! between panels and rows; views narrower than 128 px are enlarged by a whole factor
//! (nearest pixel) so that a person can see them.
//! - `novel_sheet.png`: one row per novel view: the ground truth, the render, and their
//!   absolute difference ×4 (white: wrong by a quarter of the range or more). Smeared
//!   moving objects show as streaks in the render and bright trails in the difference.
//! - `test_sheet.png`: one row per test frame (an in-between time): the ground truth,
//!   then the model's render, the two-sided event pseudo image and the linear blend
//!   (those that exist), each followed by its difference ×4: where the model is softer
//!   or wronger than what the events alone give.

use anyhow::{Result, bail};
use scene::image_io::{Image, read_image, write_png};
use std::path::{Path, PathBuf};

/// Pixels of white between panels and rows.
const GAP: u32 = 2;

/// Write a sheet to `out`: per row the ground truth and, for each other image, that
/// image and its difference ×4; None when there are no rows.
pub(crate) fn write_sheet(rows: &[(&Path, Vec<&Path>)], out: &Path) -> Result<Option<PathBuf>> {
    let Some((first, others)) = rows.first() else {
        return Ok(None);
    };
    let probe = read_image(first)?;
    let (w, h) = (probe.width, probe.height);
    let z = 128u32.div_ceil(w.max(1)).max(1); // enlargement
    let (n, panels) = (rows.len() as u32, 1 + 2 * others.len() as u32);
    let mut sheet = Image::new(
        panels * z * w + (panels - 1) * GAP,
        n * z * h + (n - 1) * GAP,
        3,
    );
    sheet.data.iter_mut().for_each(|v| *v = 1.0);
    for (row, (gt, images)) in rows.iter().enumerate() {
        let a = read_image(gt)?;
        let mut imgs = Vec::with_capacity(images.len());
        for p in images {
            let b = read_image(p)?;
            if (a.width, a.height, b.width, b.height) != (w, h, w, h) {
                bail!(
                    "{}: {}x{}, and {} {}x{}; the sheet's views are {w}x{h}",
                    gt.display(),
                    a.width,
                    a.height,
                    p.display(),
                    b.width,
                    b.height
                );
            }
            imgs.push(b);
        }
        let y0 = row as u32 * (z * h + GAP);
        for y in 0..z * h {
            for x in 0..z * w {
                let pa = rgb(&a, x / z, y / z);
                let mut put = |panel: u32, px: [f32; 3]| {
                    let sx = panel * (z * w + GAP) + x;
                    let o = (((y0 + y) * sheet.width + sx) * 3) as usize;
                    sheet.data[o..o + 3].copy_from_slice(&px);
                };
                put(0, pa);
                for (i, b) in imgs.iter().enumerate() {
                    let pb = rgb(b, x / z, y / z);
                    let diff = std::array::from_fn(|c| ((pa[c] - pb[c]).abs() * 4.0).min(1.0));
                    put(1 + 2 * i as u32, pb);
                    put(2 + 2 * i as u32, diff);
                }
            }
        }
    }
    write_png(out, &sheet)?;
    Ok(Some(out.to_path_buf()))
}

/// `test_sheet.png` in `dir` (module doc): the test frames `gt`, the model's renders
/// (`model`: pairs in the frames' order, possibly none) and the event pseudo image and
/// blend of `baselines`; None when there is nothing to set beside the frames.
pub(crate) fn test_sheet(
    gt: &[PathBuf],
    model: &[(&Path, &Path)],
    baselines: &crate::baselines::BaselineImages,
    dir: &Path,
) -> Result<Option<PathBuf>> {
    let of = |name: &str| baselines.iter().find(|(n, _)| *n == name).map(|(_, p)| p);
    let columns: Vec<Vec<&Path>> = [
        Some(model.iter().map(|p| p.1).collect()),
        of("events").map(|p| p.iter().map(PathBuf::as_path).collect()),
        of("blend").map(|p| p.iter().map(PathBuf::as_path).collect()),
    ]
    .into_iter()
    .flatten()
    .filter(|c: &Vec<&Path>| c.len() == gt.len())
    .collect();
    if columns.is_empty() {
        return Ok(None);
    }
    let rows: Vec<(&Path, Vec<&Path>)> = gt
        .iter()
        .enumerate()
        .map(|(k, g)| (g.as_path(), columns.iter().map(|c| c[k]).collect()))
        .collect();
    write_sheet(&rows, &dir.join(TEST_SHEET))?;
    Ok(Some(PathBuf::from(TEST_SHEET)))
}

/// The test frames' sheet in the output directory.
pub(crate) const TEST_SHEET: &str = "test_sheet.png";

/// Pixel `(x, y)` of `img` as RGB (grey repeated).
fn rgb(img: &Image, x: u32, y: u32) -> [f32; 3] {
    let c = img.channels as usize;
    let o = ((y * img.width + x) as usize) * c;
    if c >= 3 {
        [img.data[o], img.data[o + 1], img.data[o + 2]]
    } else {
        [img.data[o]; 3]
    }
}
