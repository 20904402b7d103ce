//! Rigid parts from the tracks init's trajectories (`tracks.parts`; [`crate::parts`]).
//!
//! The init leaves each moving track a Gaussian on a quadratic trajectory, over the
//! recording or over a window of frames. Here the moving Gaussians that lie together
//! become parts: at each train frame (a knot) the Gaussians whose trajectory was
//! fitted there (their life and one frame either side) are joined to those within
//! `PART_REACH` times the median nearest distance; a component of at least
//! `MIN_MEMBERS` is a part. Its pose at each knot is the rigid motion (Horn's method)
//! that takes its members' canonical centres (their centres at the knot nearest the
//! recording's middle, or carried there through the poses already found, knot by knot
//! outwards) onto where their trajectories put them; a member whose trajectory strays
//! from its part's motion by more than `tracks.moving_pixels` (median over its knots)
//! leaves the part and keeps its own trajectory. A group is made a part only when at
//! every knot at least a third of its members' trajectories were fitted there
//! ([`MIN_SEEN_SHARE`]): on extreme motion the tracks are windows of a few frames, and
//! a group of them chained from window to window held a mix of objects and of still
//! points, its poses at most knots guessed (BENCHMARKS.md, "Parts only where their
//! motion was seen"). With images to follow them through (`tracks.part_steps`), such a
//! group is split instead into its members living at the reference knot, joined there by
//! distance, and each component's poses come from its brightness
//! ([`super::part_motion`]). With the tracks' pixels and the depth
//! priors ([`Evidence`]), the poses and the members' canonical centres are then bundle
//! adjusted ([`super::bundle`]) to where the members were seen and to the prior's depths
//! there, a member whose median reprojection error stays over `tracks.moving_pixels`
//! leaves too, and the part is scaled about each frame's camera centre to its lifted
//! members' median depth at the reference knot (every pixel stays). The members then
//! move with their part over the whole recording (no life, no trajectory of their own).

use crate::parts::{self, NO_PART, Parts};
use crate::splats::{ALWAYS, Splats};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use scene::Camera;
use std::num::NonZeroUsize;

/// Neighbours within this many median nearest distances are joined.
const PART_REACH: f64 = 3.0;
/// Neighbours searched per Gaussian and knot.
const NEAREST: usize = 8;
/// The fewest members of a part.
const MIN_MEMBERS: usize = 12;
/// The least share of a part's members whose trajectories were fitted at each knot: a
/// part whose members were each followed over a few frames only holds poses chained
/// from window to window, and its motion at a knot few of them saw is a guess. Between
/// the groups measured (BENCHMARKS.md, "Parts only where their motion was seen"):
/// `fast` 8 fps's at most 0.26, the objects' on `rigid`, `nonrigid` and `moderate` at
/// least 0.48.
const MIN_SEEN_SHARE: f64 = 1.0 / 3.0;

/// Huber threshold of the bundle adjustment, pixels.
const HUBER_PX: f64 = 1.0;
/// Levenberg–Marquardt steps of the bundle adjustment.
const BUNDLE_STEPS: usize = 30;

/// Where the moving tracks were seen, for the bundle adjustment: `table` the tracks'
/// camera pixels per train frame (rows indexed by `Splats::track`), `depths` each
/// frame's aligned prior (empty: none), `depth_sigma` as `tracks.depth_sigma`.
pub struct Evidence<'a> {
    pub table: &'a super::loss::Table,
    pub depths: &'a [Option<super::depth::Aligned>],
    pub depth_sigma: f64,
}

/// What [`into_parts`] made.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PartsSummary {
    pub parts: usize,
    pub members: usize,
    /// Moving Gaussians left with their own trajectories.
    pub left: usize,
    /// Groups that were not made parts because at some knot under [`MIN_SEEN_SHARE`] of
    /// their members had been fitted (and, with images to follow them through, their
    /// motion was lost there).
    pub unseen: usize,
    /// Parts whose motion was followed through the images ([`super::part_motion`]):
    /// groups under `MIN_SEEN_SHARE` when the images are given.
    pub followed: usize,
}

/// Union–find with path halving.
fn find(up: &mut [usize], mut i: usize) -> usize {
    while up[i] != i {
        up[i] = up[up[i]];
        i = up[i];
    }
    i
}

/// Turn the moving Gaussians of `s` (a trajectory, [`crate::motion::has_trajectory`])
/// into rigid parts with knots at the train frames (`times` normalised, `cameras` the
/// frames'), where they group; `pixels` the largest median misfit of a member. With
/// `evidence` (and a depth row for every member on average), each part is bundle
/// adjusted to it.
pub fn into_parts(
    s: &mut Splats,
    times: &[f64],
    cameras: &[&Camera],
    pixels: f64,
    evidence: Option<&Evidence>,
    brightness: Option<&super::part_motion::Sequence>,
) -> PartsSummary {
    let n_knots = times.len();
    let movers: Vec<usize> = (0..s.len())
        .filter(|&i| s.motion.get(i).is_some_and(crate::motion::has_trajectory))
        .collect();
    if movers.len() < MIN_MEMBERS || n_knots < 2 {
        return PartsSummary {
            left: movers.len(),
            ..Default::default()
        };
    }
    let t0 = crate::motion::T0 as f64;
    let at = |i: usize, k: usize| -> [f64; 3] {
        let d = crate::motion::shift(s, i, times[k] as f32);
        std::array::from_fn(|a| s.means[i][a] as f64 + d[a] as f64)
    };
    // Knots a mover's trajectory was fitted at: its life's and one either side.
    let valid = |i: usize| -> Vec<bool> {
        let l = s.life.get(i).copied().unwrap_or(ALWAYS);
        let inside: Vec<bool> = (times.iter())
            .map(|&t| t >= l[0] as f64 - 1e-6 && t <= l[1] as f64 + 1e-6)
            .collect();
        (0..n_knots)
            .map(|k| inside[k] || (k > 0 && inside[k - 1]) || inside.get(k + 1) == Some(&true))
            .collect()
    };
    let valid: Vec<Vec<bool>> = movers.iter().map(|&i| valid(i)).collect();
    // Whether a mover's own life holds knot `k` (not only the knot either side, where
    // its trajectory is extrapolated).
    let lives = |m: usize, k: usize| {
        let l = s.life.get(movers[m]).copied().unwrap_or(ALWAYS);
        times[k] >= l[0] as f64 - 1e-6 && times[k] <= l[1] as f64 + 1e-6
    };
    let pos: Vec<Vec<[f64; 3]>> = (movers.iter())
        .map(|&i| (0..n_knots).map(|k| at(i, k)).collect())
        .collect();
    // Per knot: the movers fitted there, their nearest distances, then the joins.
    let mut up: Vec<usize> = (0..movers.len()).collect();
    let mut nearest = Vec::new();
    let mut trees = Vec::new();
    let two = NonZeroUsize::new(2).expect("2");
    for k in 0..n_knots {
        let here: Vec<usize> = (0..movers.len()).filter(|&m| valid[m][k]).collect();
        if here.len() < 2 {
            trees.push(None);
            continue;
        }
        let pts: Vec<[f64; 3]> = here.iter().map(|&m| pos[m][k]).collect();
        let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&pts).expect("finite");
        for p in &pts {
            let found = tree
                .query(p)
                .nearest_n::<SquaredEuclidean<f64>>(two)
                .execute();
            if let Some(q) = found.get(1) {
                nearest.push(q.distance.sqrt());
            }
        }
        trees.push(Some((here, pts, tree)));
    }
    nearest.sort_by(f64::total_cmp);
    let reach = PART_REACH * nearest.get(nearest.len() / 2).copied().unwrap_or(0.0);
    // Two neighbours move together: from this knot to every other knot both were
    // fitted at, their displacements differ by at most `pixels` seen from here.
    let together = |i: usize, j: usize, k: usize| {
        let Some((_, z)) = cameras[k].project_world(pos[i][k].into()) else {
            return false;
        };
        let px = cameras[k].intrinsics.fx / z.max(1e-9);
        (0..n_knots)
            .filter(|&c| c != k && valid[i][c] && valid[j][c])
            .all(|c| {
                let d: [f64; 3] = std::array::from_fn(|a| {
                    (pos[i][c][a] - pos[i][k][a]) - (pos[j][c][a] - pos[j][k][a])
                });
                (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() * px <= pixels
            })
    };
    for (k, slot) in trees.iter().enumerate() {
        if let Some((here, pts, tree)) = slot {
            join_near(&mut up, here, pts, tree, reach, |i, j| together(i, j, k));
        }
    }
    let mut groups: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for m in 0..movers.len() {
        groups.entry(find(&mut up, m)).or_default().push(m);
    }
    let reference = (0..n_knots)
        .min_by(|&a, &b| (times[a] - t0).abs().total_cmp(&(times[b] - t0).abs()))
        .expect("knots");
    let mut out = Parts {
        knots: times.iter().map(|&t| t as f32).collect(),
        fixed: reference,
        ..Default::default()
    };
    let mut member = vec![NO_PART; s.len()];
    let mut canonical = vec![[0.0f64; 3]; s.len()];
    let mut unseen = 0;
    let mut followed = 0;
    let depths: &[Option<super::depth::Aligned>] = evidence.map_or(&[], |e| e.depths);
    let seen_share = |set: &[usize]| {
        (0..n_knots).all(|k| {
            let fitted = set.iter().filter(|&&m| valid[m][k]).count();
            fitted as f64 >= MIN_SEEN_SHARE * set.len() as f64
        })
    };
    // A group seen at too few knots, with images to follow it through: its members that
    // live at the reference knot, joined there by distance alone (chained from window to
    // window, the group mixes objects; the trajectories' motion test split `fast`'s box
    // into pieces of a dozen members), each component one candidate part.
    let mut candidates: Vec<(Vec<usize>, bool)> = Vec::new();
    for (_, group) in groups {
        if group.len() < MIN_MEMBERS {
            continue;
        }
        match (brightness, &trees[reference]) {
            (Some(_), Some((here, pts, tree))) if !seen_share(&group) => {
                let inside: std::collections::HashSet<usize> = group.iter().copied().collect();
                let mut up: Vec<usize> = (0..movers.len()).collect();
                let both = |i: usize, j: usize| inside.contains(&i) && inside.contains(&j);
                join_near(&mut up, here, pts, tree, reach, both);
                let mut parts: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
                for &m in (here.iter()).filter(|&&m| inside.contains(&m) && lives(m, reference)) {
                    parts.entry(find(&mut up, m)).or_default().push(m);
                }
                candidates.extend(parts.into_values().map(|g| (g, true)));
            }
            _ => candidates.push((group, false)),
        }
    }
    for (group, by_brightness) in candidates {
        if group.len() < MIN_MEMBERS {
            continue;
        }
        let misfit = |poses: &[([f64; 4], [f64; 3])], canon: &[Option<[f64; 3]>], m: usize| {
            let Some(c) = canon[m] else {
                return f64::INFINITY;
            };
            let mut e: Vec<f64> = (0..n_knots)
                .filter(|&k| valid[m][k])
                .filter_map(|k| {
                    let (q, t) = poses[k];
                    let r = parts::rotate(q, c);
                    let x: [f64; 3] = std::array::from_fn(|a| r[a] + t[a]);
                    let a = cameras[k].project_world(x.into())?.0;
                    let b = cameras[k].project_world(pos[m][k].into())?.0;
                    Some((a - b).length())
                })
                .collect();
            e.sort_by(f64::total_cmp);
            e.get(e.len() / 2).copied().unwrap_or(f64::INFINITY)
        };
        let brightness = brightness.filter(|_| by_brightness);
        let (poses, canon) = match brightness {
            Some(seq) => match super::part_motion::group_poses(
                &group,
                &valid,
                &pos,
                reference,
                seq,
                depths,
                MIN_MEMBERS,
            ) {
                Some(pc) => pc,
                None => {
                    unseen += 1;
                    continue;
                }
            },
            None => chain(&group, &valid, &pos, reference),
        };
        // A followed part keeps every member it was followed with: their own trajectories
        // are windows of a few frames that a third of `fast`'s links put wrong, and
        // judging the members by them cost the followed parts their gain (BENCHMARKS.md,
        // "One object's motion, not a point's").
        let kept: Vec<usize> = (group.iter().copied())
            .filter(|&m| match by_brightness {
                true => canon[m].is_some(),
                false => misfit(&poses, &canon, m) <= pixels,
            })
            .collect();
        if kept.len() < MIN_MEMBERS {
            continue;
        }
        let (mut poses, mut canon) = match brightness {
            Some(_) => (poses, canon),
            None => chain(&kept, &valid, &pos, reference),
        };
        let mut kept = kept;
        if let Some(ev) = evidence.filter(|_| brightness.is_none()) {
            let track = |m: usize| {
                s.track
                    .get(movers[m])
                    .and_then(|&r| ev.table.get(r as usize))
            };
            kept.retain(|&m| track(m).is_some());
            kept = adjust(
                &kept, &track, ev, cameras, reference, pixels, &mut poses, &mut canon,
            );
            if kept.len() < MIN_MEMBERS {
                continue;
            }
        }
        if brightness.is_some() {
            followed += 1;
        } else if !seen_share(&kept) {
            unseen += 1;
            continue;
        }
        let p = out.origin.len() as u32;
        let cs: Vec<[f64; 3]> = kept.iter().filter_map(|&m| canon[m]).collect();
        let o: [f64; 3] =
            std::array::from_fn(|a| cs.iter().map(|c| c[a]).sum::<f64>() / cs.len() as f64);
        out.origin.push(o.map(|v| v as f32));
        for (q, t) in &poses {
            // x = R a + t = R(a − o) + o + T  ⇒  T = t + R o − o.
            let ro = parts::rotate(*q, o);
            out.rot.push(q.map(|v| v as f32));
            out.shift
                .push(std::array::from_fn(|a| (t[a] + ro[a] - o[a]) as f32));
        }
        for &m in &kept {
            if let Some(c) = canon[m] {
                member[movers[m]] = p;
                canonical[movers[m]] = c;
            }
        }
    }
    let members = member.iter().filter(|&&m| m != NO_PART).count();
    let summary = PartsSummary {
        parts: out.origin.len(),
        members,
        left: movers.len() - members,
        unseen,
        followed,
    };
    if members == 0 {
        return summary;
    }
    for (i, &m) in member.iter().enumerate() {
        if m != NO_PART {
            s.means[i] = canonical[i].map(|v| v as f32);
            s.motion[i] = [0.0; 6];
            if let Some(l) = s.life.get_mut(i) {
                *l = ALWAYS;
            }
        }
    }
    s.part = member;
    s.parts = out;
    summary
}

/// Joins in `up` each of the points `pts` (movers `here`) to its [`NEAREST`] neighbours
/// in `tree` within `reach` that `accept` takes.
fn join_near(
    up: &mut [usize],
    here: &[usize],
    pts: &[[f64; 3]],
    tree: &ImmutableKdTree<f64, 3>,
    reach: f64,
    accept: impl Fn(usize, usize) -> bool,
) {
    let k1 = NonZeroUsize::new(NEAREST + 1).expect("positive");
    for (a, p) in pts.iter().enumerate() {
        let found = tree
            .query(p)
            .nearest_n::<SquaredEuclidean<f64>>(k1)
            .execute();
        for q in found.iter().filter(|q| q.distance.sqrt() <= reach) {
            let (i, j) = (here[a], here[q.item as usize]);
            if i != j && accept(i, j) {
                let (x, y) = (find(up, i), find(up, j));
                up[x] = y;
            }
        }
    }
}

/// Bundle adjust one part's `poses` and its members' canonical centres `canon` (those of
/// `kept`) to `ev`, then once more without the members whose median reprojection error
/// is over `pixels`; returns the members kept. Unchanged when the members have fewer
/// depth rows than members (the scale along the rays would be free).
#[allow(clippy::too_many_arguments)]
fn adjust<'t>(
    kept: &[usize],
    track: &dyn Fn(usize) -> Option<&'t Vec<Option<glam::DVec2>>>,
    ev: &Evidence,
    cameras: &[&Camera],
    reference: usize,
    pixels: f64,
    poses: &mut [([f64; 4], [f64; 3])],
    canon: &mut [Option<[f64; 3]>],
) -> Vec<usize> {
    use super::bundle::{self, Seen};
    use glam::{DQuat, DVec3};
    let mut kept: Vec<usize> = kept
        .iter()
        .copied()
        .filter(|&m| canon[m].is_some())
        .collect();
    let seen_of = |m: usize| -> Vec<Seen> {
        let row = track(m).expect("kept members have a track");
        (row.iter().enumerate())
            .filter_map(|(k, p)| {
                let pixel = (*p)?;
                let depth = ev.depths.get(k).and_then(|d| d.as_ref()?.at(pixel));
                Some(Seen {
                    knot: k,
                    pixel,
                    depth,
                })
            })
            .collect()
    };
    let mut seen: Vec<Vec<Seen>> = kept.iter().map(|&m| seen_of(m)).collect();
    let depth_rows = seen.iter().flatten().filter(|o| o.depth.is_some()).count();
    if ev.depth_sigma <= 0.0 || depth_rows < kept.len() {
        return kept;
    }
    let mut bp: Vec<bundle::Pose> = (poses.iter())
        .map(|(q, t)| {
            (
                DQuat::from_xyzw(q[1], q[2], q[3], q[0]),
                DVec3::from_array(*t),
            )
        })
        .collect();
    let mut points: Vec<DVec3> = kept
        .iter()
        .map(|&m| DVec3::from_array(canon[m].expect("kept")))
        .collect();
    for round in 0..2 {
        let problem = bundle::Problem {
            cameras,
            seen: &seen,
            fixed: reference,
            depth_sigma: ev.depth_sigma,
            huber: HUBER_PX,
        };
        let _ = bundle::adjust(&problem, &mut bp, &mut points, BUNDLE_STEPS);
        if round == 1 {
            break;
        }
        let fit: Vec<usize> = (bundle::misfit(&problem, &bp, &points).iter().enumerate())
            .filter(|&(_, &e)| e <= pixels)
            .map(|(j, _)| j)
            .collect();
        if fit.len() == kept.len() {
            break;
        }
        kept = fit.iter().map(|&j| kept[j]).collect();
        seen = fit.iter().map(|&j| std::mem::take(&mut seen[j])).collect();
        points = fit.iter().map(|&j| points[j]).collect();
    }
    // The part's size from the lifted trajectories at the reference knot, the middle of
    // their fits: the adjustment's own distance is the prior's mean over the frames, whose
    // error is one scale per frame, and the lifts' was nearer the truth there (−1.5
    // against −3.0 % on `rigid` 4 fps's box; BENCHMARKS.md, "A bundle adjustment per
    // rigid part"). Every pixel stays. `canon` still holds the chained (lifted) centres,
    // and the pose at the reference knot is held, so depths there compare directly.
    let (q0, t0) = bp[reference];
    let depth_there = |a: DVec3| -cameras[reference].cam_to_world.to_camera(q0 * a + t0).z;
    let ratios: Vec<f64> = (kept.iter().zip(&seen).zip(&points))
        .filter(|((_, s), _)| s.iter().any(|o| o.knot == reference))
        .map(|((&m, _), &a)| {
            let lifted = DVec3::from_array(canon[m].expect("kept"));
            (depth_there(lifted) / depth_there(a)).ln()
        })
        .filter(|r| r.is_finite())
        .collect();
    let s = super::depth::median(ratios);
    if s.is_finite() {
        bundle::rescale(cameras, reference, &mut bp, &mut points, s.exp());
    }
    for (slot, (q, t)) in poses.iter_mut().zip(&bp) {
        *slot = ([q.w, q.x, q.y, q.z], t.to_array());
    }
    for (&m, a) in kept.iter().zip(&points) {
        canon[m] = Some(a.to_array());
    }
    kept
}

/// One group's pose per knot and its members' canonical centres: the identity at
/// `reference` (canonical = the centres there), then knot by knot outwards the rigid
/// motion of the members with a canonical centre onto their centres at that knot (the
/// previous knot's when fewer than three are fitted there), after which the members
/// first fitted there get their canonical centre through it.
#[allow(clippy::type_complexity)]
fn chain(
    group: &[usize],
    valid: &[Vec<bool>],
    pos: &[Vec<[f64; 3]>],
    reference: usize,
) -> (Vec<([f64; 4], [f64; 3])>, Vec<Option<[f64; 3]>>) {
    let n_knots = valid.first().map_or(0, |v| v.len());
    let mut canon: Vec<Option<[f64; 3]>> = vec![None; pos.len()];
    let mut poses = vec![([1.0, 0.0, 0.0, 0.0], [0.0; 3]); n_knots];
    for &m in group {
        if valid[m][reference] {
            canon[m] = Some(pos[m][reference]);
        }
    }
    let order = (reference + 1..n_knots)
        .map(|k| (k, k - 1))
        .chain((0..reference).rev().map(|k| (k, k + 1)));
    for (k, prev) in order {
        let (a, b): (Vec<[f64; 3]>, Vec<[f64; 3]>) = (group.iter())
            .filter(|&&m| valid[m][k])
            .filter_map(|&m| canon[m].map(|c| (c, pos[m][k])))
            .unzip();
        poses[k] = match parts::kabsch(&a, &b) {
            Some((mut q, t)) => {
                let p = poses[prev].0;
                if (0..4).map(|i| q[i] * p[i]).sum::<f64>() < 0.0 {
                    q = q.map(|v| -v);
                }
                (q, t)
            }
            None => poses[prev],
        };
        let (q, t) = poses[k];
        for &m in group {
            if canon[m].is_none() && valid[m][k] {
                let x = pos[m][k];
                canon[m] = Some(parts::rotate_back(q, std::array::from_fn(|a| x[a] - t[a])));
            }
        }
    }
    (poses, canon)
}
