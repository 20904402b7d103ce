//! The lanes projection against the one-at-a-time [`project`], Gaussian by Gaussian:
//! the same culling, the same box (to a pixel where an edge falls within rounding of an
//! integer), the same values to f32 rounding, for every lane count this CPU has.

use super::*;
use crate::splats::Gaussian;
use glam::DVec3;
use scene::{Camera, Intrinsics, Pose};

pub(crate) struct Rng(pub u64);
impl Rng {
    pub fn uf(&mut self, lo: f32, hi: f32) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        lo + (hi - lo) * ((self.0 >> 40) as f32 / (1u64 << 24) as f32)
    }
}

/// Gaussians around the origin, some behind the camera, off the image, transparent,
/// tiny or huge, and a few degenerate (zero quaternion, NaN mean).
pub(crate) fn splats(n: usize, rng: &mut Rng) -> Splats {
    let mut s: Splats = (0..n)
        .map(|_| Gaussian {
            mean: std::array::from_fn(|_| rng.uf(-3.0, 3.0)),
            log_scale: std::array::from_fn(|_| rng.uf(-6.0, 1.5)),
            rotation: std::array::from_fn(|_| rng.uf(-1.0, 1.0)),
            opacity_logit: rng.uf(-9.0, 7.0),
            sh_dc: std::array::from_fn(|_| rng.uf(-1.2, 1.2)),
            sh_rest: std::array::from_fn(|_| rng.uf(-0.4, 0.4)),
            dynamic: false,
        })
        .collect();
    s.rotations[3] = [0.0; 4];
    s.means[7] = [f32::NAN, 0.0, 0.0];
    s.means[11] = [0.0, 0.0, 6.0]; // behind the camera
    s
}

pub(crate) fn camera() -> CamSetup {
    CamSetup::new(&Camera {
        intrinsics: Intrinsics {
            width: 61,
            height: 47,
            fx: 50.0,
            fy: 52.0,
            cx: 30.2,
            cy: 23.7,
            distortion: None,
        },
        cam_to_world: Pose::look_at(DVec3::new(0.3, 0.2, 4.0), DVec3::ZERO, DVec3::Y),
    })
}

fn close(a: f32, b: f32, what: &str, i: usize) {
    let tol = 2e-5 * (1.0 + a.abs().max(b.abs()));
    assert!((a - b).abs() <= tol, "Gaussian {i}: {what} {a} against {b}");
}

fn check(out: &[Projection], s: &Splats, cam: &CamSetup, degree: u32) -> usize {
    let mut visible = 0;
    for (i, (radius, splat)) in out.iter().enumerate() {
        let want = project(s, i, cam, degree);
        assert_eq!(
            splat.is_some(),
            want.is_some(),
            "Gaussian {i}: culled in one path only"
        );
        let (Some(p), Some(g)) = (splat, want) else {
            assert_eq!(*radius, 0.0);
            continue;
        };
        visible += 1;
        assert!((radius - g.radius).abs() <= 1.0, "Gaussian {i}: radius");
        for k in 0..4 {
            assert!(
                p.bbox[k].abs_diff(g.bbox[k]) <= 1,
                "Gaussian {i}: box {:?} against {:?}",
                p.bbox,
                g.bbox
            );
        }
        close(p.cut, g.cut, "cut", i);
        close(p.opacity, g.opacity, "opacity", i);
        close(p.depth, g.depth, "depth", i);
        for k in 0..2 {
            close(p.xy[k], g.uv[k], "mean", i);
        }
        for k in 0..3 {
            // Inverting a thin ellipse's covariance magnifies rounding by its condition
            // number (≈ trace² / det): compare relative to that.
            let [a, b, c] = g.conic;
            let cond = (a + c) * (a + c) / (a * c - b * b);
            let tol = 1e-5 * a.abs().max(c.abs()) * cond.max(1.0);
            assert!(
                (p.conic[k] - g.conic[k]).abs() <= tol,
                "Gaussian {i}: conic {:?} against {:?}",
                p.conic,
                g.conic
            );
            close(p.color[k], g.color[k], "colour", i);
        }
    }
    visible
}

#[test]
fn lanes_agree_with_the_one_at_a_time_projection() {
    let mut rng = Rng(7);
    let cam = camera();
    let n = 16 * 40 + 5; // whole blocks and a remainder
    let s = splats(n, &mut rng);
    let mut widths = vec![false];
    if simd::wide_available() {
        widths.push(true);
    } else {
        eprintln!("no AVX-512F here: only the 4-lane projection is compared");
    }
    for wide in widths {
        for degree in 0..=3 {
            let mut out = vec![(0.0, None); n];
            if wide {
                #[cfg(target_arch = "x86_64")]
                // SAFETY: AVX-512F was detected above.
                unsafe {
                    project_span_avx512(&s, 0, &cam, degree, &mut out)
                };
            } else {
                project_span_lanes::<F4>(&s, 0, &cam, degree, &mut out);
            }
            let visible = check(&out, &s, &cam, degree);
            // The scene must exercise both outcomes.
            assert!(
                visible > 100 && visible < n - 100,
                "{visible} of {n} visible"
            );
        }
    }
}
