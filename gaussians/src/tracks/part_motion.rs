//! The rigid motion of a group of 3D points from one image to the next, found from the
//! brightness under all of them at once (issue #30, `fast`): an object's motion, not a
//! point's. A point tracker's small window on a striped, turning box sees texture in
//! one direction only and a pattern that turns under it; even through perfect images it
//! loses 40 % of the box's links (`examples/track_ceiling.rs`). Six parameters shared by
//! a few hundred points are held by every direction the object's texture has.
//!
//! The motion moves a point `x` to `R(ω)·(x − c) + c + v` (`c` the points' centroid):
//! Gauss–Newton on `Σ ρ(I_b(π_b(x')) − I_a(π_a(x)))`, `ρ` Huber, coarse to fine over
//! the pyramids, each residual's Jacobian the image gradient times the projection's
//! (central differences of [`Camera::project_world`]) times the motion's.

use super::bundle::cholesky_solve;
use super::lk::{Grey, Pyramid};
use glam::{DQuat, DVec2, DVec3};
use scene::Camera;

/// Pyramid levels of the images a part is followed through: a coarser level blurs a
/// part of ~20 pixels into its background, whose motion (the camera's) then pulls the
/// part's (`examples/track_ceiling.rs`, `fast` 8 fps's box: 3 of 102 links right
/// through three levels, 102 through one or two).
pub const LEVELS: usize = 2;
/// Half-size of the window (pixels) each member of a part stands for.
pub const PATCH_RADIUS: i32 = 3;
/// Huber threshold on a brightness residual (the images' units).
const HUBER: f64 = 0.05;
/// Gauss–Newton steps per pyramid level.
const STEPS: usize = 15;
/// The fewest points that must project into both images.
pub const MIN_POINTS: usize = 12;

/// A rigid motion about `centre`: `x ↦ rot·(x − centre) + centre + shift`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motion {
    pub rot: DQuat,
    pub shift: DVec3,
    pub centre: DVec3,
}

impl Motion {
    pub fn identity(centre: DVec3) -> Motion {
        Motion {
            rot: DQuat::IDENTITY,
            shift: DVec3::ZERO,
            centre,
        }
    }

    pub fn apply(&self, x: DVec3) -> DVec3 {
        self.rot * (x - self.centre) + self.centre + self.shift
    }

    /// `δ = (ω, v)` applied after `self`, about where `self` took the centre.
    fn then(&self, d: &[f64; 6]) -> Motion {
        let w = DVec3::new(d[0], d[1], d[2]);
        let r = DQuat::from_scaled_axis(w);
        // x ↦ r·(m(x) − m(c)) + m(c) + v, with m(c) = c + shift.
        Motion {
            rot: (r * self.rot).normalize(),
            shift: self.shift + DVec3::new(d[3], d[4], d[5]),
            centre: self.centre,
        }
    }
}

/// The image's coordinates (pixel centres at `+½`) of world point `x` at pyramid level
/// `l`, with its camera depth.
fn image_point(cam: &Camera, x: DVec3, l: usize) -> Option<DVec2> {
    let (q, z) = cam.project_world(x)?;
    (z > 0.0).then(|| (q + DVec2::splat(0.5)) / (1u32 << l) as f64)
}

fn sample(g: &Grey, q: DVec2) -> f64 {
    g.at(q.x as f32, q.y as f32) as f64
}

fn inside(g: &Grey, q: DVec2) -> bool {
    q.x >= 1.0 && q.y >= 1.0 && q.x <= g.width as f64 - 1.0 && q.y <= g.height as f64 - 1.0
}

/// Huber loss of a residual.
fn huber(e: f64) -> f64 {
    match e.abs() <= HUBER {
        true => 0.5 * e * e,
        false => HUBER * (e.abs() - 0.5 * HUBER),
    }
}

/// The points' reference brightness in `ga` (`None` outside it).
fn references(ga: &Grey, ca: &Camera, xs: &[DVec3], l: usize) -> Vec<Option<f64>> {
    (xs.iter())
        .map(|&x| {
            image_point(ca, x, l)
                .filter(|&q| inside(ga, q))
                .map(|q| sample(ga, q))
        })
        .collect()
}

/// The robust cost of motion `m` and the number of points it keeps inside `gb`.
fn cost(
    gb: &Grey,
    cb: &Camera,
    xs: &[DVec3],
    refs: &[Option<f64>],
    m: &Motion,
    l: usize,
) -> (f64, usize) {
    let mut c = 0.0;
    let mut used = 0;
    for (&x, r) in xs.iter().zip(refs) {
        let Some(va) = r else { continue };
        let Some(q) = image_point(cb, m.apply(x), l).filter(|&q| inside(gb, q)) else {
            continue;
        };
        used += 1;
        c += huber(sample(gb, q) - va);
    }
    (c, used)
}

/// The Gauss–Newton normal equations (6 × 6 row-major, right side) of motion `m`'s
/// update, Huber weights (IRLS).
fn normal_equations(
    gb: &Grey,
    cb: &Camera,
    xs: &[DVec3],
    refs: &[Option<f64>],
    m: &Motion,
    l: usize,
) -> (Vec<f64>, Vec<f64>) {
    let mc = m.apply(m.centre);
    let mut h = vec![0.0f64; 36];
    let mut g = vec![0.0f64; 6];
    for (&x, r) in xs.iter().zip(refs) {
        let Some(va) = r else { continue };
        let y = m.apply(x);
        let Some(q) = image_point(cb, y, l).filter(|&q| inside(gb, q)) else {
            continue;
        };
        let e = sample(gb, q) - va;
        let grad = DVec2::new(
            0.5 * (sample(gb, q + DVec2::X) - sample(gb, q - DVec2::X)),
            0.5 * (sample(gb, q + DVec2::Y) - sample(gb, q - DVec2::Y)),
        );
        // dq/dy by central differences; dI/dy = ∇I · dq/dy.
        let eps = 1e-4 * (1.0 + y.length());
        let di = [DVec3::X, DVec3::Y, DVec3::Z].map(|e3| {
            match (
                image_point(cb, y + eps * e3, l),
                image_point(cb, y - eps * e3, l),
            ) {
                (Some(p), Some(n)) => grad.dot((p - n) / (2.0 * eps)),
                _ => 0.0,
            }
        });
        let di = DVec3::from_array(di);
        // The update moves y to r(ω)·(y − m(c)) + m(c) + v: dy/dω_k = e_k × (y − m(c)),
        // so dI/dω = (y − m(c)) × dI/dy, and dI/dv = dI/dy.
        let jw = (y - mc).cross(di);
        let j = [jw.x, jw.y, jw.z, di.x, di.y, di.z];
        let w = if e.abs() <= HUBER {
            1.0
        } else {
            HUBER / e.abs()
        };
        for s in 0..6 {
            g[s] -= w * j[s] * e;
            for t in 0..6 {
                h[s * 6 + t] += w * j[s] * j[t];
            }
        }
    }
    (h, g)
}

/// The motion taking the world points `xs`, seen through `ca` in `a`, to where `cb` sees
/// the same brightness in `b`, refined from `start` (Levenberg–Marquardt: a step is
/// kept only when it lowers the cost). `None` when fewer than [`MIN_POINTS`] points fall
/// inside both images.
pub fn step(
    a: &Pyramid,
    b: &Pyramid,
    ca: &Camera,
    cb: &Camera,
    xs: &[DVec3],
    start: Motion,
) -> Option<Motion> {
    let levels = a.0.len().min(b.0.len());
    let mut m = start;
    for l in (0..levels).rev() {
        let (ga, gb) = (&a.0[l], &b.0[l]);
        let refs = references(ga, ca, xs, l);
        let (mut now, used) = cost(gb, cb, xs, &refs, &m, l);
        if used < MIN_POINTS {
            return None;
        }
        let mut lambda = 1e-3;
        for _ in 0..STEPS {
            let (h, g) = normal_equations(gb, cb, xs, &refs, &m, l);
            let mut kept = false;
            while lambda < 1e6 {
                let mut hd = h.clone();
                for s in 0..6 {
                    hd[s * 6 + s] += lambda * h[s * 6 + s] + 1e-12;
                }
                let Some(d) = cholesky_solve(hd, g.clone(), 6) else {
                    lambda *= 10.0;
                    continue;
                };
                let d: [f64; 6] = d.try_into().expect("six");
                let next = m.then(&d);
                let (c, used) = cost(gb, cb, xs, &refs, &next, l);
                if used >= MIN_POINTS && c < now {
                    (m, now, kept) = (next, c, true);
                    lambda = (lambda * 0.1).max(1e-6);
                    break;
                }
                lambda *= 10.0;
            }
            if !kept {
                break;
            }
        }
    }
    Some(m)
}

/// The images a part is followed through over the whole recording: each train frame
/// and the event images between it and the next ([`super::events`]), with the camera at
/// each image's time (the poses interpolated between the frames').
pub struct Sequence {
    pub images: Vec<Pyramid>,
    pub cameras: Vec<Camera>,
    /// Index into `images` of each train frame.
    pub frame_at: Vec<usize>,
}

impl Sequence {
    /// `grey` one image per train frame, `between[k]` the event images between frames
    /// `k` and `k + 1` (empty: the frames alone), `cameras` the frames'.
    pub fn new(grey: Vec<Grey>, between: Vec<Vec<Grey>>, cameras: &[&Camera]) -> Sequence {
        let mut seq = Sequence {
            images: Vec::new(),
            cameras: Vec::new(),
            frame_at: Vec::new(),
        };
        let mut between = between.into_iter();
        for (k, g) in grey.into_iter().enumerate() {
            seq.frame_at.push(seq.images.len());
            seq.images.push(Pyramid::new(g, LEVELS));
            seq.cameras.push(*cameras[k]);
            let inner = between.next().unwrap_or_default();
            let n = inner.len();
            for (j, g) in inner.into_iter().enumerate() {
                let s = (j + 1) as f64 / (n + 1) as f64;
                let (a, b) = (cameras[k], cameras[(k + 1).min(cameras.len() - 1)]);
                seq.images.push(Pyramid::new(g, LEVELS));
                seq.cameras.push(Camera {
                    intrinsics: a.intrinsics,
                    cam_to_world: scene::Pose::interpolate(&a.cam_to_world, &b.cam_to_world, s),
                });
            }
        }
        seq
    }
}

/// The rigid motion of the points `xs` (world, at train frame `reference`) to each image
/// of `seq`, followed image by image forwards and backwards from it (each step started at
/// rest: a start at the previous step's motion lost `fast`'s box); `None` when a step is
/// lost (too few points inside the images). At each train frame `k` the motion so far is replaced
/// by `fix(k, motion)` (a depth prior's distance: images pin a small body's distance
/// along the rays only through its size). [`at_frames`] picks the train frames' motions.
pub fn follow(
    seq: &Sequence,
    xs: &[DVec3],
    reference: usize,
    fix: &dyn Fn(usize, &Motion) -> Motion,
) -> Option<Vec<Motion>> {
    let centroid = xs.iter().sum::<DVec3>() / xs.len().max(1) as f64;
    let mut out = vec![Motion::identity(centroid); seq.images.len()];
    let from = seq.frame_at[reference];
    for forward in [true, false] {
        let mut total = Motion::identity(centroid);
        let mut ys = xs.to_vec();
        let mut i = from;
        loop {
            let j = match forward {
                true if i + 1 < seq.images.len() => i + 1,
                false if i > 0 => i - 1,
                _ => break,
            };
            let c = total.apply(centroid);
            let m = step(
                &seq.images[i],
                &seq.images[j],
                &seq.cameras[i],
                &seq.cameras[j],
                &ys,
                Motion::identity(c),
            )?;
            // m ∘ total, about the centroid.
            total = Motion {
                rot: (m.rot * total.rot).normalize(),
                shift: m.apply(c) - centroid,
                centre: centroid,
            };
            if let Some(k) = seq.frame_at.iter().position(|&f| f == j) {
                total = fix(k, &total);
            }
            ys.iter_mut()
                .zip(xs)
                .for_each(|(y, &x)| *y = total.apply(x));
            i = j;
            out[i] = total;
        }
    }
    Some(out)
}

/// The motions of [`follow`] at the train frames.
pub fn at_frames(seq: &Sequence, motions: &[Motion]) -> Vec<Motion> {
    seq.frame_at.iter().map(|&i| motions[i]).collect()
}

/// A group's poses per knot and its members' canonical centres from the images
/// ([`follow`]): the members fitted at `reference` are followed as
/// one rigid body from their centres there (their canonical centres); the others get
/// none. `None` when the motion is lost or fewer than `min_members` were fitted there.
/// (`valid[m][k]`: member `m`'s trajectory was fitted at knot `k`; `pos[m][k]` its centre
/// there, as `parts::into_parts` holds them.)
#[allow(clippy::type_complexity)]
pub(crate) fn group_poses(
    group: &[usize],
    valid: &[Vec<bool>],
    pos: &[Vec<[f64; 3]>],
    reference: usize,
    seq: &Sequence,
    depths: &[Option<super::depth::Aligned>],
    min_members: usize,
) -> Option<(Vec<([f64; 4], [f64; 3])>, Vec<Option<[f64; 3]>>)> {
    use glam::DVec3;
    let here: Vec<usize> = group
        .iter()
        .copied()
        .filter(|&m| valid[m][reference])
        .collect();
    if here.len() < min_members {
        return None;
    }
    // Each member stands for the window around its pixel at the reference frame, a
    // patch facing the camera at its depth: a dozen members alone would be a dozen
    // brightness samples for six unknowns.
    let cam = &seq.cameras[seq.frame_at[reference]];
    let r = PATCH_RADIUS;
    let patch = |m: usize| -> Vec<DVec3> {
        let Some((q, z)) = cam.project_world(DVec3::from_array(pos[m][reference])) else {
            return Vec::new();
        };
        (-r..=r)
            .flat_map(|j| (-r..=r).map(move |i| glam::DVec2::new(i as f64, j as f64)))
            .map(|d| cam.unproject_world(q + d, z))
            .collect()
    };
    let patches: Vec<Vec<DVec3>> = here.iter().map(|&m| patch(m)).collect();
    let xs: Vec<DVec3> = patches.iter().flatten().copied().collect();
    // At each train frame with an aligned prior, the body is moved along the ray of its
    // centroid to the prior's median distance under its members.
    let centres: Vec<DVec3> = here
        .iter()
        .map(|&m| DVec3::from_array(pos[m][reference]))
        .collect();
    let fix = |k: usize, m: &Motion| -> Motion {
        let Some(Some(d)) = depths.get(k) else {
            return *m;
        };
        let cam = &seq.cameras[seq.frame_at[k]];
        let mut ratios: Vec<f64> = (centres.iter())
            .filter_map(|&x| {
                let (q, z) = cam.project_world(m.apply(x))?;
                Some(d.at(q)? / z)
            })
            .filter(|r| r.is_finite() && *r > 0.0)
            .collect();
        if ratios.len() < min_members {
            return *m;
        }
        ratios.sort_by(f64::total_cmp);
        let s = ratios[ratios.len() / 2];
        let eye = cam.cam_to_world.centre();
        let g = m.apply(m.centre);
        Motion {
            shift: m.shift + (eye + s * (g - eye) - g),
            ..*m
        }
    };
    let motions = follow(seq, &xs, reference, &fix)?;
    let motions = at_frames(seq, &motions);
    let mut canon: Vec<Option<[f64; 3]>> = vec![None; pos.len()];
    for &m in &here {
        canon[m] = Some(pos[m][reference]);
    }
    // x ↦ R(x − c) + c + v  is  x ↦ R x + (c + v − R c).
    let mut poses: Vec<([f64; 4], [f64; 3])> = Vec::with_capacity(motions.len());
    for m in &motions {
        let t = m.centre + m.shift - m.rot * m.centre;
        let mut q = [m.rot.w, m.rot.x, m.rot.y, m.rot.z];
        // One hemisphere from knot to knot, as `chain` keeps it.
        if let Some((p, _)) = poses.last()
            && (0..4).map(|i| q[i] * p[i]).sum::<f64>() < 0.0
        {
            q = q.map(|v| -v);
        }
        poses.push((q, t.to_array()));
    }
    Some((poses, canon))
}
