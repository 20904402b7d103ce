//! The chart images (plotters): one scatter chart per question and scene, as PNG
//! (bitmap backend, text drawn with the bundled DejaVu Sans) and SVG.

use super::legend::{draw_legend, polyline_anchors};
use super::{ChartData, Method, ModelPoint, pareto_front};
use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// The font every chart's text is drawn with (DejaVu Sans, its licence in
/// `charts/fonts/LICENSE-DejaVu.txt`): plotters' ab_glyph text needs one registered,
/// and a bundled one does not depend on the machine's fonts.
static FONT: &[u8] = include_bytes!("../fonts/DejaVuSans.ttf");

/// Pixel size of the PNG charts.
pub const SIZE: (u32, u32) = (960, 640);
/// The same with the channel count, as the PNG reads back.
pub const SIZE_RGB: (u32, u32, u32) = (SIZE.0, SIZE.1, 3);

pub(crate) fn register_font() -> Result<()> {
    static DONE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, FONT).is_ok()
    });
    ok.then_some(())
        .ok_or_else(|| anyhow!("the bundled chart font does not load"))
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Marker {
    Circle,
    Triangle,
    Cross,
}

/// One group of points, drawn alike; each point with its label.
struct Series {
    label: String,
    color: RGBColor,
    marker: Marker,
    points: Vec<(f64, f64, String)>,
}

/// What one chart shows.
struct Spec {
    title: String,
    x_label: String,
    y_label: String,
    series: Vec<Series>,
    /// Horizontal reference lines (label with its value, y).
    lines: Vec<(String, f64)>,
    /// Plot x on a log10 axis (ticks still in x's units).
    log_x: bool,
    /// The front minimises y (an error) instead of maximising it.
    lower_is_better: bool,
}

/// Colours of the 2D baselines' dashed lines.
pub const LINE_COLOURS: [RGBColor; 3] = [
    RGBColor(120, 120, 120),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
];

/// The colour and marker of a method's points.
pub fn method_style(m: Method) -> (RGBColor, Marker) {
    match m {
        Method::Degs => (RGBColor(214, 39, 40), Marker::Circle),
        Method::RgbJoint => (RGBColor(255, 127, 14), Marker::Cross),
        Method::RgbWarmup => (RGBColor(31, 119, 180), Marker::Triangle),
    }
}

/// Short labels for experiment names `<sweep>_<key>-<value>_…`: the `_`-separated
/// parts that differ between them (a lone name stays whole), at most 40 characters.
fn short_labels(names: &[&str]) -> Vec<String> {
    let parts: Vec<Vec<&str>> = names.iter().map(|n| n.split('_').collect()).collect();
    let same_shape = parts.iter().all(|p| p.len() == parts[0].len());
    names
        .iter()
        .zip(&parts)
        .map(|(name, p)| {
            let label = if names.len() < 2 || !same_shape {
                name.to_string()
            } else {
                let differing: Vec<&str> = (0..p.len())
                    .filter(|&i| parts.iter().any(|q| q[i] != p[i]))
                    .map(|i| p[i])
                    .collect();
                if differing.is_empty() {
                    name.to_string()
                } else {
                    differing.join(" ")
                }
            };
            match label.char_indices().nth(40) {
                Some((at, _)) => format!("{}…", &label[..at]),
                None => label,
            }
        })
        .collect()
}

fn first_name(experiments: &[String]) -> &str {
    experiments.first().map(String::as_str).unwrap_or("")
}

/// Model points of one scene as series by method, x from `x_of` and y from `y_of`
/// (points without either left out).
fn model_series(points: &[&ModelPoint], x_of: &XOf, y_of: &XOf) -> Vec<Series> {
    let names: Vec<&str> = points.iter().map(|p| first_name(&p.experiments)).collect();
    let labels = short_labels(&names);
    let mut out: Vec<Series> = Vec::new();
    for m in [Method::RgbWarmup, Method::RgbJoint, Method::Degs] {
        let (color, marker) = method_style(m);
        let pts: Vec<(f64, f64, String)> = points
            .iter()
            .zip(&labels)
            .filter(|(p, _)| p.method == m)
            .filter_map(|(p, l)| {
                let tag = match (p.stage.as_str(), p.experiments.len()) {
                    ("gaussians", 1) => format!("{l} (warm-up)"),
                    ("gaussians", n) => {
                        // the parts of the label every experiment sharing it has
                        let shared: Vec<&str> = l
                            .split(' ')
                            .filter(|part| {
                                p.experiments
                                    .iter()
                                    .all(|e| e.split('_').any(|q| q == *part))
                            })
                            .collect();
                        format!("{} warm-up (shared by {n})", shared.join(" "))
                            .trim_start()
                            .to_string()
                    }
                    _ => l.clone(),
                };
                Some((x_of(p)?, y_of(p)?, tag))
            })
            .collect();
        if !pts.is_empty() {
            out.push(Series {
                label: m.label().into(),
                color,
                marker,
                points: pts,
            });
        }
    }
    out
}

/// The x of a model point on a chart (None: not on that chart).
type XOf = dyn Fn(&ModelPoint) -> Option<f64>;

/// Write every chart of `data` into `out`; the files written.
pub(crate) fn draw_all(data: &ChartData, out: &Path) -> Result<Vec<PathBuf>> {
    let mut scenes: Vec<&str> = data.models.iter().map(|p| p.scene.as_str()).collect();
    scenes.extend(data.flows.iter().map(|p| p.scene.as_str()));
    scenes.sort();
    scenes.dedup();
    let mut written = Vec::new();
    for scene in scenes {
        let models: Vec<&ModelPoint> = data.models.iter().filter(|p| p.scene == scene).collect();
        let baselines = data.baselines.iter().filter(|b| b.scene == scene);
        let psnr_lines: Vec<(String, f64)> = baselines
            .clone()
            .map(|b| (format!("{} ({:.2} dB)", b.name, b.psnr), b.psnr))
            .collect();
        let lpips_lines: Vec<(String, f64)> = baselines
            .filter_map(|b| Some((format!("{} ({:.4})", b.name, b.lpips?), b.lpips?)))
            .collect();
        let time = "total wall time of the stages, cached ones at their build cost (s)";
        let psnr: &XOf = &|p| Some(p.psnr);
        let lpips: &XOf = &|p| p.lpips;
        let charts: [(&str, String, &XOf, &XOf); 4] = [
            ("psnr-vs-time", time.into(), &|p| Some(p.total_s), psnr),
            (
                "psnr-vs-size",
                "model files on disk (MiB)".into(),
                &|p| Some(p.model_bytes as f64 / (1 << 20) as f64),
                psnr,
            ),
            (
                "psnr-vs-gaussians",
                "Gaussians".into(),
                &|p| p.gaussians.map(|g| g as f64),
                psnr,
            ),
            ("lpips-vs-time", time.into(), &|p| Some(p.total_s), lpips),
        ];
        for (file, x_label, x_of, y_of) in charts {
            let series = model_series(&models, x_of, y_of);
            if series.is_empty() {
                continue;
            }
            let question = match file {
                "psnr-vs-time" => "accuracy against time",
                "psnr-vs-size" => "accuracy against model size",
                "lpips-vs-time" => "perceptual error against time",
                _ => "accuracy against Gaussian count",
            };
            let is_lpips = file.starts_with("lpips");
            let spec = Spec {
                title: format!("{scene}: {question}"),
                x_label,
                y_label: if is_lpips {
                    "test LPIPS (VGG; lower is better)".into()
                } else {
                    "test PSNR (dB)".into()
                },
                log_x: spread(&series) > 20.0,
                series,
                lines: if is_lpips { &lpips_lines } else { &psnr_lines }.clone(),
                lower_is_better: is_lpips,
            };
            written.extend(write_both(&spec, &out.join(format!("{scene}-{file}")))?);
        }
        let scene_flows: Vec<_> = data.flows.iter().filter(|f| f.scene == scene).collect();
        let names: Vec<&str> = scene_flows
            .iter()
            .map(|f| first_name(&f.experiments))
            .collect();
        let flows: Vec<(f64, f64, String)> = scene_flows
            .iter()
            .zip(short_labels(&names))
            .map(|(f, l)| {
                let tag = match (&f.mode, f.experiments.len()) {
                    (Some(m), 1) => format!("{l} ({m})"),
                    (Some(m), n) => format!("{m}, shared by {n}"),
                    (None, _) => l,
                };
                (f.locm_s, f.epe_px_s, tag)
            })
            .collect();
        if !flows.is_empty() {
            let spec = Spec {
                title: format!("{scene}: flow error against LoCM time"),
                x_label: "LoCM fine-tuning time (s)".into(),
                y_label: "per-event flow EPE vs ground truth (px/s)".into(),
                series: vec![Series {
                    label: "evflow (LoCM)".into(),
                    color: RGBColor(214, 39, 40),
                    marker: Marker::Circle,
                    points: flows,
                }],
                lines: Vec::new(),
                log_x: false,
                lower_is_better: true,
            };
            written.extend(write_both(
                &spec,
                &out.join(format!("{scene}-epe-vs-locm")),
            )?);
        }
    }
    Ok(written)
}

/// max x ÷ min x over the points (1 when any x is not positive).
fn spread(series: &[Series]) -> f64 {
    let xs = series.iter().flat_map(|s| s.points.iter().map(|p| p.0));
    let (lo, hi) = xs.fold((f64::INFINITY, 0f64), |(lo, hi), x| (lo.min(x), hi.max(x)));
    if lo > 0.0 { hi / lo } else { 1.0 }
}

/// A chart that can draw itself on any plotters backend.
pub trait Drawing {
    fn draw_on<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>;
}

impl Drawing for Spec {
    fn draw_on<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        draw(root, self)
    }
}

/// `<stem>.png` and `<stem>.svg`.
fn write_both(spec: &Spec, stem: &Path) -> Result<Vec<PathBuf>> {
    write_png_and_svg(spec, stem)
}

/// Draw `chart` to `<stem>.png` ([`SIZE`], the bundled font) and `<stem>.svg`.
pub fn write_png_and_svg(chart: &impl Drawing, stem: &Path) -> Result<Vec<PathBuf>> {
    register_font()?;
    let png = stem.with_extension("png");
    let (w, h) = SIZE;
    let mut buf = vec![255u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area();
        chart
            .draw_on(&root)
            .map_err(|e| anyhow!("{}: {e}", png.display()))?;
        root.present()
            .map_err(|e| anyhow!("{}: {e:?}", png.display()))?;
    }
    let img = scene::image_io::Image {
        width: w,
        height: h,
        channels: 3,
        data: buf.iter().map(|&b| b as f32 / 255.0).collect(),
    };
    scene::image_io::write_png(&png, &img)?;
    let svg = stem.with_extension("svg");
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, SIZE).into_drawing_area();
        chart
            .draw_on(&root)
            .map_err(|e| anyhow!("{}: {e}", svg.display()))?;
        root.present()
            .map_err(|e| anyhow!("{}: {e:?}", svg.display()))?;
    }
    scene::atomic::write_bytes_atomic(&svg, text.as_bytes())?;
    Ok(vec![png, svg])
}

/// A tick value in plain notation with few digits.
fn tick(v: f64) -> String {
    let a = v.abs();
    if a >= 1000.0 || a == 0.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else if a >= 0.1 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

/// A tick value on a linear axis spanning `span`: enough decimals to tell the
/// ticks (about ten of them) apart.
pub fn linear_tick(v: f64, span: f64) -> String {
    let decimals = (1.0 - span.max(1e-12).log10()).ceil().clamp(0.0, 6.0) as usize;
    format!("{v:.decimals$}")
}

/// On an axis of a non-negative cost (time, bytes, count) the range spans at least
/// this fraction of its largest value, so that runs a fraction of a percent apart
/// (one warm-up shared by a sweep: model sizes a few KB apart in 1.4 MB) are drawn
/// close together, not across the whole chart.
const MIN_RELATIVE_SPAN: f64 = 0.1;

/// Padded range of `values` (a unit either side when they are all equal).
pub fn range(values: impl Iterator<Item = f64>, pad: f64, clamp_at_zero: bool) -> (f64, f64) {
    let (mut lo, mut hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let min_span = MIN_RELATIVE_SPAN * hi;
    if clamp_at_zero && lo >= 0.0 && hi > lo && hi - lo < min_span {
        let centre = 0.5 * (lo + hi);
        (lo, hi) = (centre - 0.5 * min_span, centre + 0.5 * min_span);
    }
    let span = if hi > lo {
        hi - lo
    } else if lo != 0.0 {
        2.0 * lo.abs()
    } else {
        1.0
    };
    // values that cannot be negative (times, sizes, counts) keep a non-negative axis
    let low = if clamp_at_zero && lo >= 0.0 {
        (lo - pad * span).max(0.0)
    } else {
        lo - pad * span
    };
    (low, hi + pad * span)
}

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, spec: &Spec) -> Result<(), String> {
    let err = |e: &dyn std::fmt::Debug| format!("{e:?}");
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let tx = |x: f64| if spec.log_x { x.max(1e-9).log10() } else { x };
    let all = || spec.series.iter().flat_map(|s| s.points.iter());
    let (x0, x1) = range(all().map(|p| tx(p.0)), 0.08, !spec.log_x);
    let (y0, y1) = range(
        all().map(|p| p.1).chain(spec.lines.iter().map(|l| l.1)),
        0.12,
        true,
    );
    let mut chart = ChartBuilder::on(root)
        .caption(&spec.title, ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(56)
        .y_label_area_size(72)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| err(&e))?;
    let log = spec.log_x;
    chart
        .configure_mesh()
        .x_desc(&spec.x_label)
        .y_desc(&spec.y_label)
        .axis_desc_style(("sans-serif", 18))
        .label_style(("sans-serif", 15))
        .x_label_formatter(&|v| {
            if log {
                tick(10f64.powf(*v))
            } else {
                linear_tick(*v, x1 - x0)
            }
        })
        .y_label_formatter(&|v| linear_tick(*v, y1 - y0))
        .light_line_style(RGBColor(246, 246, 246))
        .draw()
        .map_err(|e| err(&e))?;
    let mut labels = Vec::new();
    let mut lines_drawn = Vec::new();
    for (i, (label, y)) in spec.lines.iter().enumerate() {
        let c = LINE_COLOURS[i % LINE_COLOURS.len()];
        labels.push(format!("2D baseline: {label}"));
        lines_drawn.extend(polyline_anchors(&[
            chart.backend_coord(&(x0, *y)),
            chart.backend_coord(&(x1, *y)),
        ]));
        chart
            .draw_series(DashedLineSeries::new(
                [(x0, *y), (x1, *y)],
                8,
                5,
                c.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label(labels.last().cloned().unwrap_or_default())
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 24, y)], c.stroke_width(2)));
    }
    // the Pareto front over every series
    let pts: Vec<(f64, f64, &str)> = all().map(|p| (tx(p.0), p.1, p.2.as_str())).collect();
    let sign = if spec.lower_is_better { -1.0 } else { 1.0 };
    let front = pareto_front(&pts.iter().map(|p| (p.0, sign * p.1)).collect::<Vec<_>>());
    if front.len() > 1 {
        let line: Vec<(f64, f64)> = front.iter().map(|&i| (pts[i].0, pts[i].1)).collect();
        let pixels: Vec<(i32, i32)> = line.iter().map(|p| chart.backend_coord(p)).collect();
        lines_drawn.extend(polyline_anchors(&pixels));
        labels.push("Pareto front".to_string());
        chart
            .draw_series(LineSeries::new(line, BLACK.stroke_width(1)))
            .map_err(|e| err(&e))?
            .label("Pareto front")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 24, y)], BLACK));
    }
    for s in &spec.series {
        labels.push(s.label.clone());
        let (c, style) = (s.color, s.color.filled());
        let coords = s.points.iter().map(|p| (tx(p.0), p.1));
        match s.marker {
            Marker::Circle => chart
                .draw_series(coords.map(|xy| Circle::new(xy, 7, style)))
                .map_err(|e| err(&e))?
                .label(&s.label)
                .legend(move |(x, y)| Circle::new((x + 12, y), 6, style)),
            Marker::Triangle => chart
                .draw_series(coords.map(|xy| TriangleMarker::new(xy, 8, style)))
                .map_err(|e| err(&e))?
                .label(&s.label)
                .legend(move |(x, y)| TriangleMarker::new((x + 12, y), 7, style)),
            Marker::Cross => chart
                .draw_series(coords.map(|xy| Cross::new(xy, 7, c.stroke_width(3))))
                .map_err(|e| err(&e))?
                .label(&s.label)
                .legend(move |(x, y)| Cross::new((x + 12, y), 6, c.stroke_width(3))),
        };
    }
    // every point's label, those on the front (the best for their budget) first and
    // in black, the others in grey, placed clear of each other
    let order: Vec<usize> = front
        .iter()
        .copied()
        .chain((0..pts.len()).filter(|i| !front.contains(i)))
        .collect();
    let font = |i: usize| {
        let (size, colour) = if front.contains(&i) {
            (13, BLACK)
        } else {
            (12, RGBColor(110, 110, 110))
        };
        ("sans-serif", size).into_font().color(&colour)
    };
    let anchors: Vec<(i32, i32)> = order
        .iter()
        .map(|&i| chart.backend_coord(&(pts[i].0, pts[i].1)))
        .collect();
    let sizes: Vec<(i32, i32)> = order
        .iter()
        .map(|&i| {
            // the measured box is the glyphs' tight box: a little room around it
            let (w, h) = font(i).font.box_size(pts[i].2).unwrap_or((0, 0));
            (w as i32 + 2, h as i32 + 3)
        })
        .collect();
    let (xs, ys) = chart.plotting_area().get_pixel_range();
    let offsets = super::labels::place(&anchors, &sizes, (xs.start, ys.start, xs.end, ys.end));
    chart
        .draw_series(order.iter().zip(&offsets).map(|(&i, &off)| {
            EmptyElement::at((pts[i].0, pts[i].1)) + Text::new(pts[i].2.to_string(), off, font(i))
        }))
        .map_err(|e| err(&e))?;
    lines_drawn.extend(&anchors);
    // the legend keeps off the labels too: each label's corners and centre
    for ((&(x, y), &(dx, dy)), &(w, h)) in anchors.iter().zip(&offsets).zip(&sizes) {
        let (l, t) = (x + dx, y + dy);
        lines_drawn.extend([
            (l, t),
            (l + w, t),
            (l, t + h),
            (l + w, t + h),
            (l + w / 2, t + h / 2),
        ]);
    }
    draw_legend(&mut chart, &lines_drawn, &labels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_keep_what_differs_and_ticks_what_tells_them_apart() {
        let names = ["s_iterations-100_k-2", "s_iterations-300_k-2"];
        assert_eq!(short_labels(&names), ["iterations-100", "iterations-300"]);
        assert_eq!(short_labels(&["only_one"]), ["only_one"]);
        let long = "x".repeat(50);
        assert_eq!(short_labels(&[&long, "y"])[0].chars().count(), 41);
        assert_eq!(linear_tick(4.7541, 0.01), "4.754");
        assert_eq!(linear_tick(20.0, 8.0), "20.0");
        assert_eq!(linear_tick(20.0, 40.0), "20");
        assert_eq!(tick(1234.5), "1234");
    }

    #[test]
    fn a_cost_axis_spans_at_least_a_tenth_of_its_largest_value() {
        // Sizes 5 KB apart in 1.42 MB: widened to 142 KB about their centre, then padded.
        let (a, b) = range([1_418_000.0, 1_423_000.0].into_iter(), 0.0, true);
        assert!(
            (a - 1_349_350.0).abs() < 1e-6 && (b - 1_491_650.0).abs() < 1e-6,
            "{a} {b}"
        );
        let (a, b) = range([1_418_000.0, 1_423_000.0].into_iter(), 0.1, true);
        assert!((b - a - 1.2 * 142_300.0).abs() < 1e-6, "{a} {b}");
        // Spread wider than that: only the padding.
        assert_eq!(range([100.0, 150.0].into_iter(), 0.1, true), (95.0, 155.0));
        // Not a cost (PSNR; may be negative): as drawn before.
        assert_eq!(range([24.0, 24.1].into_iter(), 0.0, false), (24.0, 24.1));
        // Widening never crosses zero.
        let (a, _) = range([0.0, 0.001].into_iter(), 0.0, true);
        assert_eq!(a, 0.0);
    }
}
