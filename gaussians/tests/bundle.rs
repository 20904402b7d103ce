//! The bundle adjustment of a rigid part (`tracks::bundle`): its derivatives against
//! central finite differences in f64, and what it recovers of a known rigid motion
//! seen by a known moving camera (exact pixels; depths with per-observation noise).

use gaussians::tracks::bundle::{self, Pose, Problem, Seen};
use glam::{DQuat, DVec3};
use scene::{Camera, Intrinsics};

mod lcg;
use lcg::Lcg;

fn camera(eye: DVec3) -> Camera {
    Camera {
        intrinsics: Intrinsics {
            width: 96,
            height: 96,
            fx: 90.0,
            fy: 88.0,
            cx: 47.5,
            cy: 46.0,
            distortion: None,
        },
        cam_to_world: scene::Pose::look_at(eye, DVec3::new(0.0, 0.0, 0.0), DVec3::Y),
    }
}

/// Nine knots: the camera sweeps an arc round the origin while a part of 40 points
/// within 0.3 of its centre turns and moves across; the pose at knot 4 is the identity.
fn world(r: &mut Lcg) -> (Vec<Camera>, Vec<Pose>, Vec<DVec3>) {
    let cams = (0..9)
        .map(|k| {
            let a = 0.06 * (k as f64 - 4.0);
            camera(DVec3::new(4.0 * a.sin(), 0.3, 4.0 * a.cos()))
        })
        .collect();
    let poses = (0..9)
        .map(|k| {
            let s = k as f64 - 4.0;
            let q = DQuat::from_scaled_axis(DVec3::new(0.02 * s, 0.09 * s, 0.01 * s));
            (q, DVec3::new(0.08 * s, 0.02 * s, -0.05 * s + 0.004 * s * s))
        })
        .collect();
    let points = (0..40).map(|_| 0.3 * r.vec()).collect();
    (cams, poses, points)
}

/// Where each point is seen: every knot, exact pixels, depths off by `noise` (relative,
/// uniform) per observation.
fn observe(
    cams: &[Camera],
    poses: &[Pose],
    points: &[DVec3],
    noise: f64,
    r: &mut Lcg,
) -> Vec<Vec<Seen>> {
    observe_scaled(cams, poses, points, noise, &[0.0; 9], r)
}

/// [`observe`] with each knot's depths off by its `scale` as well (relative).
fn observe_scaled(
    cams: &[Camera],
    poses: &[Pose],
    points: &[DVec3],
    noise: f64,
    scale: &[f64],
    r: &mut Lcg,
) -> Vec<Vec<Seen>> {
    (points.iter())
        .map(|&a| {
            (0..cams.len())
                .map(|k| {
                    let (px, z) = cams[k].project_world(poses[k].0 * a + poses[k].1).unwrap();
                    Seen {
                        knot: k,
                        pixel: px,
                        depth: Some(z * (1.0 + scale[k]) * (1.0 + noise * r.next())),
                    }
                })
                .collect()
        })
        .collect()
}

/// The problem the tests fit: knot 4 held, σ = 5 %, Huber at 1 px.
fn problem<'a>(refs: &'a [&'a Camera], seen: &'a [Vec<Seen>]) -> Problem<'a> {
    Problem {
        cameras: refs,
        seen,
        fixed: 4,
        depth_sigma: 0.05,
        huber: 1.0,
    }
}

#[test]
fn the_rows_derivatives_match_central_differences() {
    let mut r = Lcg(3);
    let (cams, poses, points) = world(&mut r);
    let refs: Vec<&Camera> = cams.iter().collect();
    let seen = observe(&cams, &poses, &points, 0.05, &mut r);
    let p = problem(&refs, &seen);
    let h = 1e-6;
    for (m, o) in [(0, 0), (7, 3), (21, 8), (39, 5)].map(|(m, k)| (m, seen[m][k])) {
        // Off the truth, so that the residuals are not zero.
        let pose = (
            DQuat::from_scaled_axis(0.1 * r.vec()) * poses[o.knot].0,
            poses[o.knot].1 + 0.05 * r.vec(),
        );
        let a = points[m] + 0.05 * r.vec();
        let sc = 0.03 * r.next();
        let (res, jp, ja) = bundle::rows(&p, pose, sc, a, &o).unwrap();
        assert_eq!(res.len(), 3);
        // Columns 0..7 the knot's `[ω, t, s]`, 7..10 the point's.
        for u in 0..10 {
            let moved = |e: f64| {
                let mut d = DVec3::ZERO;
                d[if u < 7 { u % 3 } else { u - 7 }] = e;
                match u {
                    0..3 => {
                        bundle::rows(&p, (DQuat::from_scaled_axis(d) * pose.0, pose.1), sc, a, &o)
                    }
                    3..6 => bundle::rows(&p, (pose.0, pose.1 + d), sc, a, &o),
                    6 => bundle::rows(&p, pose, sc + e, a, &o),
                    _ => bundle::rows(&p, pose, sc, a + d, &o),
                }
                .unwrap()
                .0
            };
            let (plus, minus) = (moved(h), moved(-h));
            for row in 0..3 {
                let fd = (plus[row] - minus[row]) / (2.0 * h);
                let got = if u < 7 { jp[row][u] } else { ja[row][u - 7] };
                let tol = 1e-6 * (1.0 + fd.abs());
                assert!(
                    (got - fd).abs() < tol,
                    "column {u} row {row}: {got} against {fd}"
                );
            }
        }
        // The residual itself against the camera's own projection.
        let (px, z) = refs[o.knot].project_world(pose.0 * a + pose.1).unwrap();
        assert!(
            (res[0] - (px.x - o.pixel.x)).abs() < 1e-9
                && (res[1] - (px.y - o.pixel.y)).abs() < 1e-9
        );
        let want = (z.ln() - o.depth.unwrap().ln() - sc) / 0.05;
        assert!((res[2] - want).abs() < 1e-9);
    }
}

/// A perturbed start: each pose but the held one turned by up to 0.05 rad and moved by
/// up to 0.05, each point moved by up to 0.05.
fn start(poses: &[Pose], points: &[DVec3], r: &mut Lcg) -> (Vec<Pose>, Vec<DVec3>) {
    let p = (poses.iter().enumerate())
        .map(|(k, &(q, t))| {
            if k == 4 {
                (q, t)
            } else {
                (
                    DQuat::from_scaled_axis(0.05 * r.vec()) * q,
                    t + 0.05 * r.vec(),
                )
            }
        })
        .collect();
    (p, points.iter().map(|&a| a + 0.05 * r.vec()).collect())
}

#[test]
fn exact_pixels_and_depths_give_back_the_motion() {
    let mut r = Lcg(11);
    let (cams, poses, points) = world(&mut r);
    let refs: Vec<&Camera> = cams.iter().collect();
    let seen = observe(&cams, &poses, &points, 0.0, &mut r);
    let p = problem(&refs, &seen);
    let (mut fp, mut fa) = start(&poses, &points, &mut r);
    let (rep, _) = bundle::adjust(&p, &mut fp, &mut fa, 50);
    assert!(rep.cost_after < 1e-14 * rep.cost_before, "{rep:?}");
    for (a, b) in fa.iter().zip(&points) {
        assert!(a.distance(*b) < 1e-6, "{a} against {b}");
    }
    for ((q, t), (q0, t0)) in fp.iter().zip(&poses) {
        assert!(q.angle_between(*q0) < 1e-6 && t.distance(*t0) < 1e-6);
    }
    assert!(bundle::misfit(&p, &fp, &fa).iter().all(|&e| e < 1e-6));
}

#[test]
fn depths_noisy_per_observation_pool_into_the_parts_scale() {
    let mut r = Lcg(5);
    let (cams, poses, points) = world(&mut r);
    let refs: Vec<&Camera> = cams.iter().collect();
    let noise = 0.06;
    let seen = observe(&cams, &poses, &points, noise, &mut r);
    let p = problem(&refs, &seen);
    let (mut fp, mut fa) = start(&poses, &points, &mut r);
    let _ = bundle::adjust(&p, &mut fp, &mut fa, 50);
    // Every point's depth at every knot against the truth.
    let mut rel: Vec<f64> = Vec::new();
    let mut px_err: Vec<f64> = Vec::new();
    for (m, (a, b)) in fa.iter().zip(&points).enumerate() {
        for k in 0..9 {
            let z = refs[k].project_world(fp[k].0 * *a + fp[k].1).unwrap().1;
            let z0 = refs[k]
                .project_world(poses[k].0 * *b + poses[k].1)
                .unwrap()
                .1;
            rel.push(z / z0 - 1.0);
            // The pixels stay where they were seen.
            let px = refs[k].project_world(fp[k].0 * *a + fp[k].1).unwrap().0;
            px_err.push(px.distance(seen[m][k].pixel));
        }
    }
    let px_worst = px_err.iter().fold(0.0f64, |w, e| w.max(*e));
    let mean = rel.iter().sum::<f64>() / rel.len() as f64;
    let median_abs = |v: &[f64]| {
        let mut a: Vec<f64> = v.iter().map(|e| e.abs()).collect();
        a.sort_by(f64::total_cmp);
        a[a.len() / 2]
    };
    // What one track alone knows of its depth: the mean of its own nine.
    let alone: Vec<f64> = (seen.iter().zip(&points))
        .map(|(obs, &b)| {
            let r = obs.iter().map(|o| {
                let z0 = refs[o.knot]
                    .project_world(poses[o.knot].0 * b + poses[o.knot].1)
                    .unwrap()
                    .1;
                o.depth.unwrap() / z0 - 1.0
            });
            r.sum::<f64>() / obs.len() as f64
        })
        .collect();
    let (pooled, own) = (median_abs(&rel), median_abs(&alone));
    // The part's scale: 360 depths pooled (uniform noise's σ = noise / √3, so about
    // 0.2 % for the mean); each point's depth at least twice as close as its own
    // track's nine depths make it; the pixels within half a pixel of where seen.
    assert!(mean.abs() < 0.004, "scale off by {mean}");
    assert!(
        pooled <= own,
        "median depth error {pooled}, a track alone {own}"
    );
    // The part's depth at each knot: 40 depths, σ ≈ 3.5 % each, pooled: 3σ ≈ 1.7 %.
    for k in 0..9 {
        let at_k: Vec<f64> = rel.iter().skip(k).step_by(9).copied().collect();
        let m = at_k.iter().sum::<f64>() / at_k.len() as f64;
        eprintln!("knot {k}: {m}");
        assert!(m.abs() < 0.017, "knot {k}: the part's depth off by {m}");
    }
    assert!(
        px_worst < 0.5,
        "a pixel moved {px_worst} from where it was seen"
    );
}

#[test]
fn a_wrong_track_is_named_and_does_not_move_the_part() {
    let mut r = Lcg(8);
    let (cams, poses, points) = world(&mut r);
    let refs: Vec<&Camera> = cams.iter().collect();
    let mut seen = observe(&cams, &poses, &points, 0.0, &mut r);
    // Track 0 is a background point caught in the part: it stays where it was at knot 4.
    let held = seen[0][4].pixel;
    for o in &mut seen[0] {
        o.pixel = held;
    }
    let p = problem(&refs, &seen);
    let (mut fp, mut fa) = start(&poses, &points, &mut r);
    let _ = bundle::adjust(&p, &mut fp, &mut fa, 50);
    let e = bundle::misfit(&p, &fp, &fa);
    assert!(e[0] > 2.0, "the slipped track fits to {} px", e[0]);
    for m in 1..points.len() {
        assert!(e[m] < 0.2, "track {m} off by {} px", e[m]);
        assert!(fa[m].distance(points[m]) < 0.01);
    }
}

#[test]
fn a_frames_scale_error_is_pooled_not_followed() {
    let mut r = Lcg(21);
    let (cams, poses, points) = world(&mut r);
    let refs: Vec<&Camera> = cams.iter().collect();
    // Each frame's prior off by its own scale, as a network's is.
    let scale = [-0.06, 0.04, 0.05, -0.03, 0.06, -0.05, 0.02, -0.04, 0.03];
    let seen = observe_scaled(&cams, &poses, &points, 0.01, &scale, &mut r);
    let p = problem(&refs, &seen);
    let (mut fp, mut fa) = start(&poses, &points, &mut r);
    let (_, s) = bundle::adjust(&p, &mut fp, &mut fa, 50);
    let mut rels = Vec::new();
    let mean_scale = scale.iter().sum::<f64>() / 9.0;
    let mut follow = Vec::new();
    // The part's depth at each knot against the truth: one size for all frames (the
    // mean of their scales, up to the per-observation noise), not each frame's own.
    for k in 0..9 {
        let rel: f64 = (fa.iter().zip(&points))
            .map(|(a, b)| {
                let z = refs[k].project_world(fp[k].0 * *a + fp[k].1).unwrap().1;
                let z0 = refs[k]
                    .project_world(poses[k].0 * *b + poses[k].1)
                    .unwrap()
                    .1;
                z / z0 - 1.0
            })
            .sum::<f64>()
            / points.len() as f64;
        let follows = (rel - mean_scale) / (scale[k] - mean_scale);
        eprintln!("knot {k}: {rel} follows {follows}");
        follow.push(follows);
        rels.push(rel);
        // The knot's (log) scale took the rest of the frame's error.
        assert!(
            (s[k] - (rel - scale[k])).abs() < 0.005,
            "knot {k}: s = {}",
            s[k]
        );
    }
    // Followed as they come, each knot would sit at its frame's scale (`follows` 1);
    // the part's apparent size (a radius of about 7 px here) holds it to a quarter.
    let mean_rel = rels.iter().sum::<f64>() / 9.0;
    assert!(
        (mean_rel - mean_scale).abs() < 0.003,
        "{mean_rel} against {mean_scale}"
    );
    assert!(follow.iter().all(|f| f.abs() < 0.4), "{follow:?}");
}

#[test]
fn a_rescaled_part_keeps_its_pixels_and_its_reference_pose() {
    let mut r = Lcg(11);
    let (cams, poses, points) = world(&mut r);
    let refs: Vec<&Camera> = cams.iter().collect();
    let (mut p2, mut a2) = (poses.clone(), points.clone());
    // Knot 2's pose is not the identity: the gauge must hold there too.
    let s = 1.07;
    bundle::rescale(&refs, 2, &mut p2, &mut a2, s);
    assert_eq!(p2[2].0, poses[2].0);
    assert!((p2[2].1 - poses[2].1).length() < 1e-12);
    for (a, b) in points.iter().zip(&a2) {
        for k in 0..cams.len() {
            let (u, z) = cams[k].project_world(poses[k].0 * *a + poses[k].1).unwrap();
            let (v, w) = cams[k].project_world(p2[k].0 * *b + p2[k].1).unwrap();
            assert!((u - v).length() < 1e-9, "knot {k}: pixel {u} became {v}");
            assert!((w / z - s).abs() < 1e-12, "knot {k}: depth {z} became {w}");
        }
    }
    // Still rigid: distances between points scale by s.
    let d = |p: &[DVec3]| (p[0] - p[1]).length();
    assert!((d(&a2) / d(&points) - s).abs() < 1e-12);
}
