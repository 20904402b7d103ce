//! Lowering a model's SH degree by refitting, not just truncating: the real SH bands are
//! orthonormal over the whole sphere, so dropping the higher ones is the best
//! lower-degree colour over all directions; the sizing needs the best over the
//! directions the train cameras see each Gaussian from. Per Gaussian and channel, the
//! coefficients up to the lower degree minimise
//! `Σ_views (colour_low(dir_v) − colour_high(dir_v))² + λ·|x − x_truncated|²`
//! (the small ridge keeps the solve well posed when the views are few or in a line).

// Index loops mirror the normal equations and the Cholesky factorisation; the negated
// comparison rejects NaN.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

use crate::raster::sh::{basis_f64, num_coeffs};
use crate::splats::Splats;
use rayon::prelude::*;

/// Ridge weight per view, towards the truncated coefficients.
const RIDGE: f64 = 1e-3;

/// `s` with its colour refitted from SH degree `from` down to `to` (< `from`) at the
/// directions from the camera centres `eyes` to each Gaussian's mean; coefficients above
/// `to` zeroed. Geometry and flags are unchanged.
pub(crate) fn refit_sh(s: &Splats, from: u32, to: u32, eyes: &[[f64; 3]]) -> Splats {
    let mut out = s.clone();
    let (n_hi, n_lo) = (num_coeffs(from), num_coeffs(to.min(from)));
    (out.sh_dc.par_iter_mut(), out.sh_rest.par_iter_mut())
        .into_par_iter()
        .enumerate()
        .for_each(|(i, (dc, rest))| {
            let coef = |k: usize, c: usize| -> f64 {
                if k == 0 {
                    s.sh_dc[i][c] as f64
                } else {
                    s.sh_rest[i][(k - 1) * 3 + c] as f64
                }
            };
            // Normal equations (AᵀA + λV·I) x = Aᵀy + λV·x_trunc, per channel.
            let mut ata = [[0.0f64; 16]; 16];
            let mut aty = [[0.0f64; 16]; 3];
            let m = s.means[i].map(|v| v as f64);
            for e in eyes {
                let d = [m[0] - e[0], m[1] - e[1], m[2] - e[2]];
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                if !(len > 1e-12) {
                    continue;
                }
                let b = basis_f64(d.map(|v| v / len), from);
                for c in 0..3 {
                    let y: f64 = (0..n_hi).map(|k| b[k] * coef(k, c)).sum();
                    for j in 0..n_lo {
                        aty[c][j] += b[j] * y;
                    }
                }
                for j in 0..n_lo {
                    for k in 0..n_lo {
                        ata[j][k] += b[j] * b[k];
                    }
                }
            }
            let lambda = RIDGE * eyes.len().max(1) as f64;
            for j in 0..n_lo {
                ata[j][j] += lambda;
                for c in 0..3 {
                    aty[c][j] += lambda * coef(j, c);
                }
            }
            for c in 0..3 {
                let x = solve_spd(&ata, &aty[c], n_lo);
                dc[c] = x[0] as f32;
                for k in 1..16 {
                    rest[(k - 1) * 3 + c] = if k < n_lo { x[k] as f32 } else { 0.0 };
                }
            }
        });
    out
}

/// Solve `a·x = b` for the leading `n × n` block of a symmetric positive definite `a`
/// (Cholesky).
fn solve_spd(a: &[[f64; 16]; 16], b: &[f64; 16], n: usize) -> [f64; 16] {
    let mut l = [[0.0f64; 16]; 16];
    for j in 0..n {
        let mut d = a[j][j];
        for k in 0..j {
            d -= l[j][k] * l[j][k];
        }
        let d = d.max(1e-300).sqrt();
        l[j][j] = d;
        for i in j + 1..n {
            let mut v = a[i][j];
            for k in 0..j {
                v -= l[i][k] * l[j][k];
            }
            l[i][j] = v / d;
        }
    }
    let mut y = [0.0f64; 16];
    for i in 0..n {
        let mut v = b[i];
        for k in 0..i {
            v -= l[i][k] * y[k];
        }
        y[i] = v / l[i][i];
    }
    let mut x = [0.0f64; 16];
    for i in (0..n).rev() {
        let mut v = y[i];
        for k in i + 1..n {
            v -= l[k][i] * x[k];
        }
        x[i] = v / l[i][i];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::splats::Gaussian;

    /// Colour of Gaussian 0 of `s` at degree `deg` seen from `eye`.
    fn colour(s: &Splats, deg: u32, eye: [f64; 3]) -> [f64; 3] {
        let m = s.means[0].map(|v| v as f64);
        let d = [m[0] - eye[0], m[1] - eye[1], m[2] - eye[2]];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let b = basis_f64(d.map(|v| v / len), deg);
        std::array::from_fn(|c| {
            let mut v = 0.5 + b[0] * s.sh_dc[0][c] as f64;
            for k in 1..num_coeffs(deg) {
                v += b[k] * s.sh_rest[0][(k - 1) * 3 + c] as f64;
            }
            v
        })
    }

    #[test]
    fn the_refit_matches_the_seen_directions_better_than_truncation() {
        let mut s = Splats::default();
        s.push(Gaussian {
            mean: [0.0, 0.0, 0.0],
            log_scale: [-2.0; 3],
            rotation: [1.0, 0.0, 0.0, 0.0],
            opacity_logit: 1.0,
            sh_dc: [0.3, -0.1, 0.2],
            sh_rest: std::array::from_fn(|k| 0.15 * ((k * 7 % 11) as f32 - 5.0) / 5.0),
            dynamic: true,
        });
        // Nine cameras on an arc in front of it, as a capture sees an object.
        let eyes: Vec<[f64; 3]> = (0..9)
            .map(|k| {
                let a = (k as f64 - 4.0) * 0.08;
                [4.0 * a.sin(), 0.3, 4.0 * a.cos()]
            })
            .collect();
        let err = |t: &Splats, deg: u32| -> f64 {
            eyes.iter()
                .map(|&e| {
                    let (a, b) = (colour(&s, 3, e), colour(t, deg, e));
                    (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>()
                })
                .sum::<f64>()
                .sqrt()
        };
        for to in [0u32, 1, 2] {
            let mut truncated = s.clone();
            for k in num_coeffs(to)..16 {
                for c in 0..3 {
                    truncated.sh_rest[0][(k - 1) * 3 + c] = 0.0;
                }
            }
            let refit = refit_sh(&s, 3, to, &eyes);
            let (e_t, e_r) = (err(&truncated, to), err(&refit, to));
            eprintln!("degree {to}: refit {e_r:.4} against truncated {e_t:.4}");
            assert!(
                e_r < if to == 0 { 0.6 } else { 0.5 } * e_t,
                "degree {to}: refit {e_r:.4} vs truncated {e_t:.4}"
            );
            if to == 0 {
                // The best constant is the mean of the colours seen (to the ridge).
                let mean: Vec<f64> = (0..3)
                    .map(|c| eyes.iter().map(|&e| colour(&s, 3, e)[c]).sum::<f64>() / 9.0)
                    .collect();
                let got = colour(&refit, 0, eyes[0]);
                for c in 0..3 {
                    assert!((got[c] - mean[c]).abs() < 2e-3, "{got:?} vs {mean:?}");
                }
            }
            // Nothing above the new degree remains; the geometry is untouched.
            assert!(
                refit.sh_rest[0][3 * (num_coeffs(to) - 1)..]
                    .iter()
                    .all(|&v| v == 0.0)
            );
            assert_eq!(
                (refit.means.clone(), refit.rotations.clone()),
                (s.means.clone(), s.rotations.clone())
            );
        }
        // Refitting to the same degree changes (almost) nothing.
        let same = refit_sh(&s, 3, 3, &eyes);
        assert!(err(&same, 3) < 1e-6);
    }

    #[test]
    fn cholesky_solves_a_known_system() {
        let mut a = [[0.0; 16]; 16];
        let m = [[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]];
        for i in 0..3 {
            for j in 0..3 {
                a[i][j] = m[i][j];
            }
        }
        let mut b = [0.0; 16];
        b[..3].copy_from_slice(&[1.0, 2.0, 3.0]);
        let x = solve_spd(&a, &b, 3);
        for i in 0..3 {
            let r: f64 = (0..3).map(|j| m[i][j] * x[j]).sum();
            assert!((r - b[i]).abs() < 1e-12, "row {i}: {r}");
        }
    }
}
