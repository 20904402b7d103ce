//! `deform` — the joint training stage of degs (DEGS §3.4–3.5, DESIGN §5): after the
//! RGB warm-up, the dynamic Gaussians are trained with the RGB loss plus an event loss
//! (pseudo images from the event generation model) and a motion loss (per-event flow
//! against ego-motion + Gaussian scene flow), while a PoseNet corrects the camera path.
//!
//! **What is here now: the math kernels**, each with a hand-written backward checked
//! against central finite differences in `f64` (the kernels are generic over
//! [`scene::real::Real`], i.e. `f32` for training and `f64` for the checks):
//!
//! | module | computes |
//! |---|---|
//! | [`camera_path`] | the camera at any time (slerp + linear or Catmull-Rom centre, clamped outside) and its velocity `(v_c, ω_c)` in the camera frame; symmetric-difference velocity of two poses and its backward |
//! | [`posenet`] | PoseNet: time encoding → 2-layer MLP → twist `(v, ω)` right-multiplied onto the interpolated pose; zero at initialisation; backward to flat weights |
//! | [`flow`] | `F_ego` (Eq. 9) from camera velocity and inverse depth, `F_gs` (Eq. 10) in the paper's and the exact form; backward |
//! | [`event_counts`] | per-interval cumulative signed event counts at fine time bins: the count of any pixel over any sub-interval in two lookups |
//! | [`crop`] | the event term on one of `k × k` tiles of the image: the cropped camera and the same window of the pseudo image |
//! | [`coarse`] | the event term at `1/k` of the resolution: the camera of `k × k` blocks and the pseudo image averaged over them in linear intensity |
//! | [`event_image`] | pseudo images (Eq. 11, nearest frame; two-sided baseline), `L_event` with gradients w.r.t. the render and `C`; sRGB ↔ linear |
//! | [`contrast`] | the contrast threshold `C` estimated from frames and events (robust fit of counts on log changes, bootstrap spread); the modes given / estimate / learn |
//! | [`motion_loss`] | `L_motion` (Eq. 12) over CSR bindings with a robust norm; gradients w.r.t. `F_ego` and `F_gs` |
//! | [`neighbours`] | bound Gaussians whose events' mean flow disagrees with their neighbours' in the image (dropped from `L_motion`) |
//! | [`rate_outliers`] | hot pixels and bursts: event-rate outliers left out of the pseudo images and of `L_motion` |
//! | [`schedule`] | loss weights γ1, γ2(iter) (Eq. 13) |
//! | [`lie`] | SO(3) exp/log and Jacobians, the two pose perturbations and gradient conversion between them |
//! | [`baselines`] | the 2D baselines on the held-out frames: nearest train frame, linear blend, two-sided event pseudo image |
//! | [`camera_check`] | the joint training's camera (interpolated, and with the PoseNet) against the held-out frames' recorded poses |
//!
//! **Conventions.** Camera axes OpenGL (−Z forward, +Y up), poses camera-to-world, pixel
//! `v` downwards (`scene::camera`); Eq. 9's computer-vision frame is converted inside
//! [`flow`]. Camera velocity: `v = Rᵀċ`, `Ṙ = R[ω]×` (camera frame). Pose gradients are
//! camera-right twists `T·[Exp(ω) | v]` ([`lie`]), the rasterizer's included. Images planar `C × H × W`, linear intensity. Event times are `f64` seconds on
//! the frames' clock, windows half-open `[t_a, t_b)`, polarity ±1. Reductions are summed
//! per fixed chunk in order, so results do not depend on the thread count.
//!
//! **The stage**: [`inputs`] reads the scene, the warm-up model, the flows and the
//! bindings; [`trainer`] runs the joint iterations (Eq. 13) around the warm-up's
//! `gaussians::train::Trainer`, rebinding through `assoc`, and falls back as
//! [`fallbacks`] says on degenerate inputs; [`stage`] writes the outputs
//! and `report.json`; [`settings`] holds every setting. The kernels depend only on
//! `scene`, `glam`, `rayon` and `serde` (the float trait is `scene::real::Real`). Imports
//! between modules go one way only: any module may use the leaf `lie`, and
//! `event_image`, `fallbacks`, `contrast` and `rate_outliers` use `event_counts`.

pub mod baselines;
pub mod camera_check;
pub mod camera_path;
pub mod coarse;
pub mod contrast;
pub mod crop;
pub mod event_counts;
pub mod event_image;
pub mod fallbacks;
pub mod flow;
pub mod inputs;
pub mod lie;
pub mod motion_loss;
pub mod neighbours;
pub mod posenet;
pub mod rate_outliers;
pub mod schedule;
pub mod settings;
pub mod stage;
pub mod trainer;

#[cfg(test)]
mod tests;
