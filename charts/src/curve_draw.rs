//! The LoCM budget chart: one line per curve file, flow EPE ÷ zero-flow EPE against
//! LoCM fine-tuning time, the step where the stopping rule stopped ringed and labelled,
//! a dashed line at ratio 1 (the error of predicting no motion).

use super::curve::{Curve, read_curve, to_csv};
use super::draw::{Drawing, LINE_COLOURS, linear_tick, range, write_png_and_svg};
use super::legend::{draw_legend, polyline_anchors};
use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// One colour per curve, in file order (repeating past six).
pub(crate) const CURVE_COLOURS: [RGBColor; 6] = [
    RGBColor(214, 39, 40),
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// What the label of a curve's stopping point says.
pub(crate) fn stop_label(c: &Curve) -> Option<String> {
    let s = c.stop()?;
    let why = s.stop_reason.as_deref().unwrap_or("stopped");
    Some(format!(
        "step {} ({why}): {:.3} at {:.1} s",
        s.step, s.ratio, s.locm_s
    ))
}

struct CurveChart<'a> {
    curves: &'a [Curve],
}

/// Draw `curves` to `<stem>.png` and `<stem>.svg`.
pub(crate) fn draw_curves(curves: &[Curve], stem: &Path) -> Result<Vec<PathBuf>> {
    write_png_and_svg(&CurveChart { curves }, stem)
}

impl Drawing for CurveChart<'_> {
    fn draw_on<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let err = |e: &dyn std::fmt::Debug| format!("{e:?}");
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let steps = || self.curves.iter().flat_map(|c| c.steps.iter());
        let (x0, x1) = range(steps().map(|s| s.locm_s), 0.05, true);
        // the zero-flow level is always in view
        let (y0, y1) = range(steps().map(|s| s.ratio).chain([1.0]), 0.08, true);
        let mut chart = ChartBuilder::on(root)
            .caption(
                "Flow error against LoCM fine-tuning time",
                ("sans-serif", 24),
            )
            .margin(16)
            .x_label_area_size(56)
            .y_label_area_size(72)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("LoCM fine-tuning time, scoring not counted (s)")
            .y_desc("mean flow EPE ÷ zero-flow EPE")
            .axis_desc_style(("sans-serif", 18))
            .label_style(("sans-serif", 15))
            .x_label_formatter(&|v| linear_tick(*v, x1 - x0))
            .y_label_formatter(&|v| linear_tick(*v, y1 - y0))
            .light_line_style(RGBColor(246, 246, 246))
            .draw()
            .map_err(|e| err(&e))?;
        let grey = LINE_COLOURS[0];
        chart
            .draw_series(DashedLineSeries::new(
                [(x0, 1.0), (x1, 1.0)],
                8,
                5,
                grey.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label("zero flow (ratio 1: predicting no motion)")
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 24, y)], grey.stroke_width(2)));
        let mut labels = vec!["zero flow (ratio 1: predicting no motion)".to_string()];
        let mut drawn = polyline_anchors(&[
            chart.backend_coord(&(x0, 1.0)),
            chart.backend_coord(&(x1, 1.0)),
        ]);
        for (i, c) in self.curves.iter().enumerate() {
            let colour = CURVE_COLOURS[i % CURVE_COLOURS.len()];
            let xy: Vec<(f64, f64)> = c.steps.iter().map(|s| (s.locm_s, s.ratio)).collect();
            let pixels: Vec<(i32, i32)> = xy.iter().map(|p| chart.backend_coord(p)).collect();
            drawn.extend(polyline_anchors(&pixels));
            let zero = c.steps[0].zero_px;
            labels.push(format!(
                "{}: {} steps, zero-flow EPE {zero:.2} px",
                c.name,
                c.steps.len() - 1
            ));
            chart
                .draw_series(LineSeries::new(xy.clone(), colour.stroke_width(2)))
                .map_err(|e| err(&e))?
                .label(labels.last().cloned().unwrap_or_default())
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 24, y)], colour.stroke_width(2))
                });
            chart
                .draw_series(xy.iter().map(|&p| Circle::new(p, 3, colour.filled())))
                .map_err(|e| err(&e))?;
        }
        // the stopping points: a black ring, labelled beside it
        let stops: Vec<(f64, f64, String)> = self
            .curves
            .iter()
            .filter_map(|c| {
                let s = c.stop()?;
                Some((s.locm_s, s.ratio, stop_label(c)?))
            })
            .collect();
        if !stops.is_empty() {
            labels.push("where the stopping rule stopped".to_string());
            chart
                .draw_series(
                    stops
                        .iter()
                        .map(|s| Circle::new((s.0, s.1), 9, BLACK.stroke_width(2))),
                )
                .map_err(|e| err(&e))?
                .label("where the stopping rule stopped")
                .legend(|(x, y)| Circle::new((x + 12, y), 7, BLACK.stroke_width(2)));
        }
        let font = ("sans-serif", 14).into_font().color(&BLACK);
        let anchors: Vec<(i32, i32)> = stops
            .iter()
            .map(|s| chart.backend_coord(&(s.0, s.1)))
            .collect();
        let sizes: Vec<(i32, i32)> = stops
            .iter()
            .map(|s| {
                let (w, h) = font.font.box_size(&s.2).unwrap_or((0, 0));
                (w as i32, h as i32)
            })
            .collect();
        let (xs, ys) = chart.plotting_area().get_pixel_range();
        let area = (xs.start, ys.start, xs.end, ys.end);
        let offsets = super::labels::place(&anchors, &sizes, area);
        chart
            .draw_series(stops.iter().zip(&offsets).map(|(s, &off)| {
                EmptyElement::at((s.0, s.1)) + Text::new(s.2.clone(), off, font.clone())
            }))
            .map_err(|e| err(&e))?;
        drawn.extend(&anchors);
        draw_legend(&mut chart, &drawn, &labels)
    }
}

/// Read the curve files, draw their chart and write `locm-curves.json` / `.csv` into
/// `out`; the paths written.
pub fn write_curve_charts(paths: &[PathBuf], out: &Path) -> Result<Vec<PathBuf>> {
    let mut curves = paths
        .iter()
        .map(|p| read_curve(p))
        .collect::<Result<Vec<_>>>()?;
    // two files of one name (in different folders) are told apart by their paths
    let names: Vec<String> = curves.iter().map(|c| c.name.clone()).collect();
    for c in curves.iter_mut() {
        if names.iter().filter(|n| **n == c.name).count() > 1 {
            c.name = c.path.display().to_string();
        }
    }
    std::fs::create_dir_all(out).map_err(|e| anyhow!("{}: cannot create: {e}", out.display()))?;
    let mut written = draw_curves(&curves, &out.join("locm-curves"))?;
    let json = out.join("locm-curves.json");
    scene::atomic::write_json_atomic(&json, &curves)?;
    let csv = out.join("locm-curves.csv");
    scene::atomic::write_bytes_atomic(&csv, to_csv(&curves).as_bytes())?;
    written.extend([json, csv]);
    Ok(written)
}
