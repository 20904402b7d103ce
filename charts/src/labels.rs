//! Where point labels go on a chart: beside their point, inside the plot, not over
//! each other.

/// A label's rectangle in pixels: left, top, width, height.
type Rect = (i32, i32, i32, i32);

fn overlaps(a: Rect, b: Rect) -> bool {
    a.0 < b.0 + b.2 && b.0 < a.0 + a.2 && a.1 < b.1 + b.3 && b.1 < a.1 + a.3
}

/// How many rows of places are tried above and below a point: enough for a dozen
/// labels of points that (nearly) coincide, as a sweep's repeats often do.
const ROWS: i32 = 6;

/// The offset (dx, dy) of each label's top-left corner from its point, in the order
/// given (earlier labels take the better places): right above, right below, left
/// above, left below, then a row further up or down each time (up to [`ROWS`]); the
/// first that stays inside `area` (left, top, right, bottom) and clears the markers and
/// the labels already placed, else the first inside the area, else right above.
pub fn place(
    points: &[(i32, i32)],
    sizes: &[(i32, i32)],
    area: (i32, i32, i32, i32),
) -> Vec<(i32, i32)> {
    // the markers (about 14 px across) are taken already
    let mut placed: Vec<Rect> = points
        .iter()
        .map(|&(x, y)| (x - 7, y - 7, 14, 14))
        .collect();
    let mut out = Vec::with_capacity(points.len());
    for (&(x, y), &(w, h)) in points.iter().zip(sizes) {
        let candidates: Vec<(i32, i32)> = (0..ROWS)
            .flat_map(|k| {
                let (up, down) = (-h - 4 - k * (h + 4), 5 + k * (h + 4));
                [(9, up), (9, down), (-9 - w, up), (-9 - w, down)]
            })
            .collect();
        let rect = |(dx, dy): (i32, i32)| (x + dx, y + dy, w, h);
        let inside =
            |r: Rect| r.0 >= area.0 && r.1 >= area.1 && r.0 + r.2 <= area.2 && r.1 + r.3 <= area.3;
        let free = |r: Rect| !placed.iter().any(|&p| overlaps(p, r));
        let best = candidates
            .iter()
            .copied()
            .find(|&c| inside(rect(c)) && free(rect(c)))
            .or_else(|| candidates.iter().copied().find(|&c| inside(rect(c))))
            .unwrap_or(candidates[0]);
        placed.push(rect(best));
        out.push(best);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_move_apart_and_stay_inside() {
        let area = (0, 0, 200, 100);
        // two points close together: the second label goes below the first one's
        let o = place(&[(50, 50), (52, 50)], &[(60, 12), (60, 12)], area);
        assert_eq!(o, [(9, -16), (9, 5)]);
        // near the right edge a label goes left of its point
        let o = place(&[(190, 50)], &[(60, 12)], area);
        assert_eq!(o, [(-69, -16)]);
        // near the top it goes below
        let o = place(&[(20, 5)], &[(60, 12)], area);
        assert_eq!(o, [(9, 5)]);
        // a label does not cover another point's marker
        let o = place(&[(50, 50), (100, 40)], &[(60, 12), (10, 12)], area);
        assert_eq!(o[0], (9, 5));
        assert!(overlaps((0, 0, 10, 10), (5, 5, 10, 10)));
        // eight labels of one point (a sweep's repeats) all find free places
        let o = place(&[(100, 100); 8], &[(60, 12); 8], (0, 0, 300, 200));
        let rects: Vec<Rect> = o
            .iter()
            .map(|&(dx, dy)| (100 + dx, 100 + dy, 60, 12))
            .collect();
        for (i, a) in rects.iter().enumerate() {
            for b in &rects[i + 1..] {
                assert!(!overlaps(*a, *b), "{a:?} overlaps {b:?}");
            }
        }
        assert!(!overlaps((0, 0, 10, 10), (10, 0, 10, 10)));
    }
}
