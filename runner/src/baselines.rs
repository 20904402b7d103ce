//! The block of 2D baselines `degs eval` prints beside a run's figures: what the nearest
//! train frame, the linear blend of the two neighbouring train frames and the two-sided
//! event pseudo image score on the test frames (the `evaluate` stage computes them).
//!
//! Each row: the whole image, the pixels a moving object covers and the others (the
//! still scene), where the scene has the moving objects' masks.
//!
//! They predict the recorded camera's image at a time; none can render a new
//! viewpoint, so the novel views have no baseline figures.

use scene::evaluation::{BaselineFigures, Score};

/// A model's mean figures on one split (PSNR, SSIM, LPIPS and the two over the moving
/// objects' pixels, those it has).
pub type Figures = Option<Score>;

/// The block `degs eval` prints under its table: the model's test-frame figures beside
/// the baselines', then its novel-view figures (with no baselines). `model` names the
/// stage whose renders were scored; `baselines` is the figures or why there are none.
pub(crate) fn format_block(
    model: &str,
    test: Figures,
    novel: Figures,
    baselines: Result<&BaselineFigures, &str>,
) -> String {
    let opt = |v: Option<f64>, w: usize, p: usize| {
        v.map_or(format!("{:>w$}", "-"), |v| format!("{v:>w$.p$}"))
    };
    let row = |label: &str, f: Figures| match f {
        Some(s) => format!(
            "  {label:<32} {:>8.2} {:>7.4} {} {} {} {} {}\n",
            s.psnr_mean,
            s.ssim_mean,
            opt(s.lpips_mean, 7, 4),
            opt(s.moving_psnr_mean, 9, 2),
            opt(s.moving_lpips_mean, 10, 4),
            opt(s.still_psnr_mean, 8, 2),
            opt(s.still_lpips_mean, 9, 4)
        ),
        None => format!("  {label:<32} {:>8} {:>7}\n", "-", "-"),
    };
    let of = |s: &Score| Some(*s);
    let head = |title: &str| {
        format!(
            "{title:<34} {:>8} {:>7} {:>7} {:>9} {:>10} {:>8} {:>9}\n",
            "PSNR dB", "SSIM", "LPIPS", "moving dB", "mov. LPIPS", "still dB", "st. LPIPS"
        )
    };
    let model = format!("model ({model} renders)");
    let mut out = head("test frames");
    out += &row(&model, test);
    match baselines {
        Ok(b) => {
            out += &row("nearest train frame", of(&b.nearest));
            out += &row("linear blend", of(&b.blend));
            match &b.events {
                Some(e) => out += &row("event pseudo image (two-sided)", of(e)),
                None => out += "  event pseudo image (two-sided)   - (the scene has no events)\n",
            }
            out += &format!("  2D baselines: {}\n", b.source);
        }
        Err(why) => out += &format!("  2D baselines: not available ({why})\n"),
    }
    if let Some(f) = novel {
        out += &head("novel views");
        out += &row(&model, Some(f));
        out += "  2D baselines: none (they cannot render a new viewpoint)\n";
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use scene::evaluation::COMPUTED;

    #[test]
    fn the_block_lists_the_model_beside_each_baseline() {
        let b = BaselineFigures {
            nearest: Score {
                psnr_mean: 20.5,
                ssim_mean: 0.6,
                lpips_mean: Some(0.25),
                moving_psnr_mean: Some(15.125),
                still_psnr_mean: Some(21.5),
                still_lpips_mean: Some(0.0625),
                ..Score::default()
            },
            blend: Score {
                psnr_mean: f64::INFINITY,
                ssim_mean: 1.0,
                ..Score::default()
            },
            events: None,
            source: COMPUTED.into(),
        }
        .capped(100.0);
        let fig = |psnr_mean, ssim_mean| Score {
            psnr_mean,
            ssim_mean,
            ..Score::default()
        };
        let text = format_block("deform", Some(fig(24.0, 0.8)), Some(fig(19.5, 0.7)), Ok(&b));
        let lines: Vec<&str> = text.lines().collect();
        let cols = |l: &str| l.split_whitespace().map(str::to_string).collect::<Vec<_>>();
        assert_eq!(
            cols(lines[1]),
            [
                "model", "(deform", "renders)", "24.00", "0.8000", "-", "-", "-", "-", "-"
            ]
        );
        assert_eq!(
            cols(lines[2])[3..],
            ["20.50", "0.6000", "0.2500", "15.12", "-", "21.50", "0.0625"]
        );
        assert_eq!(
            cols(lines[3])[2..],
            ["100.00", "1.0000", "-", "-", "-", "-", "-"]
        );
        assert!(lines[4].contains("no events"), "{text}");
        assert_eq!(lines[5], "  2D baselines: computed from the scene");
        assert!(lines[6].starts_with("novel views"), "{text}");
        assert_eq!(
            cols(lines[7])[3..],
            ["19.50", "0.7000", "-", "-", "-", "-", "-"]
        );
        assert!(lines[8].contains("cannot render a new viewpoint"), "{text}");
        let none = format_block("gaussians", None, None, Err("no test frames"));
        assert_eq!(
            none.lines().collect::<Vec<_>>()[1..],
            [
                "  model (gaussians renders)               -       -",
                "  2D baselines: not available (no test frames)"
            ]
        );
    }
}
