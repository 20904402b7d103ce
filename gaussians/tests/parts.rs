//! Rigid parts (`gaussians::parts`, `tracks.parts`): the gradients against f64 central
//! differences, the init against a closed-form motion, the file round trip.

use gaussians::parts::{self, NO_PART, Parts};
use gaussians::splats::{ALWAYS, Gaussian, Splats};

mod lcg;
use lcg::Lcg;

fn dot<const N: usize>(a: [f64; N], b: [f64; N]) -> f64 {
    (0..N).map(|i| a[i] * b[i]).sum()
}

#[test]
fn place_gradients_match_finite_differences() {
    let mut r = Lcg(7);
    for _ in 0..20 {
        let q = r.arr::<4>().map(|v| v + 0.3);
        let (t, o, x) = (r.arr::<3>(), r.arr::<3>(), r.arr::<3>());
        let rot = r.arr::<4>();
        let (gx, gr) = (r.arr::<3>(), r.arr::<4>());
        let loss = |q: [f64; 4], t: [f64; 3], x: [f64; 3], rot: [f64; 4]| {
            let (px, pr) = parts::place(q, t, o, x, rot);
            dot(gx, px) + dot(gr, pr)
        };
        let (g_q, g_t, g_x, g_r) = parts::place_backward(q, o, x, rot, gx, gr);
        let h = 1e-6;
        let close = |a: f64, b: f64, what: &str| {
            assert!(
                (a - b).abs() <= 1e-6 * (1.0 + b.abs()),
                "{what}: {a} against {b}"
            );
        };
        for i in 0..4 {
            let (mut p, mut m) = (q, q);
            (p[i], m[i]) = (q[i] + h, q[i] - h);
            close(
                g_q[i],
                (loss(p, t, x, rot) - loss(m, t, x, rot)) / (2.0 * h),
                "q",
            );
            let (mut p, mut m) = (rot, rot);
            (p[i], m[i]) = (rot[i] + h, rot[i] - h);
            close(
                g_r[i],
                (loss(q, t, x, p) - loss(q, t, x, m)) / (2.0 * h),
                "rotation",
            );
        }
        for i in 0..3 {
            let (mut p, mut m) = (t, t);
            (p[i], m[i]) = (t[i] + h, t[i] - h);
            close(
                g_t[i],
                (loss(q, p, x, rot) - loss(q, m, x, rot)) / (2.0 * h),
                "t",
            );
            let (mut p, mut m) = (x, x);
            (p[i], m[i]) = (x[i] + h, x[i] - h);
            close(
                g_x[i],
                (loss(q, t, p, rot) - loss(q, t, m, rot)) / (2.0 * h),
                "x",
            );
        }
    }
}

/// Two parts over four knots, six Gaussians (two in no part).
fn model(r: &mut Lcg) -> Splats {
    let mut s = Splats::default();
    for _ in 0..6 {
        let mut g = Gaussian::isotropic(r.arr::<3>().map(|v| v as f32), -2.0, 0.0, [0.1; 3]);
        g.rotation = r.arr::<4>().map(|v| (v + 0.2) as f32);
        s.push(g);
    }
    let knots = vec![0.0, 0.3, 0.55, 1.0];
    let rows = 2 * knots.len();
    s.parts = Parts {
        knots,
        origin: vec![[0.1, 0.2, -0.3], [-0.5, 0.0, 0.4]],
        rot: (0..rows)
            .map(|_| {
                let v = r.arr::<4>();
                [1.0 + 0.3 * v[0], 0.3 * v[1], 0.3 * v[2], 0.3 * v[3]].map(|c| c as f32)
            })
            .collect(),
        shift: (0..rows).map(|_| r.arr::<3>().map(|v| v as f32)).collect(),
        fixed: 2,
    };
    s.part = vec![0, 1, NO_PART, 0, 1, NO_PART];
    s
}

#[test]
fn part_pose_gradients_match_finite_differences() {
    let mut r = Lcg(11);
    let s = model(&mut r);
    let n = s.len();
    let gm: Vec<[f64; 3]> = (0..n).map(|_| r.arr::<3>()).collect();
    let gq: Vec<[f64; 4]> = (0..n).map(|_| r.arr::<4>()).collect();
    let p = &s.parts;
    let f64s = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<f64>>();
    // L = Σ gm·x' + gq·q' in f64, from flat knot poses, centres and rotations.
    let loss = |rot: &[f64], shift: &[f64], means: &[f64], rots: &[f64], t: f32| -> f64 {
        let k = p.knots.len();
        (0..n)
            .map(|i| {
                let x: [f64; 3] = std::array::from_fn(|a| means[3 * i + a]);
                let q: [f64; 4] = std::array::from_fn(|a| rots[4 * i + a]);
                let (px, pq) = match s.part[i] {
                    NO_PART => (x, q),
                    m => {
                        let m = m as usize;
                        let rr: Vec<[f64; 4]> = (0..k)
                            .map(|j| std::array::from_fn(|a| rot[4 * (m * k + j) + a]))
                            .collect();
                        let ss: Vec<[f64; 3]> = (0..k)
                            .map(|j| std::array::from_fn(|a| shift[3 * (m * k + j) + a]))
                            .collect();
                        let (pq, pt) = parts::pose_at(&p.knots, &rr, &ss, t);
                        parts::place(pq, pt, p.origin[m].map(|v| v as f64), x, q)
                    }
                };
                dot(gm[i], px) + dot(gq[i], pq)
            })
            .sum()
    };
    for t in [0.1f32, 0.42, 0.55, 0.93] {
        let mut placed = s.clone();
        parts::advance(&s.parts, &s.part, t, &mut placed);
        let mut g = gaussians::SplatGrads::zeros(n);
        g.means = gm.iter().map(|g| g.map(|v| v as f32)).collect();
        g.rotations = gq.iter().map(|g| g.map(|v| v as f32)).collect();
        parts::backward(&s.parts, &s.part, t, &placed, &mut g);
        let (g_means, g_rots, g_rot, g_shift) = (g.means, g.rotations, g.part_rot, g.part_shift);
        let base = (
            f64s(p.rot.as_flattened()),
            f64s(p.shift.as_flattened()),
            f64s(s.means.as_flattened()),
            f64s(s.rotations.as_flattened()),
        );
        let h = 1e-6;
        let fd = |which: usize, j: usize| {
            let mut plus = base.clone();
            let mut minus = base.clone();
            let (a, b) = match which {
                0 => (&mut plus.0, &mut minus.0),
                1 => (&mut plus.1, &mut minus.1),
                2 => (&mut plus.2, &mut minus.2),
                _ => (&mut plus.3, &mut minus.3),
            };
            a[j] += h;
            b[j] -= h;
            (loss(&plus.0, &plus.1, &plus.2, &plus.3, t)
                - loss(&minus.0, &minus.1, &minus.2, &minus.3, t))
                / (2.0 * h)
        };
        let close = |a: f32, b: f64, what: String| {
            assert!(
                (a as f64 - b).abs() <= 2e-3 * (1.0 + b.abs()),
                "{what} at t = {t}: {a} against {b}"
            );
        };
        let k = p.knots.len();
        for j in 0..4 * p.rot.len() {
            let row = j / 4;
            if row % k == p.fixed {
                assert_eq!(g_rot[row][j % 4], 0.0, "the fixed knot gets no gradient");
            } else {
                close(g_rot[row][j % 4], fd(0, j), format!("rot {j}"));
            }
        }
        for j in 0..3 * p.shift.len() {
            let row = j / 3;
            if row % k == p.fixed {
                assert_eq!(g_shift[row][j % 3], 0.0);
            } else {
                close(g_shift[row][j % 3], fd(1, j), format!("shift {j}"));
            }
        }
        for j in 0..3 * n {
            close(g_means[j / 3][j % 3], fd(2, j), format!("mean {j}"));
        }
        for j in 0..4 * n {
            close(g_rots[j / 4][j % 4], fd(3, j), format!("rotation {j}"));
        }
    }
}

#[test]
fn the_pose_passes_through_each_knot() {
    let mut r = Lcg(3);
    let s = model(&mut r);
    for (k, &t) in s.parts.knots.iter().enumerate() {
        let (q, sh) = s.parts.pose(1, t);
        let row = s.parts.rows(1).start + k;
        assert!((0..4).all(|a| (q[a] - s.parts.rot[row][a]).abs() < 1e-6));
        assert!((0..3).all(|a| (sh[a] - s.parts.shift[row][a]).abs() < 1e-6));
    }
}

type Blob = ([f32; 3], [f32; 3], [f32; 3]);

/// Two blobs (centre, velocity, acceleration), each moving on its own quadratic (a
/// translation: rigid).
const BLOBS: [Blob; 2] = [
    ([-1.0, 0.0, -5.0], [0.6, 0.1, 0.0], [0.0, 0.4, 0.2]),
    ([1.2, 0.3, -6.0], [-0.3, 0.0, 0.5], [0.5, 0.0, 0.0]),
];

/// A still Gaussian, then 30 Gaussians of each blob per life in `lives`, each on its
/// blob's trajectory; and the five knots' cameras (one camera at the origin).
fn blobs_model(lives: &[[f32; 2]]) -> (Splats, scene::Camera) {
    let mut r = Lcg(5);
    let mut s = Splats::default();
    s.push(Gaussian::isotropic([0.0, 0.0, -20.0], -2.0, 0.0, [0.0; 3]));
    s.motion.push([0.0; 6]);
    s.life.push(ALWAYS);
    for (c, v, a) in BLOBS {
        for &life in lives {
            for _ in 0..30 {
                let off = r.arr::<3>().map(|x| 0.15 * x as f32);
                s.push(Gaussian::isotropic(
                    std::array::from_fn(|i| c[i] + off[i]),
                    -3.0,
                    0.0,
                    [0.0; 3],
                ));
                *s.motion.last_mut().unwrap() = [v[0], v[1], v[2], a[0], a[1], a[2]];
                *s.life.last_mut().unwrap() = life;
            }
        }
    }
    let cam = scene::Camera {
        intrinsics: scene::Intrinsics {
            width: 96,
            height: 96,
            fx: 80.0,
            fy: 80.0,
            cx: 48.0,
            cy: 48.0,
            distortion: None,
        },
        cam_to_world: Default::default(),
    };
    (s, cam)
}

/// Two blobs on their own quadratic paths, their Gaussians in windows of two frames
/// (sharing their end frames) as the tracks init leaves them: the init finds two parts
/// with every Gaussian in one, and their poses are the blobs' translations from the
/// middle frame.
#[test]
fn the_init_groups_two_moving_blobs_and_finds_their_motion() {
    let times = [0.0, 0.25, 0.5, 0.75, 1.0];
    let lives = [[f32::MIN, 0.25], [0.25, 0.5], [0.5, 0.75], [0.75, f32::MAX]];
    let (mut s, cam) = blobs_model(&lives);
    let cams = [&cam; 5];
    let before = s.clone();
    let sum = gaussians::tracks::parts::into_parts(&mut s, &times, &cams, 2.0, None, None);
    assert_eq!((sum.parts, sum.members, sum.left), (2, 240, 0), "{sum:?}");
    assert_eq!(sum.unseen, 0);
    assert_eq!(s.part[0], NO_PART);
    for i in 1..s.len() {
        let b = (i - 1) / 120;
        let p = s.part[i] as usize;
        assert_eq!(p, s.part[1 + 120 * b] as usize, "one part per blob");
        assert_eq!(s.motion[i], [0.0; 6]);
        assert_eq!(s.life[i], ALWAYS);
        // Canonical = the centre at the middle (the trajectory's μ).
        assert!((0..3).all(|a| (s.means[i][a] - before.means[i][a]).abs() < 1e-4));
        let (_, v, a) = BLOBS[b];
        for &t in &times {
            let tau = t as f32 - 0.5;
            let (q, sh) = s.parts.pose(p, t as f32);
            let want: [f32; 3] = std::array::from_fn(|k| v[k] * tau + a[k] * tau * tau);
            assert!((q[0].abs() - 1.0).abs() < 1e-4 && q[1..].iter().all(|c| c.abs() < 1e-4));
            assert!(
                (0..3).all(|k| (sh[k] - want[k]).abs() < 1e-4),
                "{sh:?} against {want:?}"
            );
        }
    }
}

/// The same blobs with Gaussians fitted over the first half of the recording only
/// (windows ending at 0.25 and 0.5, each fitted one frame beyond): no member was fitted
/// at the last knot, so a part's pose there would be a guess. No part is made, and
/// every Gaussian keeps its trajectory and its life.
#[test]
fn a_group_not_seen_at_every_frame_is_not_a_part() {
    let times = [0.0, 0.25, 0.5, 0.75, 1.0];
    let (mut s, cam) = blobs_model(&[[f32::MIN, 0.25], [0.25, 0.5]]);
    let before = s.clone();
    let sum = gaussians::tracks::parts::into_parts(&mut s, &times, &[&cam; 5], 2.0, None, None);
    assert_eq!((sum.parts, sum.members, sum.left), (0, 0, 120), "{sum:?}");
    assert_eq!(
        sum.unseen, 2,
        "both blobs' groups found, neither made a part"
    );
    assert_eq!((s.motion, s.life), (before.motion, before.life));
    assert!(s.parts.is_empty());
}

#[test]
fn the_motion_file_keeps_the_parts_and_names_a_wrong_one() {
    let mut r = Lcg(9);
    let s = model(&mut r);
    let dir = std::env::temp_dir().join(format!("degs-parts-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("motion.safetensors");
    let motion = vec![[0.0f32; 6]; s.len()];
    gaussians::model::motion_file::write_with_parts(&path, &motion, &[], &s.part, &s.parts)
        .unwrap();
    let (part, parts) = gaussians::model::motion_file::read_parts(&path, s.len()).unwrap();
    assert_eq!((part, parts), (s.part.clone(), s.parts.clone()));
    let e = gaussians::model::motion_file::read_parts(&path, s.len() + 1)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("motion.safetensors") && e.contains("part entries"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A flat part facing the cameras (so a uniform depth map is its true depth), turning
/// about the view axis and moving across and away, seen by a camera that slides
/// sideways over five frames. Its Gaussians' lifted trajectories are off by a few
/// millimetres each (as a track's own depth rows leave them); the tracks' pixels and
/// the depths are exact. With them (`Evidence`) the bundle adjustment puts every member
/// back on its true path at every frame; without, the poses chained from the
/// trajectories keep their error.
#[test]
fn the_bundle_adjustment_puts_the_members_on_their_true_paths() {
    let (before, after) = bundle_case(1.0);
    // f32 storage of the poses and centres: about 1e-6 of 5 units.
    assert!(after < 1e-4, "bundle adjusted: {after} off the truth");
    assert!(
        before > 10.0 * after,
        "chained: {before}, adjusted: {after}"
    );
}

/// Every frame's prior 8 % too far: the pixels and the prior's depths fit a part 8 %
/// larger and farther just as well, and the part's size comes from the lifted
/// trajectories' depth at the middle knot (true here), not from the prior.
#[test]
fn a_prior_too_far_everywhere_does_not_move_the_part() {
    let (_, after) = bundle_case(1.08);
    assert!(after < 1e-4, "bundle adjusted: {after} off the truth");
}

/// The members of a flat part on a known motion, their lifted trajectories right at the
/// middle knot only, bundle adjusted to their true pixels and to depth priors
/// `prior_scale` times the truth; the largest distance of a member from its true path
/// over the knots, chained and adjusted.
fn bundle_case(prior_scale: f64) -> (f64, f64) {
    use gaussians::tracks::depth::Aligned;
    use gaussians::tracks::parts::{Evidence, into_parts};
    let mut r = Lcg(12);
    let times = [0.0, 0.25, 0.5, 0.75, 1.0];
    let centre = glam::DVec3::new(0.1, -0.2, -5.0);
    let truth = |a: glam::DVec3, t: f64| {
        let tau = t - 0.5;
        let q = glam::DQuat::from_rotation_z(0.4 * tau);
        q * (a - centre) + centre + glam::DVec3::new(0.6 * tau, 0.1 * tau, 0.8 * tau)
    };
    let cams: Vec<scene::Camera> = (0..5)
        .map(|k| scene::Camera {
            intrinsics: scene::Intrinsics {
                width: 96,
                height: 96,
                fx: 80.0,
                fy: 80.0,
                cx: 47.5,
                cy: 47.5,
                distortion: None,
            },
            cam_to_world: scene::Pose::new(
                glam::DQuat::IDENTITY,
                glam::DVec3::new(0.2 * k as f64 - 0.4, 0.0, 0.0),
            ),
        })
        .collect();
    let cam_refs: Vec<&scene::Camera> = cams.iter().collect();
    let points: Vec<glam::DVec3> = (0..49)
        .map(|i| {
            centre
                + glam::DVec3::new(
                    0.12 * (i % 7) as f64 - 0.36,
                    0.12 * (i / 7) as f64 - 0.36,
                    0.0,
                )
        })
        .collect();
    let mut s = Splats::default();
    let mut table = Vec::new();
    for &a in &points {
        // The quadratic through the true positions at τ = 0, ±¼, then each velocity and
        // acceleration off by up to 2 cm and 4 cm per unit time (squared).
        let (p0, pm, pp) = (truth(a, 0.5), truth(a, 0.25), truth(a, 0.75));
        let v = (pp - pm) / 0.5 + 0.02 * glam::DVec3::from_array(r.arr::<3>());
        let acc =
            (pp + pm - 2.0 * p0) / (2.0 * 0.0625) + 0.04 * glam::DVec3::from_array(r.arr::<3>());
        s.push(Gaussian::isotropic(
            p0.as_vec3().to_array(),
            -3.0,
            0.0,
            [0.0; 3],
        ));
        let n = s.len();
        s.motion.resize(n, [0.0; 6]);
        s.life.resize(n, ALWAYS);
        s.track.resize(n, 0);
        s.motion[n - 1] = [v.x, v.y, v.z, acc.x, acc.y, acc.z].map(|c| c as f32);
        s.track[n - 1] = table.len() as u32;
        table.push(
            (0..5)
                .map(|k| Some(cams[k].project_world(truth(a, times[k])).unwrap().0))
                .collect::<Vec<_>>(),
        );
    }
    let depths: Vec<Option<Aligned>> = (0..5)
        .map(|k| {
            Some(Aligned {
                width: 96,
                height: 96,
                z: vec![(-truth(centre, times[k]).z * prior_scale) as f32; 96 * 96],
                median_rel_error: 0.0,
                points: 0,
            })
        })
        .collect();
    let worst = |s: &Splats| {
        let mut w = 0.0f64;
        for (k, &t) in times.iter().enumerate() {
            let mut at = s.clone();
            parts::advance(&s.parts, &s.part, t as f32, &mut at);
            for (i, &a) in points.iter().enumerate() {
                let x = glam::Vec3::from(at.means[i]).as_dvec3();
                w = w.max(x.distance(truth(a, times[k])));
            }
        }
        w
    };
    let mut chained = s.clone();
    let sum = into_parts(&mut chained, &times, &cam_refs, 2.0, None, None);
    assert_eq!((sum.parts, sum.members), (1, 49), "{sum:?}");
    let ev = Evidence {
        table: &table,
        depths: &depths,
        depth_sigma: 0.05,
    };
    let sum = into_parts(&mut s, &times, &cam_refs, 2.0, Some(&ev), None);
    assert_eq!((sum.parts, sum.members), (1, 49), "{sum:?}");
    (worst(&chained), worst(&s))
}
