//! Initial Gaussians: random points inside the region the cameras look at (Deform-GS
//! synthetic init: random points, random colours, opacity 0.1, identity rotation), and
//! the scene extent (1.1 × the largest camera-centre distance from their mean), and the
//! choice among the inits ([`initial_splats`]).

use super::settings::{Init, TrainSettings};
use super::view::View;
use crate::splats::{Gaussian, Splats};
use glam::DVec3;
use rand::{RngExt, SeedableRng};
use scene::Camera;
use scene::error::{Error, Result};
use scene::manifest::Scene;
use std::path::Path;

/// 0th-order SH constant: colour = 0.5 + C0 · dc.
pub const SH_C0: f32 = 0.282_094_8;

/// 3DGS camera extent: 1.1 × max distance of a camera centre from their mean.
pub fn camera_extent(cams: &[Camera]) -> f32 {
    let n = cams.len().max(1) as f64;
    let mean = cams.iter().map(|c| c.cam_to_world.centre()).sum::<DVec3>() / n;
    let r = cams
        .iter()
        .map(|c| (c.cam_to_world.centre() - mean).length())
        .fold(0.0, f64::max);
    (1.1 * r).max(1e-3) as f32
}

/// Box the cameras look at. Centre = the least-squares meeting point of the optical
/// axes when they converge (they span more than ~10° and meet in front of every camera);
/// for nearly parallel axes (cameras along one short path looking the same way) that
/// point is ill-conditioned and can sit anywhere along the axes, so the centre is then
/// the point of the mean optical axis nearest the world origin (where normalised
/// datasets put the scene), or 1 unit ahead when the origin is behind the cameras.
/// Half-size = the smallest camera distance to the centre × tan(half the horizontal
/// FOV), so every camera sees the whole box. Returns (centre, half-size).
pub fn camera_bounds(cams: &[Camera]) -> (DVec3, f64) {
    let mut a = glam::DMat3::ZERO;
    let mut b = DVec3::ZERO;
    let (mut mean_o, mut mean_d) = (DVec3::ZERO, DVec3::ZERO);
    for c in cams {
        let o = c.cam_to_world.centre();
        let d = (c.cam_to_world.rotation * DVec3::NEG_Z).normalize();
        // Σ (I − d dᵀ) x = Σ (I − d dᵀ) o
        let p = glam::DMat3::IDENTITY - glam::DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += p;
        b += p * o;
        mean_o += o;
        mean_d += d;
    }
    let n = cams.len().max(1) as f64;
    mean_o /= n;
    mean_d = mean_d.normalize_or(DVec3::NEG_Z);
    // The smallest eigenvalue of Σ(I − d dᵀ)/n is ≈ sin² of the axes' angular spread
    // (0 for parallel axes); its inverse bounds how far noise moves the solution.
    let min_eig = smallest_eigenvalue(a / n);
    let meet = (min_eig > (10f64.to_radians().sin() * 0.5).powi(2))
        .then(|| a.inverse() * b)
        .filter(|x| {
            x.is_finite()
                && cams.iter().all(|c| {
                    let d = c.cam_to_world.rotation * DVec3::NEG_Z;
                    (*x - c.cam_to_world.centre()).dot(d) > 0.0
                })
        });
    let centre = meet.unwrap_or_else(|| {
        let ahead = (-mean_o).dot(mean_d);
        mean_o + mean_d * if ahead > 1e-3 { ahead } else { 1.0 }
    });
    let half = cams
        .iter()
        .map(|c| (c.cam_to_world.centre() - centre).length() * (c.intrinsics.fov_x() * 0.5).tan())
        .fold(f64::INFINITY, f64::min);
    (
        centre,
        if half.is_finite() && half > 0.0 {
            half
        } else {
            1.0
        },
    )
}

/// Smallest eigenvalue of a symmetric 3×3 matrix (closed form, trigonometric).
fn smallest_eigenvalue(m: glam::DMat3) -> f64 {
    let e = |i: usize, j: usize| m.col(j)[i];
    let p1 = e(0, 1).powi(2) + e(0, 2).powi(2) + e(1, 2).powi(2);
    let q = (e(0, 0) + e(1, 1) + e(2, 2)) / 3.0;
    if p1 < 1e-30 {
        return e(0, 0).min(e(1, 1)).min(e(2, 2));
    }
    let p2 = (e(0, 0) - q).powi(2) + (e(1, 1) - q).powi(2) + (e(2, 2) - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    let bm = (m - glam::DMat3::IDENTITY * q) * (1.0 / p);
    let r = (bm.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos()
}

/// `n` random Gaussians uniform in the cube `centre ± half`. The scale is the expected
/// nearest-neighbour distance of `n` uniform points (≈ 0.55·(V/n)^{1/3}), standing in
/// for 3DGS's mean distance to 3 nearest neighbours.
pub fn random_splats(n: usize, centre: DVec3, half: f64, seed: u64) -> Splats {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let spacing = 0.55 * ((2.0 * half).powi(3) / n.max(1) as f64).cbrt();
    let ls = (spacing as f32).ln();
    let opacity = (0.1f32 / 0.9).ln();
    let mut s = Splats::with_capacity(n);
    for _ in 0..n {
        let p: [f32; 3] =
            std::array::from_fn(|k| (centre[k] + half * rng.random_range(-1.0..1.0)) as f32);
        let sh_dc = std::array::from_fn(|_| (rng.random_range(0.0f32..1.0) - 0.5) / SH_C0);
        s.push(Gaussian {
            dynamic: true,
            ..Gaussian::isotropic(p, ls, opacity, sh_dc)
        });
    }
    s
}

/// `n` random Gaussians inside the train cameras' viewing frusta: a random camera, a
/// random pixel ray, a depth uniform in `[near, far]` (`near`/`far` = `near_frac`/
/// `far_frac` × the camera's distance to the [`camera_bounds`] centre). Covers what the
/// cameras see (walls and floors beyond the box included) with no geometry known.
/// Scale: expected nearest-neighbour spacing of `n` points in one frustum.
pub(crate) fn frustum_splats(
    cams: &[Camera],
    n: usize,
    near_frac: f64,
    far_frac: f64,
    seed: u64,
) -> Splats {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (centre, _) = camera_bounds(cams);
    let opacity = (0.1f32 / 0.9).ln();
    let mut s = Splats::default();
    if cams.is_empty() {
        return s;
    }
    let c0 = &cams[0];
    let d0 = (c0.cam_to_world.centre() - centre).length().max(1e-3);
    let (near0, far0) = (near_frac * d0, far_frac * d0);
    let i0 = &c0.intrinsics;
    let (tx, ty) = (
        i0.width as f64 / (2.0 * i0.fx),
        i0.height as f64 / (2.0 * i0.fy),
    );
    let volume = 4.0 * tx * ty * (far0.powi(3) - near0.powi(3)) / 3.0;
    let ls = ((0.55 * (volume / n.max(1) as f64).cbrt()) as f32).ln();
    for _ in 0..n {
        let cam = &cams[rng.random_range(0..cams.len())];
        let d = (cam.cam_to_world.centre() - centre).length().max(1e-3);
        let i = &cam.intrinsics;
        let px = glam::DVec2::new(
            rng.random_range(0.0..i.width as f64),
            rng.random_range(0.0..i.height as f64),
        );
        let depth = rng.random_range(near_frac * d..far_frac * d);
        let p = cam.unproject_world(px, depth);
        let mean = [p.x as f32, p.y as f32, p.z as f32];
        let sh_dc = std::array::from_fn(|_| (rng.random_range(0.0f32..1.0) - 0.5) / SH_C0);
        s.push(Gaussian {
            dynamic: true,
            ..Gaussian::isotropic(mean, ls, opacity, sh_dc)
        });
    }
    s
}

/// Up to `n` initial Gaussians from plane-sweep stereo over the train views
/// ([`super::stereo`]), plus `random_fraction · n` random [`frustum_splats`] (all `n`
/// random when stereo finds no point). Stereo points keep their colour (SH DC), opacity
/// 0.1, and a footprint of the pixel spacing the sampling leaves at their depth. Returns
/// the Gaussians and how many of them came from stereo.
pub fn stereo_splats(
    views: &[super::View],
    n: usize,
    near_frac: f64,
    far_frac: f64,
    st: &super::stereo::StereoSettings,
    seed: u64,
) -> (Splats, usize) {
    use super::stereo::{StereoView, stereo_points};
    let cams: Vec<Camera> = views.iter().map(|v| v.camera).collect();
    if cams.is_empty() {
        return (Splats::default(), 0);
    }
    let (centre, _) = camera_bounds(&cams);
    let d = cams
        .iter()
        .map(|c| (c.cam_to_world.centre() - centre).length())
        .sum::<f64>()
        / cams.len() as f64;
    let d = d.max(1e-3);
    let sv: Vec<StereoView> = views
        .iter()
        .map(|v| StereoView {
            camera: &v.camera,
            rgb: &v.rgb,
        })
        .collect();
    let mut pts = stereo_points(&sv, near_frac * d, far_frac * d, st);
    // Random points only where stereo found nothing at all: floaters cost more than the
    // holes they would fill (measured, BENCHMARKS.md).
    let n_random = if pts.is_empty() {
        n
    } else {
        (n as f64 * st.random_fraction).round() as usize
    };
    let n_stereo = n - n_random.min(n);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x5757);
    // Partial Fisher–Yates: a uniform sample of `n_stereo` points.
    for i in 0..n_stereo.min(pts.len()) {
        let j = rng.random_range(i..pts.len());
        pts.swap(i, j);
    }
    pts.truncate(n_stereo);
    let found = pts.len();
    let mut s = frustum_splats(&cams, n_random.min(n), near_frac, far_frac, seed);
    // Pixels per sampled point in one view, so neighbouring Gaussians just touch.
    let k = &cams[0].intrinsics;
    let swept = views.len().min(st.max_reference_views);
    let px_spacing = ((k.width as f64 * k.height as f64 * swept as f64) / found.max(1) as f64)
        .sqrt()
        .max(1.0) as f32;
    let opacity = (0.1f32 / 0.9).ln();
    for p in pts {
        let scale = 0.5 * p.depth / p.focal * px_spacing;
        let sh_dc = p.colour.map(|c| (c - 0.5) / SH_C0);
        s.push(Gaussian {
            dynamic: true,
            ..Gaussian::isotropic(p.position, scale.max(1e-6).ln(), opacity, sh_dc)
        });
    }
    (s, found)
}

/// What the init made ([`initial_splats`]).
pub(crate) struct Initial {
    pub splats: Splats,
    /// Gaussians placed on surfaces (PLY points, stereo points, moving tracks).
    pub surface_points: usize,
    /// Fully transparent PLY Gaussians dropped (0 without a PLY).
    pub dropped_transparent: usize,
    /// What the tracks init did (`init = "tracks"`, the default's choice).
    pub tracks: Option<TracksSummary>,
    /// What a user must know about the result ([`prior_warnings`]).
    pub warnings: Vec<String>,
}

/// What the tracks init did, for the report: the moving Gaussians it placed, the rigid
/// parts it made of them, and the train frames whose depth prior it used.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct TracksSummary {
    /// Gaussians placed on moving tracks' trajectories.
    pub moving: usize,
    /// The largest share of a reference frame's track starts that became moving
    /// Gaussians (of the middle frame's, and of each window's with `tracks.window`).
    pub moving_share: f64,
    /// Rigid parts made of them (`tracks.parts`), their members, and the groups turned
    /// away because too few of their members were followed at some frame (or, with
    /// `tracks.part_steps`, because their motion was lost in the images).
    pub parts: usize,
    pub part_members: usize,
    pub groups_not_parts: usize,
    /// Of the parts, those whose motion was followed through the images
    /// (`tracks.part_steps`).
    pub parts_followed: usize,
    /// Train frames whose depth prior was aligned to the still scene and used.
    pub prior_frames: usize,
    pub train_frames: usize,
}

/// The share of a reference frame's track starts that must lift to moving Gaussians for
/// the scene to count as having moving objects ([`prior_warnings`]): still scenes
/// measured 0.4–0.6 % (drifting tracks on the floor and wall, `static` at 48², 64² and
/// 96²), scenes with moving objects 2.9–6.2 % (`rigid` at 64², every preset at 96²).
pub const MOVING_SHARE: f64 = 0.015;

/// The warnings of a tracks init that placed `moving` Gaussians on moving tracks (at
/// most `share` of a reference frame's track starts), with `prior_frames` frames' depth
/// priors used; `has_priors`: the scene brought maps at all. One moving camera cannot
/// tell a moving object's distance (DESIGN.md §5, "Depth priors"), so without a prior the
/// moving objects are placed at a guess and a new viewpoint shows it. A few drifting
/// tracks on a still scene (under [`MOVING_SHARE`]) are not moving objects.
pub fn prior_warnings(
    moving: usize,
    share: f64,
    has_priors: bool,
    prior_frames: usize,
) -> Vec<String> {
    if share < MOVING_SHARE || prior_frames > 0 {
        return Vec::new();
    }
    let (why, fix) = if has_priors {
        (
            "the scene's depth priors (depth/) were not used: no frame's map agreed with the \
             still scene (its median error over tracks.depth_sigma, or tracks.depth_sigma = 0)",
            "Check depth/depth.json's kind against what the maps hold (the log's \"depth \
             prior:\" line gives each frame's error against the still scene).",
        )
    } else {
        (
            "the scene has no depth priors (depth/<image stem>.exr and depth/depth.json)",
            "A monocular depth network's output in depth/ fixes it (Depth Anything's is kind \
             \"inverse_affine\"; README, \"Scene layout\").",
        )
    };
    vec![format!(
        "{moving} Gaussians of moving objects ({:.1} % of a frame's tracks) were placed \
         without a depth prior: {why}. \
         One moving camera cannot tell how far a moving object is (measured 15-65 % too \
         near at DAVIS346 size), so from viewpoints off the recorded path the moving \
         objects will be misplaced and smeared, though the recorded views look right. {fix}",
        100.0 * share
    )]
}

/// Initial Gaussians: the PLY if given (all flagged dynamic), else as `settings.init`
/// says; the moving tracks' term into `tracks` (`init = "tracks"`).
pub(crate) fn initial_splats(
    settings: &TrainSettings,
    views: &[View],
    ply: Option<&Path>,
    tracks: &mut crate::tracks::loss::TrackTerm,
    scene: &Scene,
) -> Result<Initial> {
    match ply {
        Some(p) => {
            let r = crate::ply::read_counted(p)?;
            let mut s = r.splats;
            if s.is_empty() {
                return Err(Error::invalid(p, "the point cloud has no Gaussians"));
            }
            s.dynamic = vec![true; s.len()];
            Ok(Initial {
                surface_points: s.len(),
                splats: s,
                dropped_transparent: r.dropped_transparent,
                tracks: None,
                warnings: Vec::new(),
            })
        }
        None => {
            let cams: Vec<_> = views.iter().map(|v| v.camera).collect();
            let n = settings.init_points;
            let (near, far) = (settings.init_near, settings.init_far);
            let priors = match settings.init {
                Init::Auto | Init::Tracks => scene::depth_prior::load(&scene.root, &scene.train)?,
                _ => None,
            };
            let (mut summary, mut warnings) = (None, Vec::new());
            let (splats, surface) = match settings.init.resolve() {
                Init::Auto | Init::Stereo => {
                    stereo_splats(views, n, near, far, &settings.stereo, settings.seed)
                }
                Init::Tracks => {
                    let (mut s, found) =
                        stereo_splats(views, n, near, far, &settings.stereo, settings.seed);
                    let images: Vec<_> = (views.iter())
                        .map(|v| crate::tracks::Image {
                            camera: &v.camera,
                            time: v.time as f64,
                            rgb: &v.rgb,
                        })
                        .collect();
                    let stream = event_stream(settings, scene)?;
                    let seconds: Vec<f64> =
                        scene.train.frames.iter().map(|f| f.timestamp).collect();
                    let source = stream
                        .as_ref()
                        .map(|ev| crate::tracks::events::EventSource {
                            events: ev.as_slice(),
                            seconds: &seconds,
                            contrast: scene.contrast_threshold() as f32,
                            srgb: scene.train.frames_srgb(),
                            steps: settings.tracks.event_steps as usize,
                        });
                    let k = &cams[0].intrinsics;
                    let stride = (settings.tracks).stride_for(k.width as usize, k.height as usize);
                    let st = crate::tracks::TrackSettings {
                        window: settings.tracks.window_frames(&seconds),
                        ..settings.tracks
                    };
                    if st.window > 0 {
                        eprintln!(
                            "tracks: windows of {} frames ({:?} handover)",
                            st.window, st.handover
                        );
                    }
                    let (table, aligned, moving_share) = crate::tracks::add_moving(
                        &mut s,
                        &images,
                        stride,
                        &st,
                        priors.as_ref(),
                        source.as_ref(),
                    );
                    let moving = table.len();
                    let prior_frames = aligned.iter().flatten().count();
                    let mut sum = TracksSummary {
                        moving,
                        moving_share,
                        prior_frames,
                        train_frames: views.len(),
                        ..TracksSummary::default()
                    };
                    warnings = prior_warnings(moving, moving_share, priors.is_some(), prior_frames);
                    for w in &warnings {
                        eprintln!("warning: {w}");
                    }
                    if st.parts {
                        let times: Vec<f64> = images.iter().map(|v| v.time).collect();
                        let cams: Vec<&scene::Camera> = images.iter().map(|v| v.camera).collect();
                        let evidence = crate::tracks::parts::Evidence {
                            table: &table,
                            depths: &aligned,
                            depth_sigma: st.depth_sigma,
                        };
                        let sequence = (st.part_steps > 0)
                            .then(|| part_sequence(&images, &cams, source.as_ref(), st.part_steps));
                        let p = crate::tracks::parts::into_parts(
                            &mut s,
                            &times,
                            &cams,
                            st.moving_pixels,
                            st.bundle.then_some(&evidence),
                            sequence.as_ref(),
                        );
                        eprintln!(
                            "tracks: {} rigid parts of {} Gaussians; {} moving Gaussians keep their own trajectories",
                            p.parts, p.members, p.left
                        );
                        if p.followed > 0 {
                            eprintln!(
                                "tracks: {} of the parts followed as rigid bodies through the images (members followed at too few frames)",
                                p.followed
                            );
                        }
                        if p.unseen > 0 {
                            eprintln!(
                                "tracks: {} groups not made parts: at some frame under a third of their members had been followed",
                                p.unseen
                            );
                        }
                        (sum.parts, sum.part_members) = (p.parts, p.members);
                        sum.groups_not_parts = p.unseen;
                        sum.parts_followed = p.followed;
                    }
                    summary = Some(sum);
                    *tracks = crate::tracks::loss::TrackTerm::new(table);
                    tracks.priors = crate::tracks::prior_loss::PriorTerm::new(aligned);
                    (s, found + moving)
                }
                Init::Frustum => (frustum_splats(&cams, n, near, far, settings.seed), 0),
                Init::Box => {
                    let (centre, half) = camera_bounds(&cams);
                    (random_splats(n, centre, half, settings.seed), 0)
                }
            };
            Ok(Initial {
                splats,
                surface_points: surface,
                dropped_transparent: 0,
                tracks: summary,
                warnings,
            })
        }
    }
}

/// The train frames and `steps` event images per interval between them (`source`'s
/// events; the frames alone without), for parts to be followed through.
fn part_sequence(
    images: &[crate::tracks::Image],
    cams: &[&scene::Camera],
    source: Option<&crate::tracks::events::EventSource>,
    steps: u32,
) -> crate::tracks::part_motion::Sequence {
    use crate::tracks::lk::Grey;
    let k = &cams[0].intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    let grey: Vec<Grey> = images
        .iter()
        .map(|v| Grey::from_planar(v.rgb, w, h))
        .collect();
    let between = match source {
        Some(src) => crate::tracks::events::between(
            &grey,
            &crate::tracks::events::EventSource {
                steps: steps as usize,
                ..*src
            },
        ),
        None => Vec::new(),
    };
    crate::tracks::part_motion::Sequence::new(grey, between, cams)
}

/// Whether the init reads the scene's events: the tracks init (no PLY given), chaining
/// its tracks through event images (`tracks.event_steps` > 0) or following parts through
/// them (`tracks.part_steps` > 0 with `tracks.parts`), on a scene with events.
/// The stage hashes the events into its record's inputs by this same answer.
pub(crate) fn reads_events(settings: &TrainSettings, scene: &Scene, ply: Option<&Path>) -> bool {
    let tr = &settings.tracks;
    ply.is_none()
        && (tr.event_steps > 0 || (tr.parts && tr.part_steps > 0))
        && scene.train.events.is_some()
        && settings.init.resolve() == Init::Tracks
}

/// The scene's events when [`reads_events`] says the init reads them.
fn event_stream(settings: &TrainSettings, scene: &Scene) -> Result<Option<scene::EventStream>> {
    if !reads_events(settings, scene, None) {
        return Ok(None);
    }
    Ok(Some(scene.load_events()?))
}
