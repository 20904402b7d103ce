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
//! - `test_error_map.png`: one panel each for the model, the event pseudo image and the
//!   blend: every pixel's absolute error (mean of the channels) averaged over the test
//!   frames, ×8 (white: off by an eighth of the range on average). What one frame's
//!   difference cannot tell: the error that stays at the same place (a moving shadow's
//!   outline, a halo beside a moving object, a blurred background).

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

/// The columns set beside the test frames `gt`: the model's renders (`model`: pairs in
/// the frames' order, possibly none), then the event pseudo image and the blend of
/// `baselines`, those that have one image per frame.
fn columns<'a>(
    gt: &[PathBuf],
    model: &[(&'a Path, &'a Path)],
    baselines: &'a crate::baselines::BaselineImages,
) -> Vec<Vec<&'a Path>> {
    let of = |name: &str| baselines.iter().find(|(n, _)| *n == name).map(|(_, p)| p);
    [
        Some(model.iter().map(|p| p.1).collect()),
        of("events").map(|p| p.iter().map(PathBuf::as_path).collect()),
        of("blend").map(|p| p.iter().map(PathBuf::as_path).collect()),
    ]
    .into_iter()
    .flatten()
    .filter(|c: &Vec<&Path>| !c.is_empty() && c.len() == gt.len())
    .collect()
}

/// `test_sheet.png` and `test_error_map.png` in `dir` (module doc): the test frames `gt`
/// beside [`columns`], and where each column's error stays; None for both when there is
/// nothing to set beside the frames.
pub(crate) fn test_sheets(
    gt: &[PathBuf],
    model: &[(&Path, &Path)],
    baselines: &crate::baselines::BaselineImages,
    dir: &Path,
) -> Result<(Option<PathBuf>, Option<PathBuf>)> {
    let columns = columns(gt, model, baselines);
    if columns.is_empty() {
        return Ok((None, None));
    }
    let rows: Vec<(&Path, Vec<&Path>)> = gt
        .iter()
        .enumerate()
        .map(|(k, g)| (g.as_path(), columns.iter().map(|c| c[k]).collect()))
        .collect();
    write_sheet(&rows, &dir.join(TEST_SHEET))?;
    error_map(gt, &columns, &dir.join(TEST_ERROR_MAP))?;
    Ok((
        Some(PathBuf::from(TEST_SHEET)),
        Some(PathBuf::from(TEST_ERROR_MAP)),
    ))
}

/// Write the error map (module doc) of `columns` against `gt` to `out`.
fn error_map(gt: &[PathBuf], columns: &[Vec<&Path>], out: &Path) -> Result<()> {
    let maps = columns
        .iter()
        .map(|c| mean_abs_error(gt, c))
        .collect::<Result<Vec<_>>>()?;
    let (w, h) = (maps[0].width, maps[0].height);
    let z = 128u32.div_ceil(w.max(1)).max(1);
    let n = maps.len() as u32;
    let mut strip = Image::new(n * z * w + (n - 1) * GAP, z * h, 1);
    strip.data.iter_mut().for_each(|v| *v = 1.0);
    for (i, m) in maps.iter().enumerate() {
        for y in 0..z * h {
            for x in 0..z * w {
                let e = m.data[((y / z) * w + x / z) as usize];
                strip.data[(y * strip.width + i as u32 * (z * w + GAP) + x) as usize] =
                    (ERROR_GAIN * e).min(1.0);
            }
        }
    }
    write_png(out, &strip)?;
    Ok(())
}

/// The error map's gain: white is an average error of `1/ERROR_GAIN` of the range.
pub(crate) const ERROR_GAIN: f32 = 8.0;

/// The test frames' error map in the output directory.
pub(crate) const TEST_ERROR_MAP: &str = "test_error_map.png";

/// Each pixel's absolute error between `gt[k]` and `images[k]`, the mean of its
/// channels, averaged over the frames (one channel, 0–1).
pub(crate) fn mean_abs_error(gt: &[PathBuf], images: &[&Path]) -> Result<Image> {
    let mut sum: Option<Image> = None;
    for (g, p) in gt.iter().zip(images) {
        let (a, b) = (read_image(g)?, read_image(p)?);
        if (a.width, a.height) != (b.width, b.height) {
            bail!(
                "{}: {}x{}, and {} {}x{}",
                g.display(),
                a.width,
                a.height,
                p.display(),
                b.width,
                b.height
            );
        }
        let acc = sum.get_or_insert_with(|| Image::new(a.width, a.height, 1));
        if (acc.width, acc.height) != (a.width, a.height) {
            bail!(
                "{}: {}x{}, the first frame {}x{}",
                g.display(),
                a.width,
                a.height,
                acc.width,
                acc.height
            );
        }
        for (i, v) in acc.data.iter_mut().enumerate() {
            let (x, y) = (i as u32 % a.width, i as u32 / a.width);
            let (pa, pb) = (rgb(&a, x, y), rgb(&b, x, y));
            *v += (0..3).map(|c| (pa[c] - pb[c]).abs()).sum::<f32>() / 3.0;
        }
    }
    let mut m = sum.unwrap_or_else(|| Image::new(0, 0, 1));
    let n = gt.len().min(images.len()).max(1) as f32;
    m.data.iter_mut().for_each(|v| *v /= n);
    Ok(m)
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
