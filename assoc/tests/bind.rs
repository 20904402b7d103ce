//! kNN binding against brute force; weights; radius; degenerate inputs.

use assoc::bind::MIN_DISTANCE;
use assoc::bind_nearest;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// `n` points uniform in the unit cube.
fn random_points(rng: &mut ChaCha8Rng, n: usize) -> Vec<[f32; 3]> {
    (0..n)
        .map(|_| {
            [
                rng.random::<f32>(),
                rng.random::<f32>(),
                rng.random::<f32>(),
            ]
        })
        .collect()
}

/// Brute force: (squared distance, index) of the k nearest within r, ties by index.
fn brute(points: &[[f32; 3]], c: [f32; 3], r: f32, k: usize) -> Vec<(f32, usize)> {
    let mut v: Vec<(f32, usize)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let d2 = (0..3).map(|a| (p[a] - c[a]) * (p[a] - c[a])).sum::<f32>();
            (d2, i)
        })
        .filter(|&(d2, _)| d2 <= r * r)
        .collect();
    v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    v.truncate(k);
    v
}

fn check_against_brute(points: &[[f32; 3]], centres: &[[f32; 3]], radii: &[f32], k: usize) {
    let ids: Vec<u64> = (0..points.len() as u64).map(|i| 1000 + i).collect();
    let (b, dist) = bind_nearest(points, &ids, centres, radii, k);
    assert_eq!(b.gaussians(), centres.len());
    assert_eq!(dist.len(), b.events.len());
    for (g, c) in centres.iter().enumerate() {
        let want = brute(points, *c, radii[g], k);
        let (ev, w) = b.of(g);
        assert_eq!(ev.len(), want.len(), "Gaussian {g}: binding count");
        for (j, &(d2, i)) in want.iter().enumerate() {
            // Same distance always; same index unless tied with another candidate.
            let got = (ev[j] - 1000) as usize;
            let got_d2 = (0..3)
                .map(|a| (points[got][a] - c[a]) * (points[got][a] - c[a]))
                .sum::<f32>();
            assert!(
                (got_d2 - d2).abs() <= 1e-6 * d2.max(1e-6),
                "Gaussian {g} slot {j}"
            );
            let all = brute(points, *c, radii[g], usize::MAX);
            let tied = all.iter().filter(|x| x.0 == d2).count() > 1;
            if !tied {
                assert_eq!(got, i, "Gaussian {g} slot {j}");
            }
        }
        if !ev.is_empty() {
            let s: f32 = w.iter().sum();
            assert!((s - 1.0).abs() < 1e-6, "weights sum {s}");
            // Inverse-distance: nearer gets more weight.
            for j in 1..w.len() {
                assert!(w[j] <= w[j - 1] + 1e-6);
            }
            for (j, &d) in dist[b.offsets[g] as usize..b.offsets[g + 1] as usize]
                .iter()
                .enumerate()
            {
                assert!(
                    d <= radii[g] * (1.0 + 1e-6),
                    "slot {j}: {d} beyond {}",
                    radii[g]
                );
            }
        }
    }
}

#[test]
fn random_clouds_match_brute_force() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for trial in 0..20 {
        let n = [0, 1, 2, 5, 50, 2000][trial % 6];
        let points: Vec<[f32; 3]> = random_points(&mut rng, n);
        let centres: Vec<[f32; 3]> = random_points(&mut rng, 300);
        let radii: Vec<f32> = (0..300).map(|_| rng.random::<f32>() * 0.3).collect();
        for k in [1, 3, 7] {
            check_against_brute(&points, &centres, &radii, k);
        }
    }
}

#[test]
fn ties_and_duplicates_on_a_grid() {
    // Integer grid: many equal distances; plus exact duplicates of points.
    let mut points = Vec::new();
    for x in 0..6 {
        for y in 0..6 {
            for z in 0..3 {
                points.push([x as f32, y as f32, z as f32]);
            }
        }
    }
    points.extend_from_slice(&points.clone()[..20]);
    let centres: Vec<[f32; 3]> = (0..40)
        .map(|i| [(i % 6) as f32, ((i / 6) % 6) as f32 + 0.5, 1.0])
        .collect();
    let radii = vec![1.2f32; centres.len()];
    check_against_brute(&points, &centres, &radii, 3);
}

#[test]
fn k_larger_than_points_and_exact_hits() {
    let points = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0]];
    let (b, _) = bind_nearest(&points, &[5, 9], &[[0.0, 0.0, 0.0]], &[10.0], 8);
    let (ev, w) = b.of(0);
    assert_eq!(ev, &[5, 9]);
    // An event at the centre dominates but stays finite.
    assert!(w[0] > 0.999 && w[0].is_finite() && (w[0] + w[1] - 1.0).abs() < 1e-6);
}

#[test]
fn zero_radius_nan_centre_and_k_zero_bind_nothing() {
    let points = [[0.0f32, 0.0, 0.0]];
    let (b, _) = bind_nearest(
        &points,
        &[0],
        &[[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [0.1, 0.0, 0.0]],
        &[0.0, 1.0, 1.0],
        3,
    );
    assert_eq!(b.offsets, vec![0, 0, 0, 1]);
    let (b, d) = bind_nearest(&points, &[0], &[[0.0, 0.0, 0.0]], &[1.0], 0);
    assert_eq!((b.bound(), b.gaussians(), d.len()), (0, 1, 0));
    let (b, _) = bind_nearest(&[], &[], &[[0.0, 0.0, 0.0]], &[1.0], 3);
    assert_eq!(b.offsets, vec![0, 0]);
}

/// The weights are exactly the normalised inverse distances
/// `w_i = (1/d_i) / Σ_j (1/d_j)`, with `d` floored at [`MIN_DISTANCE`] (documented in
/// `assoc::bind`), recomputed here in f64 from the brute-force distances.
#[test]
fn weights_are_normalised_inverse_distances() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let points: Vec<[f32; 3]> = (0..400)
        .map(|_| [rng.random(), rng.random(), rng.random()])
        .collect();
    let centres: Vec<[f32; 3]> = (0..200)
        .map(|_| [rng.random(), rng.random(), rng.random()])
        .collect();
    let radii = vec![0.15f32; centres.len()];
    let ids: Vec<u64> = (0..points.len() as u64).collect();
    let (b, dist) = bind_nearest(&points, &ids, &centres, &radii, 3);
    let mut checked = 0;
    for (g, c) in centres.iter().enumerate() {
        let (ev, w) = b.of(g);
        let d: Vec<f64> = ev
            .iter()
            .map(|&i| {
                let p = points[i as usize];
                (0..3)
                    .map(|a| (p[a] as f64 - c[a] as f64).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .collect();
        let inv: Vec<f64> = d
            .iter()
            .map(|&d| 1.0 / d.max(MIN_DISTANCE as f64))
            .collect();
        let sum: f64 = inv.iter().sum();
        let range = b.offsets[g] as usize..b.offsets[g + 1] as usize;
        for (j, (&wj, &dj)) in w.iter().zip(&dist[range]).enumerate() {
            assert!((dj as f64 - d[j]).abs() < 1e-6, "Gaussian {g}: distance");
            let want = inv[j] / sum;
            assert!(
                (wj as f64 - want).abs() < 2e-6,
                "Gaussian {g} slot {j}: weight {wj} vs {want}"
            );
            checked += 1;
        }
    }
    // Most Gaussians bind to the full k = 3 at this density (≈ 5.6 points in reach).
    assert!(checked > 400, "{checked} weights checked");
    assert!(b.bound() > 150, "{} bound", b.bound());

    // Distances 0, 1, 2 from the centre: d = 0 counts as MIN_DISTANCE.
    let pts = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
    let (b, d) = bind_nearest(&pts, &[7, 8, 9], &[[0.0; 3]], &[5.0], 3);
    assert_eq!(b.events, vec![7, 8, 9]);
    assert_eq!(d, vec![0.0, 1.0, 2.0]);
    let inv = [1.0 / MIN_DISTANCE as f64, 1.0, 0.5];
    let sum: f64 = inv.iter().sum();
    for (j, &w) in b.weights.iter().enumerate() {
        let want = inv[j] / sum;
        assert!(
            (w as f64 - want).abs() <= 1e-6 * want,
            "slot {j}: {w} vs {want}"
        );
    }
    // Exactly: w = (1e6, 1, 0.5) / 1000001.5.
    assert!((b.weights[1] as f64 - 1.0 / 1_000_001.5).abs() < 1e-12);
    // Two events at the centre share the weight equally; a third at 1 gets ~1e-6.
    let pts = [[0.0f32, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
    let (b, _) = bind_nearest(&pts, &[1, 2, 3], &[[0.0; 3]], &[5.0], 3);
    assert_eq!(b.weights[0], b.weights[1]);
    assert!((b.weights[0] as f64 - 1e6 / 2_000_001.0).abs() < 1e-7);
    assert!((b.weights[2] as f64 - 1.0 / 2_000_001.0).abs() < 1e-12);
}

#[test]
fn bindings_of_some_gaussians_spread_to_all_give_each_its_own_events() {
    // Bind events to the centres of Gaussians 1, 3 and 4 of six (the others not alive),
    // spread to six: each alive Gaussian's events are the ones binding it alone gives,
    // the others have none.
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let points: Vec<[f32; 3]> = random_points(&mut rng, 200);
    let ids: Vec<u64> = (0..200).collect();
    let all: Vec<[f32; 3]> = (0..6).map(|g| [0.15 * g as f32 + 0.1, 0.5, 0.5]).collect();
    let alive = [1usize, 3, 4];
    let centres: Vec<[f32; 3]> = alive.iter().map(|&g| all[g]).collect();
    let (b, _) = bind_nearest(&points, &ids, &centres, &[0.2; 3], 4);
    let spread = b.clone().spread(&alive, 6);
    assert_eq!(spread.gaussians(), 6);
    for (g, centre) in all.iter().enumerate() {
        let (ev, w) = spread.of(g);
        match alive.iter().position(|&a| a == g) {
            Some(j) => {
                let (one, _) = bind_nearest(&points, &ids, &[*centre], &[0.2], 4);
                assert_eq!(ev, one.of(0).0, "Gaussian {g}");
                assert_eq!((ev, w), b.of(j));
            }
            None => assert!(ev.is_empty() && w.is_empty(), "Gaussian {g} is not alive"),
        }
    }
}
