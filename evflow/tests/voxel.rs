//! Voxel grid (Eq. 15) against hand-computed values.

use evflow::voxel::{normalize_nonzero, voxel_grid, voxel_grid_raw};
use scene::EventStream;

fn stream(w: u32, h: u32, evs: &[(f64, u16, u16, i8)]) -> EventStream {
    let mut s = EventStream::new(w, h);
    for &(t, x, y, p) in evs {
        s.push(t, x, y, p);
    }
    s
}

#[test]
fn raw_grid_is_bilinear_in_time_and_signed() {
    // 2×1 sensor, 5 bins over [0, 1]: t* = 4t.
    let s = stream(2, 1, &[(0.0, 0, 0, 1), (0.375, 1, 0, -1), (1.0, 0, 0, 1)]);
    let g = voxel_grid_raw(&s.as_slice(), 0.0, 1.0, 5, 2, 1);
    // [bin][x]: t*=0 → bin 0; t*=1.5 → −½ in bins 1 and 2; t*=4 → bin 4.
    let expected = [1.0, 0.0, 0.0, -0.5, 0.0, -0.5, 0.0, 0.0, 1.0, 0.0];
    assert_eq!(g, expected);
}

#[test]
fn normalised_grid_matches_hand_computation() {
    let s = stream(2, 1, &[(0.0, 0, 0, 1), (0.375, 1, 0, -1), (1.0, 0, 0, 1)]);
    let g = voxel_grid(&s.as_slice(), 0.0, 1.0, 5, 2, 1);
    // Non-zero cells {1, −½, −½, 1}: mean ¼, std ¾ → {1, −1, −1, 1}; zeros stay 0.
    let expected = [1.0, 0.0, 0.0, -1.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0];
    for (a, b) in g.iter().zip(expected) {
        assert!((a - b).abs() < 1e-6, "{g:?}");
    }
}

#[test]
fn weights_follow_the_tent_and_events_accumulate() {
    // Window [1, 2], 3 bins: t* = 2(t − 1).
    let s = stream(
        1,
        2,
        &[
            (1.1, 0, 1, 1),
            (1.1, 0, 1, 1),
            (1.7, 0, 0, -1),
            (2.2, 0, 0, 1),
        ],
    );
    let g = voxel_grid_raw(&s.as_slice(), 1.0, 2.0, 3, 1, 2);
    // Layout [bin][y]: two +1 at t*=0.2 → pixel y=1: bin0 2·0.8, bin1 2·0.2.
    // −1 at t*=1.4 → y=0: bin1 −0.6, bin2 −0.4. +1 at t*=2.4 → bin2 gets 0.6 (tent).
    let expected = [0.0, 1.6, -0.6, 0.4, 0.2, 0.0];
    for (a, b) in g.iter().zip(expected) {
        assert!((a - b).abs() < 1e-6, "{g:?}");
    }
}

#[test]
fn empty_window_gives_zeros_and_no_nan() {
    let s = stream(4, 3, &[]);
    let g = voxel_grid(&s.as_slice(), 0.0, 1.0, 5, 4, 3);
    assert_eq!(g.len(), 5 * 4 * 3);
    assert!(g.iter().all(|&v| v == 0.0));
    // Degenerate window: everything in bin 0, still finite.
    let s = stream(2, 2, &[(0.5, 1, 1, 1), (0.5, 0, 0, -1), (0.5, 0, 0, -1)]);
    let g = voxel_grid_raw(&s.as_slice(), 0.5, 0.5, 5, 2, 2);
    assert_eq!(&g[..4], &[-2.0, 0.0, 0.0, 1.0]);
    assert!(g[4..].iter().all(|&v| v == 0.0));
    let g = voxel_grid(&s.as_slice(), 0.5, 0.5, 5, 2, 2);
    // Non-zero {−2, 1}: mean −½, std 1.5 → {−1, 1}.
    assert!((g[0] + 1.0).abs() < 1e-6 && (g[3] - 1.0).abs() < 1e-6);
    assert!(g.iter().all(|v| v.is_finite()));
}

#[test]
fn single_nonzero_cell_has_zero_std_and_stays_finite() {
    let mut g = vec![0.0, 3.0, 0.0];
    normalize_nonzero(&mut g);
    assert_eq!(g, vec![0.0, 0.0, 0.0]);
}

#[test]
fn events_outside_the_sensor_are_ignored() {
    let s = stream(8, 8, &[(0.5, 7, 7, 1), (0.5, 3, 3, 1)]);
    // Grid narrower than the stream's sensor: (7, 7) falls outside 4×4.
    let g = voxel_grid_raw(&s.as_slice(), 0.0, 1.0, 3, 4, 4);
    assert_eq!(g.iter().sum::<f32>(), 1.0);
    assert_eq!(g[16 + 3 * 4 + 3], 1.0); // t* = 1 → bin 1 only
}
