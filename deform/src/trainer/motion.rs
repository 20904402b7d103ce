//! The motion term of the joint step (Eq. 12 at the drawn train frame): flows of the
//! bound Gaussians against their events' flow, and where its gradient goes. It reads the
//! training through [`MotionTerm`]: the Gaussians, the field, the bindings, the camera.

use super::{NEAR, field_time};
use crate::camera_path::{CameraVelocity, velocity_between, velocity_between_backward};
use crate::fallbacks::DroppedBindings;
use crate::flow::{EgoGrad, ego_flow, ego_flow_backward, gaussian_flow, gaussian_flow_backward};
use crate::flow::{EgoPoints, Flow2, GsCameras, GsGrad, Pinhole, ProjCam};
use crate::inputs::Inputs;
use crate::motion_loss::{
    CsrBindings, MotionGrad, MotionInputs, MotionSettings, PerGaussian, motion_loss,
};
use crate::neighbours::NeighbourSettings;
use crate::settings::FlowForm;
use gaussians::field::{Deformation, Deltas, Mlp};
use gaussians::train::{ModelGrads, ViewRender};
use gaussians::{Rasterizer, RenderedImage, Splats, TileRasterizer};
use scene::Camera;

/// The motion term's gradients: on the centres as rendered at the view's time (`x(t0)`,
/// taken back with the view's RGB gradient), on the centres at the span's other end
/// (`x(t1)`: to the canonical centres and trajectories) and on the field's parameters
/// (through `x(t1)`). Empty vectors: no contribution.
#[derive(Default)]
pub(super) struct MotionGrads {
    pub(super) at_view: Vec<[f32; 3]>,
    /// `∂L/∂x(t1)`, and the field time `t1` maps to.
    at_end: Vec<[f32; 3]>,
    tau1: f32,
    field: Vec<f32>,
    /// `(t, ξ(t), ∂L/∂ε)`: camera-right twist gradients of the corrected camera at the
    /// span's two ends, for the PoseNet.
    pub(super) camera: Vec<(f64, [f64; 6], [f64; 6])>,
}

impl MotionGrads {
    /// Add the parts through `x(t1)` (canonical centres, trajectories of `s`) and the
    /// field's to `g` (the rendered-centre part goes through `Trainer::view_backward`).
    pub(super) fn add_to(&self, s: &Splats, g: &mut ModelGrads) {
        if self.at_end.len() == g.splats.means.len() {
            gaussians::motion::add_centre_gradient(s, self.tau1, &self.at_end, &mut g.splats);
        }
        if !self.field.is_empty() && g.field.len() == self.field.len() {
            g.field
                .iter_mut()
                .zip(&self.field)
                .for_each(|(a, b)| *a += b);
        }
    }
}

/// What the motion term reads of the joint training.
pub(super) struct MotionTerm<'a> {
    pub(super) d: &'a Inputs,
    /// The bindings at the term's train frame.
    pub(super) bindings: &'a assoc::Bindings,
    /// The canonical Gaussians, and the field while it is on (moving only the dynamic
    /// Gaussians when `dynamic_only`).
    pub(super) splats: &'a Splats,
    pub(super) field: Option<&'a Mlp<f32>>,
    pub(super) dynamic_only: bool,
    /// The span of the flows (seconds).
    pub(super) span: f64,
    pub(super) flow_form: FlowForm,
    pub(super) motion: &'a MotionSettings,
    pub(super) neighbours: &'a NeighbourSettings,
    /// The joint training's camera (PoseNet-corrected) at `t` seconds, and the correction.
    pub(super) camera_at: &'a dyn Fn(f64) -> (Camera, [f64; 6]),
    /// Whether a PoseNet learns from the term (its camera gradients are wanted).
    pub(super) posenet: bool,
}

impl MotionTerm<'_> {
    /// Eq. 12 over the Gaussians bound at train frame `i` (rendered as `rv`, whose
    /// deformed centres are `x(t0)`): writes `γ2·∂L/∂θ` into `out`; returns
    /// `(L_motion, bound Gaussians, bound events left out and why)`.
    pub(super) fn eval(
        &self,
        i: usize,
        rv: &ViewRender<<TileRasterizer as Rasterizer>::State>,
        g2: f32,
        out: &mut MotionGrads,
    ) -> (f64, usize, DroppedBindings) {
        let (d, b) = (self.d, self.bindings);
        let mut dropped = DroppedBindings::default();
        if b.gaussians() != self.splats.len() {
            return (0.0, 0, dropped);
        }
        let idx: Vec<usize> = (0..b.gaussians())
            .filter(|&g| !b.of(g).0.is_empty())
            .collect();
        if idx.is_empty() {
            return (0.0, 0, dropped);
        }
        let t0 = d.times[i];
        let t1 = if i + 1 < d.times.len() {
            t0 + self.span
        } else {
            t0 - self.span
        };
        let tau1 = field_time(d, t1);
        // Compact CSR over the bound Gaussians, without the events at hot pixels or in
        // bursts (the others' weights are renormalised by the loss).
        let (mut offsets, mut events, mut weights) = (vec![0u32], Vec::new(), Vec::new());
        let ev = &d.events;
        for &g in &idx {
            let (e, w) = b.of(g);
            for (&k, &wk) in e.iter().zip(w) {
                let at = k as usize;
                if at < ev.len() && d.rate_outliers.excludes(ev.t[at], ev.x[at], ev.y[at]) {
                    dropped.rate_outliers += 1;
                } else {
                    events.push(k);
                    weights.push(wk);
                }
            }
            offsets.push(events.len() as u32);
        }
        // Deformed centres at t0 (as rendered) and t1: canonical centre, plus the field's
        // shift (its input the canonical centre, detached), plus the trajectory's, as
        // `render_view` moves them.
        let xs: Vec<[f32; 3]> = idx.iter().map(|&g| self.splats.means[g]).collect();
        let moves = |k: usize| !self.dynamic_only || self.splats.is_dynamic(idx[k]);
        let along = |k: usize| gaussians::motion::shift(self.splats, idx[k], tau1);
        let x0: Vec<[f32; 3]> = idx.iter().map(|&g| rv.deformed.means[g]).collect();
        // A rigid part's member moves with its part's pose at t1 (`gaussians::parts`);
        // the term does not train the poses (their gradient stops here).
        let parts = &self.splats.parts;
        let part_poses: Vec<([f32; 4], [f32; 3])> =
            (0..parts.len()).map(|p| parts.pose(p, tau1)).collect();
        let part_pose = |k: usize| {
            let m = *self.splats.part.get(idx[k])?;
            let (q, t) = *part_poses.get(m as usize)?;
            Some((q, t, parts.origin[m as usize]))
        };
        let (field_dx, cache1) = match self.field {
            Some(f) => {
                let (dl, c1) = Deformation::forward(f, &xs, &[tau1]);
                (Some(dl.dx), Some((f, c1)))
            }
            None => (None, None),
        };
        let x1: Vec<[f32; 3]> = (0..xs.len())
            .map(|k| {
                let dx = match &field_dx {
                    Some(dx) if moves(k) => dx[k],
                    _ => [0.0; 3],
                };
                let tr = along(k);
                let x: [f32; 3] = std::array::from_fn(|c| xs[k][c] + dx[c] + tr[c]);
                match part_pose(k) {
                    Some((q, t, o)) => gaussians::parts::place(q, t, o, x, [1.0, 0.0, 0.0, 0.0]).0,
                    None => x,
                }
            })
            .collect();
        let k = d.views[i].camera.intrinsics;
        // The joint training's camera (PoseNet-corrected) at both ends of the span.
        let (ca, xa) = (self.camera_at)(t0);
        let (cb, xb) = (self.camera_at)(t1);
        let cam0 = ProjCam::<f32>::new(&rv.camera.cam_to_world, &k, NEAR);
        let cam1 = ProjCam::<f32>::new(&cb.cam_to_world, &k, NEAR);
        let cams = match self.flow_form {
            FlowForm::Paper => GsCameras::Same(&cam0),
            FlowForm::Exact => GsCameras::Exact(&cam0, &cam1),
        };
        let mut fgs = Flow2::default();
        gaussian_flow(cams, &x0, &x1, &mut fgs);
        // F_ego from the velocity of the joint training's camera (PoseNet-corrected) over
        // [t0, t1]: the PoseNet learns from L_motion too (Eq. 12 trains it jointly).
        let mut fego = Flow2::default();
        let paper = self.flow_form == FlowForm::Paper;
        let vel = velocity_between(&ca.cam_to_world, &cb.cam_to_world, t1 - t0);
        let vel = vel.to_array().map(|x| x as f32);
        let pinhole = Pinhole::from_intrinsics(&k);
        let (u, v, rho) = if paper {
            ego_points(&rv.image, &cam0, &x0)
        } else {
            Default::default()
        };
        let pts = EgoPoints {
            u: &u,
            v: &v,
            inv_depth: &rho,
        };
        if paper {
            ego_flow(&pinhole, &vel, pts, (1.0 / NEAR) as f32, &mut fego);
        }
        dropped.disagreeing = self.drop_disagreeing(
            &cam0,
            &x0,
            (t1 - t0) as f32,
            (&mut offsets, &mut events, &mut weights),
        );
        let inp = MotionInputs {
            dt: (t1 - t0) as f32,
            bindings: CsrBindings {
                offsets: &offsets,
                events: &events,
                weights: &weights,
            },
            flow_u: &d.flow_u,
            flow_v: &d.flow_v,
            flow_base: 0,
            ego: (self.flow_form == FlowForm::Paper).then(|| PerGaussian {
                u: &fego.u,
                v: &fego.v,
                valid: Some(&fego.valid),
            }),
            gs: PerGaussian {
                u: &fgs.u,
                v: &fgs.v,
                valid: Some(&fgs.valid),
            },
        };
        let mut mg = MotionGrad::default();
        let ml = motion_loss(self.motion, &inp, Some(&mut mg));
        dropped.no_flow = ml.missing_events + ml.dropped_non_finite;
        dropped.outliers = ml.dropped_outliers;
        if ml.bound == 0 {
            return (0.0, idx.len(), dropped);
        }
        let gu: Vec<f32> = mg.gs_u.iter().map(|g| g * g2).collect();
        let gv: Vec<f32> = mg.gs_v.iter().map(|g| g * g2).collect();
        let mut gg = GsGrad::default();
        gaussian_flow_backward(cams, &x0, &x1, &fgs, &gu, &gv, &mut gg);
        for (kk, g) in gg.x1.iter_mut().enumerate() {
            if let Some((q, _, _)) = part_pose(kk) {
                *g = gaussians::parts::rotate_back(q, *g);
            }
        }
        let n = self.splats.len();
        out.at_view = vec![[0.0; 3]; n];
        out.at_end = vec![[0.0; 3]; n];
        out.tau1 = tau1;
        for (kk, &g) in idx.iter().enumerate() {
            out.at_view[g] = gg.x0[kk];
            out.at_end[g] = gg.x1[kk];
        }
        if paper && self.posenet {
            let scaled = |g: &[f32]| g.iter().map(|x| x * g2).collect::<Vec<f32>>();
            let mut eg = EgoGrad::default();
            let (gu, gv) = (scaled(&mg.ego_u), scaled(&mg.ego_v));
            ego_flow_backward(&pinhole, &vel, pts, &fego, &gu, &gv, &mut eg);
            let g_vel = CameraVelocity::from_array(eg.velocity.map(f64::from));
            let (ga, gb) =
                velocity_between_backward(&ca.cam_to_world, &cb.cam_to_world, t1 - t0, &g_vel);
            out.camera = vec![(t0, xa, ga), (t1, xb, gb)];
        }
        if let Some((f, c1)) = cache1 {
            let mut dl = Deltas::zeros(idx.len());
            for (kk, g) in gg.x1.iter().enumerate() {
                if moves(kk) {
                    dl.dx[kk] = *g;
                }
            }
            out.field = Deformation::backward(f, &c1, &dl);
        }
        (ml.loss as f64, idx.len(), dropped)
    }

    /// Empty the CSR ranges (`csr`: offsets, events, weights) of the bound Gaussians whose events'
    /// mean flow over the span `dt` disagrees with their neighbours' in the image
    /// ([`crate::neighbours`]; centres `x0` seen by `cam`); returns the events removed.
    fn drop_disagreeing(
        &self,
        cam: &ProjCam<f32>,
        x0: &[[f32; 3]],
        dt: f32,
        csr: (&mut Vec<u32>, &mut Vec<u64>, &mut Vec<f32>),
    ) -> usize {
        let (d, (offsets, events, weights)) = (self.d, csr);
        let s = self.neighbours;
        if s.radius_px <= 0.0 {
            return 0;
        }
        let range = |k: usize| offsets[k] as usize..offsets[k + 1] as usize;
        let px: Vec<[f32; 2]> = x0
            .iter()
            .map(|p| cam.project(p).map_or([f32::NAN; 2], |(q, _)| q))
            .collect();
        let flow: Vec<Option<[f32; 2]>> = (0..x0.len())
            .map(|k| {
                let (mut sum, mut n) = ([0.0f32; 2], 0usize);
                for &e in &events[range(k)] {
                    let (u, v) = (d.flow_u[e as usize], d.flow_v[e as usize]);
                    if u.is_finite() && v.is_finite() {
                        sum = [sum[0] + u, sum[1] + v];
                        n += 1;
                    }
                }
                (n > 0).then(|| [sum[0] / n as f32 * dt, sum[1] / n as f32 * dt])
            })
            .collect();
        let drop = crate::neighbours::disagreeing(&px, &flow, s);
        if !drop.contains(&true) {
            return 0;
        }
        let (mut kept, mut kept_w, mut new_offsets) = (Vec::new(), Vec::new(), vec![0u32]);
        let mut removed = 0;
        for (k, &out) in drop.iter().enumerate() {
            if out {
                removed += range(k).len();
            } else {
                kept.extend_from_slice(&events[range(k)]);
                kept_w.extend_from_slice(&weights[range(k)]);
            }
            new_offsets.push(kept.len() as u32);
        }
        (*events, *weights, *offsets) = (kept, kept_w, new_offsets);
        removed
    }
}

/// Pixel and inverse rendered depth (alpha-normalised; −1 where nothing was rendered) of
/// each centre `x` under `cam`.
fn ego_points(
    img: &RenderedImage,
    cam: &ProjCam<f32>,
    x: &[[f32; 3]],
) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let (w, h) = (img.width, img.height);
    let mut out = (
        Vec::with_capacity(x.len()),
        Vec::with_capacity(x.len()),
        Vec::with_capacity(x.len()),
    );
    for p in x {
        let (px, rho) = match cam.project(p) {
            Some((px, _)) => {
                let (xi, yi) = (px[0].round(), px[1].round());
                let rho = if xi >= 0.0 && yi >= 0.0 && (xi as usize) < w && (yi as usize) < h {
                    let k = yi as usize * w + xi as usize;
                    let a = img.alpha[k];
                    if a >= 0.5 {
                        a / img.depth[k].max(1e-12)
                    } else {
                        -1.0
                    }
                } else {
                    -1.0
                };
                (px, rho)
            }
            None => ([0.0; 2], -1.0),
        };
        out.0.push(px[0]);
        out.1.push(px[1]);
        out.2.push(rho);
    }
    out
}
