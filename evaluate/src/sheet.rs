//! The novel views at a glance (issue #30, "look at it"): `novel_sheet.png` in the run
//! directory, one row per novel view: the ground truth, the render, and their absolute
//! difference ×4 (white: wrong by a quarter of the range or more), with a gap of
//! white between the panels. Smeared moving objects show as streaks in the render and
//! bright trails in the difference. Views narrower than 128 px are enlarged by a whole
//! factor (nearest pixel) so that a person can see them.

use anyhow::{Result, bail};
use scene::image_io::{Image, read_image, write_png};
use std::path::{Path, PathBuf};

/// Pixels of white between panels and rows.
const GAP: u32 = 2;

/// Write the sheet of `pairs` (ground truth, render) to `out`; None when there are no
/// pairs.
pub(crate) fn write_sheet(pairs: &[(&Path, &Path)], out: &Path) -> Result<Option<PathBuf>> {
    let Some(&(first, _)) = pairs.first() else {
        return Ok(None);
    };
    let probe = read_image(first)?;
    let (w, h) = (probe.width, probe.height);
    let z = 128u32.div_ceil(w.max(1)).max(1); // enlargement
    let n = pairs.len() as u32;
    let mut sheet = Image::new(3 * z * w + 2 * GAP, n * z * h + (n - 1) * GAP, 3);
    sheet.data.iter_mut().for_each(|v| *v = 1.0);
    for (row, (gt, render)) in pairs.iter().enumerate() {
        let (a, b) = (read_image(gt)?, read_image(render)?);
        if (a.width, a.height, b.width, b.height) != (w, h, w, h) {
            bail!(
                "{}: {}x{}, and its render {}x{}; the sheet's views are {w}x{h}",
                gt.display(),
                a.width,
                a.height,
                b.width,
                b.height
            );
        }
        let y0 = row as u32 * (z * h + GAP);
        for y in 0..z * h {
            for x in 0..z * w {
                let (pa, pb) = (rgb(&a, x / z, y / z), rgb(&b, x / z, y / z));
                let diff = std::array::from_fn(|c| ((pa[c] - pb[c]).abs() * 4.0).min(1.0));
                for (panel, px) in [pa, pb, diff].into_iter().enumerate() {
                    let sx = panel as u32 * (z * w + GAP) + x;
                    let o = (((y0 + y) * sheet.width + sx) * 3) as usize;
                    sheet.data[o..o + 3].copy_from_slice(&px);
                }
            }
        }
    }
    write_png(out, &sheet)?;
    Ok(Some(out.to_path_buf()))
}

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
