//! Two charts per stress: test PSNR and test LPIPS (when the runs have it) against the
//! stress level, DEGS and RGB-only as lines with markers, the 2D baselines (from the
//! DEGS runs) dashed. Levels sit at even
//! spacing in increasing order (they span decades and include 0), ticked with their
//! values; the clean scene is the stress's neutral level.

use super::report::{StressRecord, StressResult};
use super::variants::StressKind;
use anyhow::Result;
use charts::Method;
use charts::draw::{
    Drawing, LINE_COLOURS, Marker, linear_tick, method_style, range, write_png_and_svg,
};
use charts::legend::{draw_legend, polyline_anchors};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// A figure of a result (None where it has none).
type Figure = dyn Fn(&StressResult) -> Option<f64>;

/// One line: its legend label, style and `(level index, figure)` points.
struct Line {
    label: String,
    color: RGBColor,
    marker: Option<Marker>,
    dashed: bool,
    points: Vec<(f64, f64)>,
}

/// What one stress chart shows.
struct StressChart {
    title: String,
    x_label: String,
    y_label: &'static str,
    /// Tick text of each level position.
    levels: Vec<String>,
    lines: Vec<Line>,
}

/// Level text with few digits (0.001, 0.5, 20, 10000000).
fn level_text(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{}", v as i64)
    } else {
        format!("{v}")
    }
}

/// The figure a chart plots: the test PSNR or the test LPIPS, of the model and of each
/// 2D baseline.
#[derive(Clone, Copy, PartialEq)]
enum Plotted {
    Psnr,
    Lpips,
}

impl Plotted {
    fn figures(self) -> [&'static Figure; 4] {
        match self {
            Plotted::Psnr => [&|x| x.psnr, &|x| x.nearest_psnr, &|x| x.blend_psnr, &|x| {
                x.events_psnr
            }],
            Plotted::Lpips => [
                &|x| x.lpips,
                &|x| x.nearest_lpips,
                &|x| x.blend_lpips,
                &|x| x.events_lpips,
            ],
        }
    }
}

fn build(r: &StressRecord, kind: StressKind, plotted: Plotted) -> Option<StressChart> {
    let [model, nearest, blend, events] = plotted.figures();
    let degs = r.curve(kind, "degs");
    let rgb = r.curve(kind, "rgb");
    let mut levels: Vec<f64> = degs.iter().chain(&rgb).map(|(l, _)| *l).collect();
    levels.sort_by(f64::total_cmp);
    levels.dedup();
    if levels.is_empty() {
        return None;
    }
    let at = |l: f64| levels.iter().position(|x| *x == l).unwrap_or(0) as f64;
    let curve = |c: &[(f64, &StressResult)], f: &Figure| {
        c.iter()
            .filter_map(|(l, x)| f(x).filter(|v| v.is_finite()).map(|v| (at(*l), v)))
            .collect::<Vec<_>>()
    };
    let mut lines = Vec::new();
    for (method, c, m) in [
        ("RGB-only (γ1 = γ2 = 0)", &rgb, Method::RgbJoint),
        ("DEGS (events)", &degs, Method::Degs),
    ] {
        let (color, marker) = method_style(m);
        lines.push(Line {
            label: method.into(),
            color,
            marker: Some(marker),
            dashed: false,
            points: curve(c, model),
        });
    }
    if lines.iter().all(|l| l.points.is_empty()) {
        return None;
    }
    let baselines: [(&str, &Figure); 3] = [
        ("nearest frame", nearest),
        ("linear blend", blend),
        ("event pseudo image", events),
    ];
    for (i, (name, f)) in baselines.into_iter().enumerate() {
        lines.push(Line {
            label: format!("2D baseline: {name}"),
            color: LINE_COLOURS[i % LINE_COLOURS.len()],
            marker: None,
            dashed: true,
            points: curve(&degs, f),
        });
    }
    lines.retain(|l| !l.points.is_empty());
    let (what, y_label) = match plotted {
        Plotted::Psnr => ("test PSNR", "test PSNR (dB)"),
        Plotted::Lpips => ("test LPIPS", "test LPIPS (VGG; lower is better)"),
    };
    Some(StressChart {
        title: format!("{}: {what} under stress ({})", r.stress, kind.key()),
        x_label: kind.axis_label().into(),
        y_label,
        levels: levels.iter().map(|&l| level_text(l)).collect(),
        lines,
    })
}

impl Drawing for StressChart {
    fn draw_on<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let err = |e: &dyn std::fmt::Debug| format!("{e:?}");
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let n = self.levels.len() as f64;
        let (y0, y1) = range(
            self.lines.iter().flat_map(|l| l.points.iter().map(|p| p.1)),
            0.12,
            true,
        );
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 24))
            .margin(16)
            .x_label_area_size(56)
            .y_label_area_size(72)
            .build_cartesian_2d(-0.5..n - 0.5, y0..y1)
            .map_err(|e| err(&e))?;
        let levels = &self.levels;
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(self.y_label)
            .axis_desc_style(("sans-serif", 18))
            .label_style(("sans-serif", 15))
            .x_labels(levels.len() * 2 + 1)
            .x_label_formatter(&|v| {
                let i = v.round();
                match levels.get(i as usize) {
                    Some(t) if (v - i).abs() < 1e-6 && i >= 0.0 => t.clone(),
                    _ => String::new(),
                }
            })
            .y_label_formatter(&|v| linear_tick(*v, y1 - y0))
            .light_line_style(RGBColor(246, 246, 246))
            .draw()
            .map_err(|e| err(&e))?;
        let mut anchors = Vec::new();
        for l in &self.lines {
            let (c, style) = (l.color, l.color.stroke_width(2));
            let pixels: Vec<(i32, i32)> = l.points.iter().map(|p| chart.backend_coord(p)).collect();
            anchors.extend(polyline_anchors(&pixels));
            let drawn = if l.dashed {
                chart.draw_series(DashedLineSeries::new(l.points.clone(), 8, 5, style))
            } else {
                chart.draw_series(LineSeries::new(l.points.clone(), style))
            }
            .map_err(|e| err(&e))?;
            drawn
                .label(&l.label)
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 24, y)], c.stroke_width(2)));
            let filled = c.filled();
            let pts = l.points.iter().copied();
            match l.marker {
                Some(Marker::Circle) => {
                    chart
                        .draw_series(pts.map(|xy| Circle::new(xy, 6, filled)))
                        .map_err(|e| err(&e))?;
                }
                Some(Marker::Triangle) => {
                    chart
                        .draw_series(pts.map(|xy| TriangleMarker::new(xy, 7, filled)))
                        .map_err(|e| err(&e))?;
                }
                Some(Marker::Cross) => {
                    chart
                        .draw_series(pts.map(|xy| Cross::new(xy, 6, c.stroke_width(3))))
                        .map_err(|e| err(&e))?;
                }
                None => {}
            }
        }
        let labels: Vec<String> = self.lines.iter().map(|l| l.label.clone()).collect();
        draw_legend(&mut chart, &anchors, &labels)
    }
}

/// `<out>/stress-<key>.png` and `.svg` (PSNR) and `stress-<key>-lpips.png` and `.svg`
/// (when the runs have LPIPS) for every stress with levels (corruptions have no chart);
/// the files written.
pub fn write_charts(r: &StressRecord, out: &Path) -> Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    for kind in r.stresses() {
        for (plotted, suffix) in [(Plotted::Psnr, ""), (Plotted::Lpips, "-lpips")] {
            if let Some(chart) = build(r, kind, plotted) {
                let stem = out.join(format!("stress-{}{suffix}", kind.key()));
                written.extend(write_png_and_svg(&chart, &stem)?);
            }
        }
    }
    Ok(written)
}
