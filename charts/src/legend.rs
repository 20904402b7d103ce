//! Where a chart's legend goes: the place that covers the least of what was drawn, at
//! the legend's real size.

use plotters::prelude::*;

/// Font of the legend's labels.
const LEGEND_FONT: (&str, u32) = ("sans-serif", 14);

/// The legend of `labels` (the series' labels, in the order they were added) on a
/// translucent white box where it covers the fewest of `anchors` (pixel positions of what
/// was drawn; lines as [`polyline_anchors`]): see [`legend_place`].
pub fn draw_legend<'a, DB: DrawingBackend + 'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    anchors: &[(i32, i32)],
    labels: &[String],
) -> Result<(), String> {
    let (xs, ys) = chart.plotting_area().get_pixel_range();
    let area = (xs.start, ys.start, xs.end, ys.end);
    let place = legend_place(anchors, area, legend_size(labels));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::Coordinate(
            place.origin.0 - area.0,
            place.origin.1 - area.1,
        ))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(LEGEND_FONT)
        .draw()
        .map_err(|e| format!("{e:?}"))
}

/// The named places a legend may take, in order of preference on ties: the corners, then
/// the middles of the edges.
pub(crate) const LEGEND_PLACES: [&str; 8] = [
    "lower right",
    "upper right",
    "lower left",
    "upper left",
    "upper middle",
    "lower middle",
    "middle right",
    "middle left",
];

/// Where a legend goes: the name of its place ("inside" when no named place was the
/// emptiest) and its box's upper-left corner in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct LegendPlace {
    pub name: &'static str,
    pub origin: (i32, i32),
}

/// Size in pixels of the legend box of `labels`, laid out as plotters lays it out (the
/// labels' text block, a 30-pixel sample of the series and a 10-pixel margin around).
pub(crate) fn legend_size(labels: &[String]) -> (i32, i32) {
    // Measured with the bundled font (`draw::register_font`, before any chart is drawn).
    let font: TextStyle = LEGEND_FONT.into_font().into();
    let mut text = MultiLineText::<(i32, i32), &str>::new((0, 0), &font);
    for l in labels {
        text.push_line(l.as_str());
    }
    let (w, h) = text.estimate_dimension().unwrap_or((0, 0));
    (w + 30 + 20, h + 20)
}

/// The upper-left corner of a legend of `size` at place `k` of [`LEGEND_PLACES`] in the
/// plotting area `(x0, y0, x1, y1)`: 5 pixels in from the edges it touches.
fn named_origin(k: usize, area: (i32, i32, i32, i32), size: (i32, i32)) -> (i32, i32) {
    let (x0, y0, x1, y1) = area;
    let (w, h) = size;
    let (left, centre, right) = (x0 + 5, x0 + (x1 - x0 - w) / 2, x1 - w - 5);
    let (top, middle, bottom) = (y0 + 5, y0 + (y1 - y0 - h) / 2, y1 - h - 5);
    match k {
        0 => (right, bottom),
        1 => (right, top),
        2 => (left, bottom),
        3 => (left, top),
        4 => (centre, top),
        5 => (centre, bottom),
        6 => (right, middle),
        _ => (left, middle),
    }
}

/// The legend box of `size` pixels that covers the fewest of `points` in the plotting
/// area `(x0, y0, x1, y1)` (pixels, y down): the named places first (the earlier on
/// ties), then any position on a 10-pixel grid inside the area when one covers fewer.
pub(crate) fn legend_place(
    points: &[(i32, i32)],
    area: (i32, i32, i32, i32),
    size: (i32, i32),
) -> LegendPlace {
    let covered = |(bx, by): (i32, i32)| {
        points
            .iter()
            .filter(|&&(x, y)| x >= bx && x <= bx + size.0 && y >= by && y <= by + size.1)
            .count()
    };
    let named = (0..LEGEND_PLACES.len()).map(|k| (LEGEND_PLACES[k], named_origin(k, area, size)));
    let (x0, y0, x1, y1) = area;
    let grid = (y0 + 5..=y1 - size.1 - 5).step_by(10).flat_map(|y| {
        (x0 + 5..=x1 - size.0 - 5)
            .step_by(10)
            .map(move |x| ("inside", (x, y)))
    });
    let (name, origin) = named
        .chain(grid)
        .min_by_key(|&(_, o)| covered(o))
        .unwrap_or(("lower right", (x0, y0)));
    LegendPlace { name, origin }
}

/// Points every few pixels along the polyline through `points` (pixels), so that a
/// legend avoids a line and not only its vertices.
pub fn polyline_anchors(points: &[(i32, i32)]) -> Vec<(i32, i32)> {
    const STEP: f64 = 4.0;
    let mut out: Vec<(i32, i32)> = points.first().copied().into_iter().collect();
    for w in points.windows(2) {
        let (a, b) = (w[0], w[1]);
        let (dx, dy) = (f64::from(b.0 - a.0), f64::from(b.1 - a.1));
        let n = ((dx.hypot(dy) / STEP).ceil() as usize).clamp(1, 4096);
        out.extend((1..=n).map(|i| {
            let s = i as f64 / n as f64;
            (a.0 + (s * dx).round() as i32, a.1 + (s * dy).round() as i32)
        }));
    }
    out
}
