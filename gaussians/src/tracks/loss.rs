//! The track term `L_track` (issues #30 and #32): the moving tracks' Gaussians are
//! pulled, at every train view, to where their track saw them.
//!
//! The tracks start the trajectories ([`super::add_moving`]), but a quadratic over the
//! recording cannot follow a turning object, and the rendering loss alone does not move
//! a textured one (BENCHMARKS.md, "What moves them"). So the correspondences stay in
//! the loss, as the 2D track loss of Shape of Motion (Wang et al. 2025) does:
//!
//! ```text
//! L_track = w · (1/N) Σ_i H(|π_v(μ_i(t_v)) − p_iv|)
//! ```
//!
//! over the `N` Gaussians whose track was seen in view `v`, `μ_i(t_v)` the centre as
//! rendered (field and trajectory applied), `π_v` the view's pinhole projection, `p_iv`
//! the track's position (camera pixels), `H` Huber with threshold `δ = huber_px`
//! (`r²/2` up to δ, `δ(r − δ/2)` beyond: a drifted track pulls no harder than δ). Its
//! gradient joins the rendered centres' (`Trainer::view_backward`'s `d_means`), so the
//! canonical centre, the trajectory and the field all learn from it. Only image-plane
//! positions are asked for: the distance along each ray is left to the other terms.

use glam::{DMat3, DVec2, DVec3};
use scene::Camera;

/// Per track, its position in each train view (camera pixels; `None` where lost).
pub type Table = Vec<Vec<Option<DVec2>>>;

pub use crate::splats::{NO_TRACK as NONE, first_copies};

/// `L_track` at view `view` (camera `camera`) of the rendered centres `means` (one per
/// Gaussian; `ids` their tracks, indices into `table`, whose rows give each view's
/// position), with weight `weight` and Huber threshold `huber_px`. Its gradient with
/// respect to `means` is written into `d_means` (one row per Gaussian, zero for untracked
/// ones; left empty when the term is off). Returns the loss and `N`, the Gaussians it
/// counted.
#[allow(clippy::too_many_arguments)]
pub fn at_view(
    means: &[[f32; 3]],
    ids: &[u32],
    table: &[Vec<Option<DVec2>>],
    view: usize,
    camera: &Camera,
    weight: f64,
    huber_px: f64,
    d_means: &mut Vec<[f32; 3]>,
) -> (f64, usize) {
    d_means.clear();
    if ids.len() != means.len() || weight <= 0.0 {
        return (0.0, 0);
    }
    d_means.resize(means.len(), [0.0; 3]);
    let k = &camera.intrinsics;
    let rot = DMat3::from_quat(camera.cam_to_world.rotation);
    // Pass 1: the residuals of the Gaussians seen here (the mean needs their count).
    let mut seen = Vec::new();
    for (i, &id) in ids.iter().enumerate() {
        let Some(Some(p)) = (id != NONE).then(|| table[id as usize].get(view).copied().flatten())
        else {
            continue;
        };
        let x = DVec3::from(means[i].map(f64::from));
        let pc = camera.cam_to_world.to_camera(x);
        let d = -pc.z;
        if d <= 1e-6 {
            continue;
        }
        let u = DVec2::new(k.cx + k.fx * pc.x / d, k.cy - k.fy * pc.y / d);
        seen.push((i, pc, u - p));
    }
    let n = seen.len();
    if n == 0 {
        return (0.0, 0);
    }
    let scale = weight / n as f64;
    let mut loss = 0.0;
    for (i, pc, e) in seen {
        let r = e.length();
        // H(r) and H'(r)·e/r.
        let (h, g) = if r <= huber_px {
            (0.5 * r * r, e)
        } else {
            (huber_px * (r - 0.5 * huber_px), e * (huber_px / r))
        };
        loss += h;
        let d = -pc.z;
        // ∂(u, v)/∂p_cam of u = cx + fx·x/d, v = cy − fy·y/d, d = −z.
        let du = DVec3::new(k.fx / d, 0.0, k.fx * pc.x / (d * d));
        let dv = DVec3::new(0.0, -k.fy / d, -k.fy * pc.y / (d * d));
        // p_cam = Rᵀ(μ − c): ∂L/∂μ = R·∂L/∂p_cam.
        let gw = rot * (du * g.x + dv * g.y) * scale;
        d_means[i] = gw.as_vec3().to_array();
    }
    (loss * scale, n)
}

/// The trainer's track term: the tracks and a reused gradient buffer.
#[derive(Clone, Debug, Default)]
pub struct TrackTerm {
    pub table: Table,
    grad: Vec<[f32; 3]>,
    /// `L_track` and the Gaussians it counted at the last view.
    pub last: (f64, usize),
    /// The depth priors' term (`L_depth`), empty without priors.
    pub priors: super::prior_loss::PriorTerm,
    /// The shape term's pairs (`tracks.rigidity`), while it is on, and its last value.
    pub shape: Option<super::rigid::Pairs>,
    pub last_shape: f64,
}

impl TrackTerm {
    pub fn new(table: Table) -> Self {
        TrackTerm {
            table,
            ..Self::default()
        }
    }

    /// The gradient of `L_track` at train view `view` on `means` ([`at_view`]); `None`
    /// when the term is off or no tracked Gaussian was seen there.
    pub fn gradient(
        &mut self,
        means: &[[f32; 3]],
        ids: &[u32],
        view: usize,
        camera: &Camera,
        st: &super::TrackSettings,
    ) -> Option<&[[f32; 3]]> {
        let (w, h) = (st.weight, st.huber_px);
        self.last = at_view(means, ids, &self.table, view, camera, w, h, &mut self.grad);
        (self.last.1 > 0).then_some(self.grad.as_slice())
    }
}
