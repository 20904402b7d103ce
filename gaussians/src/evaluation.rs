//! A model's renders scored against the frames of a split (`report.json`'s `test` and
//! `novel`): PSNR and SSIM on 8-bit images, and LPIPS (VGG16, as `degs eval` reports it)
//! when the weights are already cached. A stage never downloads them (`degs eval` does,
//! at first use); `DEGS_LPIPS=off` turns LPIPS off here as there. Without LPIPS the
//! evaluation says why (`lpips_note`).

use crate::model::Model;
use crate::train::View;
pub use lpips::Lpips;
use lpips::{Rgb, Variant};
use scene::error::{Error, Result};
use scene::image_io::{write_exr_depth, write_png};
use scene::metrics;
use serde::Serialize;
use std::path::Path;

/// PSNR / SSIM / LPIPS of renders against the frames of a split.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Evaluation {
    pub split: String,
    pub frames: usize,
    pub psnr_mean: f64,
    pub ssim_mean: f64,
    pub psnr: Vec<f64>,
    pub ssim: Vec<f64>,
    /// LPIPS (VGG16, lower is better) of each render against its frame, both as 8-bit
    /// images; absent when it was not computed (`lpips_note` says why).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lpips_mean: Option<f64>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub lpips: Vec<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lpips_note: Option<String>,
    /// PSNR of the mean colour of each target (a trivial baseline).
    pub mean_colour_psnr_mean: f64,
}

impl Evaluation {
    /// `PSNR 30.91 dB, SSIM 0.9623, LPIPS 0.0530` (LPIPS left out when there is none).
    pub fn figures(&self) -> String {
        let lpips = self
            .lpips_mean
            .map_or(String::new(), |l| format!(", LPIPS {l:.4}"));
        format!(
            "PSNR {:.2} dB, SSIM {:.4}{lpips}",
            self.psnr_mean, self.ssim_mean
        )
    }
}

/// PSNR of identical 8-bit images is reported as this (dB), so means and `report.json`
/// stay finite (JSON has no infinity: serde_json would write `null`); the same cap as
/// `degs eval`'s.
pub const PSNR_CAP: f64 = 100.0;

/// The network the reports use (`degs eval`'s).
const VARIANT: Variant = Variant::Vgg;

/// The LPIPS metric a stage scores with, or why there is none.
pub type StageLpips = std::result::Result<Lpips, String>;

/// [`StageLpips`], loaded once per stage: off by `DEGS_LPIPS=off`, else the cached
/// weights (`DEGS_LPIPS` = `fetch`, `cached` or unset).
pub fn stage_lpips() -> StageLpips {
    match std::env::var("DEGS_LPIPS").as_deref() {
        Ok("off") => Err("LPIPS off (DEGS_LPIPS=off)".into()),
        Err(_) | Ok("" | "fetch" | "cached") => Lpips::load_cached(VARIANT).map_err(|e| {
            format!("LPIPS not computed: {e} (`degs eval` downloads the weights at first use)")
        }),
        Ok(v) => Err(format!(
            "LPIPS not computed: DEGS_LPIPS={v} (expected fetch, cached or off)"
        )),
    }
}

/// LPIPS of two planar RGB images (`3 × h × w`, values in [0, 1]), each quantised to
/// 8 bits first as the PNGs `degs eval` scores are.
pub fn lpips_planar(m: &Lpips, a: &[f32], b: &[f32], width: usize, height: usize) -> Result<f64> {
    let n = width * height;
    let interleave = |p: &[f32]| -> Vec<f32> {
        (0..n * 3)
            .map(|k| (p[(k % 3) * n + k / 3].clamp(0.0, 1.0) * 255.0).round() / 255.0)
            .collect()
    };
    let (a, b) = (interleave(a), interleave(b));
    let rgb = |data| Rgb {
        data,
        width,
        height,
    };
    m.distance(rgb(&a), rgb(&b))
}

/// Render `model` at every view, write `renders/NNNN.png` (when `renders` is set) and
/// return PSNR (at most [`PSNR_CAP`]), SSIM and LPIPS (with `lpips`) against the views'
/// images.
pub fn evaluate(
    model: &Model,
    views: &[View],
    split: &str,
    renders: Option<&Path>,
    lpips: &StageLpips,
) -> Result<Evaluation> {
    evaluate_writing(model, views, split, renders.map(|r| (r, None)), lpips)
}

/// [`evaluate`], writing each render to `NNNN.png` in the first folder and, when given,
/// its depth (`stage::write_depths`' form) to `NNNN.exr` in the second, from one
/// render.
pub(crate) fn evaluate_writing(
    model: &Model,
    views: &[View],
    split: &str,
    out: Option<(&Path, Option<&Path>)>,
    lpips: &StageLpips,
) -> Result<Evaluation> {
    if let Some(depth) = out.and_then(|o| o.1) {
        std::fs::create_dir_all(depth).map_err(|e| Error::io(depth, e))?;
    }
    let mut ev = Evaluation {
        split: split.to_string(),
        frames: views.len(),
        ..Evaluation::default()
    };
    let mut note = match lpips {
        _ if views.is_empty() => Some("no frames".to_string()),
        Ok(_) => None,
        Err(e) => Some(e.clone()),
    };
    let mut base = Vec::new();
    for (i, v) in views.iter().enumerate() {
        let f = model.render(&v.camera, v.time);
        if let Some((dir, depth)) = out {
            write_png(dir.join(format!("{i:04}.png")), &f.rgb_image())?;
            if let Some(depth) = depth {
                let (w, h) = (f.width as u32, f.height as u32);
                write_exr_depth(
                    depth.join(format!("{i:04}.exr")),
                    w,
                    h,
                    &f.normalised_depth(),
                )?;
            }
        }
        ev.psnr.push(metrics::psnr_u8(&f.rgb, &v.rgb).min(PSNR_CAP));
        ev.ssim
            .push(metrics::ssim_u8(&f.rgb, &v.rgb, f.width, f.height));
        base.push(metrics::psnr_u8(&mean_colour(&v.rgb), &v.rgb).min(PSNR_CAP));
        if let (Ok(m), None) = (lpips, &note) {
            match lpips_planar(m, &f.rgb, &v.rgb, f.width, f.height) {
                Ok(d) => ev.lpips.push(d),
                Err(e) => note = Some(format!("LPIPS not computed: frame {i}: {e}")),
            }
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    ev.psnr_mean = mean(&ev.psnr);
    ev.ssim_mean = mean(&ev.ssim);
    ev.mean_colour_psnr_mean = mean(&base);
    match note {
        None => ev.lpips_mean = Some(mean(&ev.lpips)),
        Some(note) => {
            ev.lpips.clear();
            ev.lpips_note = Some(note);
        }
    }
    Ok(ev)
}

/// A planar image filled with each channel's mean.
fn mean_colour(rgb: &[f32]) -> Vec<f32> {
    let n = rgb.len() / 3;
    let mut out = Vec::with_capacity(rgb.len());
    for c in rgb.chunks(n.max(1)) {
        let m = c.iter().map(|&v| v as f64).sum::<f64>() / n.max(1) as f64;
        out.extend(std::iter::repeat_n(m as f32, c.len()));
    }
    out
}
