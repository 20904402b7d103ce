//! The joint training loop (DEGS §3.5, Eq. 13): every iteration renders one train frame
//! for `L_rgb` (whose render also gives the motion loss its depth and deformed centres),
//! one in-between time `t_e` for `L_event`, and adds `γ2·L_motion` over the Gaussians
//! bound to events near that frame; one Adam step then updates the canonical Gaussians,
//! the deformation field and the PoseNet. Bindings are rebuilt every `rebind_every`
//! iterations and whenever densification changes the Gaussians.
//!
//! Simplifications (documented in docs/DESIGN.md §9): the rendered depth in `F_ego` is
//! detached; frames keep their recorded poses (the PoseNet corrects in-between times
//! only). The PoseNet learns from `L_event` (the camera of the render at `t_e`) and from
//! `L_motion` (the corrected camera's velocity in `F_ego`).

use crate::camera_check::{CameraCheck, image_error_px, pose_error};
use crate::contrast::LearnedContrast;
use crate::crop::Crop;
use crate::event_image::{PseudoImage, PseudoInputs, pseudo_image, render_event_loss};
use crate::fallbacks::{DroppedBindings, EventSkip, Fallbacks, interval_skip};
use crate::inputs::Inputs;
use crate::posenet::{PoseNet, apply_correction, correction_backward};
use crate::settings::{DeformSettings, EventChannels};
use gaussians::stage::PSNR_CAP;
use gaussians::train::{ModelGrads, Trainer, ViewRender};
use gaussians::{Planes, Rasterizer, TileRasterizer};
use rand::{RngExt, SeedableRng};
use scene::Camera;
use scene::metrics::psnr_u8;
use stagekit::optim::{Adam, ExpSchedule};
use std::time::Instant;

mod motion;
mod rebind;
use motion::{MotionGrads, MotionTerm};

/// Near plane (scene units) below which a centre or depth is not used by the motion loss.
const NEAR: f64 = 1e-3;

/// Seconds spent per part of the iteration.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct Timings {
    pub rgb: f64,
    pub event: f64,
    pub motion: f64,
    pub update: f64,
    pub rebind: f64,
}

/// One iteration's figures.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct JointStep {
    pub iteration: u32,
    pub l_rgb: f64,
    pub l_event: f64,
    pub l_motion: f64,
    /// The warm-up's track term at the train frame (0 without tracks; weighted).
    pub l_track: f64,
    /// The warm-up's depth-prior term at the train frame (0 without priors; weighted).
    pub l_depth: f64,
    pub total: f64,
    /// PSNR of the train frame's render (dB, at most `gaussians::stage::PSNR_CAP`).
    pub psnr: f64,
    /// Gaussians bound at the frame of this iteration's motion loss.
    pub bound: usize,
    pub gaussians: usize,
    /// `L_event` was skipped (RGB-only supervision; [`crate::fallbacks`]).
    pub event_skipped: bool,
    /// Bound events left out of this iteration's `L_motion` (no flow, outliers,
    /// Gaussians disagreeing with their neighbours, hot pixels and bursts).
    pub bindings_dropped: usize,
    /// The contrast threshold after this iteration.
    pub contrast: f64,
}

/// The joint training state around the warm-up's trainer.
pub struct JointTrainer {
    pub inner: Trainer,
    pub settings: DeformSettings,
    pub posenet: Option<PoseNet<f32>>,
    posenet_adam: Adam,
    /// The PoseNet's learning rate by iteration (log-linear decay; 0 throughout when
    /// `posenet_lr` is 0).
    posenet_lr: ExpSchedule,
    posenet_grad: Vec<f32>,
    /// `L_motion`'s and `L_track`'s gradients on the rendered centres, summed.
    d_means: Vec<[f32; 3]>,
    /// `L_track`'s gradient when it skips the field (`tracks.into_field = false`).
    own_means: Vec<[f32; 3]>,
    /// Bindings per train frame (for the current Gaussians).
    pub bindings: Vec<assoc::Bindings>,
    pub iteration: u32,
    pub timings: Timings,
    pub rebinds: u32,
    /// What the training left out so far (degenerate inputs).
    pub fallbacks: Fallbacks,
    /// The contrast threshold `C` in use; learned when the settings say so.
    pub contrast: f64,
    learned_contrast: Option<LearnedContrast>,
    rng: rand_chacha::ChaCha8Rng,
    pseudo: PseudoImage<f32>,
    /// The window of `pseudo` the event term compares (`event_tiles > 1`).
    pseudo_crop: PseudoImage<f32>,
    /// [`crate::coarse`]'s pseudo image (`event_downsample > 1`).
    pseudo_coarse: PseudoImage<f32>,
    span: f64,
}

/// Add `w·src` to the parameter gradients of `dst` (not its densification statistics).
fn add_scaled(dst: &mut ModelGrads, src: &ModelGrads, w: f32) {
    let d = &mut dst.splats;
    let s = &src.splats;
    let add = |a: &mut [f32], b: &[f32]| a.iter_mut().zip(b).for_each(|(x, y)| *x += w * y);
    add(d.means.as_flattened_mut(), s.means.as_flattened());
    add(d.log_scales.as_flattened_mut(), s.log_scales.as_flattened());
    add(d.rotations.as_flattened_mut(), s.rotations.as_flattened());
    add(&mut d.opacity_logits, &s.opacity_logits);
    add(d.sh_dc.as_flattened_mut(), s.sh_dc.as_flattened());
    add(d.sh_rest.as_flattened_mut(), s.sh_rest.as_flattened());
    add(d.motion.as_flattened_mut(), s.motion.as_flattened());
    add(d.part_rot.as_flattened_mut(), s.part_rot.as_flattened());
    add(d.part_shift.as_flattened_mut(), s.part_shift.as_flattened());
    if dst.field.len() == src.field.len() {
        add(&mut dst.field, &src.field);
    } else if dst.field.is_empty() {
        dst.field = src.field.iter().map(|g| w * g).collect();
    }
}

/// Normalised time of the field at `t` seconds: linear between the neighbouring train
/// frames' `(timestamp, time)`.
pub(crate) fn field_time(d: &Inputs, t: f64) -> f32 {
    let n = d.times.len();
    let j = d.times.partition_point(|&k| k <= t).clamp(1, n.max(2) - 1) - 1;
    if n < 2 || d.times[j + 1] <= d.times[j] {
        return d.views[j.min(n - 1)].time;
    }
    let s = ((t - d.times[j]) / (d.times[j + 1] - d.times[j])).clamp(0.0, 1.0) as f32;
    d.views[j].time + s * (d.views[j + 1].time - d.views[j].time)
}

impl JointTrainer {
    /// Start from the warm-up model in `d` (its settings continue: learning rates,
    /// densification, field).
    pub fn new(d: &Inputs, settings: DeformSettings) -> Self {
        let mut warm = d.warmup.clone();
        // The model says whether the warm-up split it into static and dynamic Gaussians.
        warm.dynamic_only = d.model.info.dynamic_only;
        let done = d.model.info.iterations;
        warm.iterations = done + settings.iterations;
        if !settings.densify {
            warm.densify.until_iter = 0;
        }
        if settings.regrow {
            // The warm-up's cap before its sizing; a model from before that was kept:
            // 0, the per-pixel cap, set from the views when the trainer starts.
            warm.densify.max_gaussians = d.model.info.gaussian_cap_before_sizing.unwrap_or(0);
        }
        let cams: Vec<Camera> = d.views.iter().map(|v| v.camera).collect();
        let extent = gaussians::stage::scene_extent(&warm, &cams);
        let mut inner = Trainer::new(warm, d.model.splats.clone(), extent);
        match &d.model.field {
            Some(f) if settings.field_color => inner.set_field(f.with_color()),
            Some(f) => inner.set_field(f.clone()),
            None => inner.settings.deform = false,
        }
        inner.iteration = done;
        inner.part_pose_lr = settings.part_pose_lr;
        inner.tracks = gaussians::tracks::loss::TrackTerm::new(d.tracks.clone());
        inner.tracks.priors = gaussians::tracks::prior_loss::PriorTerm::new(d.priors.clone());
        let posenet = settings
            .posenet
            .then(|| PoseNet::<f32>::new(settings.posenet_net));
        let mut posenet_adam = Adam::default();
        let np = posenet.as_ref().map_or(0, |p| p.params().len());
        posenet_adam.add_group("posenet", settings.posenet_lr, 1e-15, 1, np);
        let posenet_lr = if settings.posenet_lr > 0.0 {
            let end = u64::from(settings.iterations);
            ExpSchedule::new(settings.posenet_lr, settings.posenet_lr_final, end)
        } else {
            ExpSchedule::constant(0.0)
        };
        let span = if settings.motion_span > 0.0 {
            settings.motion_span
        } else {
            d.assoc_delta_t
        };
        JointTrainer {
            inner,
            posenet,
            posenet_adam,
            posenet_lr,
            posenet_grad: vec![0.0; np],
            d_means: Vec::new(),
            own_means: Vec::new(),
            bindings: d.bindings.clone(),
            iteration: 0,
            timings: Timings::default(),
            rebinds: 0,
            fallbacks: Fallbacks {
                flows_out_of_range: d.flows_out_of_range,
                events_without_flow: d.flow_u.iter().filter(|u| !u.is_finite()).count(),
                hot_pixels: d.rate_outliers.hot_pixels.len(),
                hot_pixel_events: d.rate_outliers.hot_events,
                burst_bins: d.rate_outliers.burst_bin_count(),
                burst_events: d.rate_outliers.burst_events,
                ..Fallbacks::default()
            },
            contrast: d.contrast,
            learned_contrast: settings
                .contrast
                .learns()
                .then(|| LearnedContrast::new(d.contrast, settings.contrast_lr)),
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(settings.seed),
            pseudo: PseudoImage::default(),
            pseudo_crop: PseudoImage::default(),
            pseudo_coarse: PseudoImage::default(),
            span,
            settings,
        }
    }

    /// The camera at `t` seconds (interpolated, PoseNet-corrected) and the correction.
    pub fn camera_at(&self, d: &Inputs, t: f64) -> (Camera, [f64; 6]) {
        let pose = d.path.pose_at(t);
        let xi = match &self.posenet {
            Some(p) => match self.posenet_times(d, t) {
                (tn, Some((ta, tb))) => p.forward_anchored(tn, ta, tb),
                (tn, None) => p.forward(tn),
            }
            .map(f64::from),
            None => [0.0; 6],
        };
        let camera = Camera {
            intrinsics: d.views[0].camera.intrinsics,
            cam_to_world: apply_correction(&pose, xi),
        };
        (camera, xi)
    }

    /// Normalised `t` and, when the correction is anchored at the train frames
    /// ([`DeformSettings::posenet_anchor`]), the normalised times of the two frames around it.
    fn posenet_times(&self, d: &Inputs, t: f64) -> (f32, Option<(f32, f32)>) {
        let n = |x: f64| d.path.normalised_time(x) as f32;
        let frames = d.path.bracket(t).filter(|_| self.settings.posenet_anchor);
        (n(t), frames.map(|(a, b)| (n(a), n(b))))
    }

    /// The camera's error at the held-out frames' times against their recorded poses
    /// (interpolated path, and with the PoseNet correction); the image errors through the
    /// model's depth rendered at each recorded camera.
    pub(crate) fn camera_check(&self, r: &TileRasterizer, d: &Inputs) -> CameraCheck {
        let times: Vec<f64> = d.scene.test.frames.iter().map(|f| f.timestamp).collect();
        let recorded: Vec<_> = d.test.iter().map(|v| v.camera.cam_to_world).collect();
        let interp: Vec<_> = times.iter().map(|&t| d.path.pose_at(t)).collect();
        let corrected: Vec<_> = times
            .iter()
            .map(|&t| self.camera_at(d, t).0.cam_to_world)
            .collect();
        let depths: Vec<Vec<f32>> = d
            .test
            .iter()
            .zip(&times)
            .map(|(v, &t)| {
                let (splats, _) = self.inner.deformed(field_time(d, t));
                let bg = self.inner.settings.background;
                let (image, _) = r.render(&splats, &v.camera, self.inner.sh_degree(), bg);
                image.normalised_depth()
            })
            .collect();
        let image_px = |poses: &[scene::Pose]| -> Vec<Option<f64>> {
            d.test
                .iter()
                .zip(poses)
                .zip(&depths)
                .map(|((v, p), z)| image_error_px(&v.camera, p, z))
                .collect()
        };
        CameraCheck {
            frames: recorded.len().min(times.len()),
            interpolated: pose_error(&interp, &recorded, &image_px(&interp)),
            corrected: pose_error(&corrected, &recorded, &image_px(&corrected)),
        }
    }

    /// Eq. 12 at train frame `i` ([`motion`]; rendered as `rv`): writes `γ2·∂L/∂θ` into
    /// `out`; returns `(L_motion, bound Gaussians, bound events left out and why)`.
    fn motion_term(
        &self,
        d: &Inputs,
        i: usize,
        rv: &ViewRender<<TileRasterizer as Rasterizer>::State>,
        g2: f32,
        out: &mut MotionGrads,
    ) -> (f64, usize, DroppedBindings) {
        let inner = &self.inner;
        let term = MotionTerm {
            d,
            bindings: &self.bindings[i],
            splats: &inner.splats,
            field: inner.field_on().then_some(&inner.field),
            dynamic_only: inner.settings.dynamic_only,
            span: self.span,
            flow_form: self.settings.flow_form,
            motion: &self.settings.motion,
            neighbours: &self.settings.motion_neighbours,
            camera_at: &|t| self.camera_at(d, t),
            posenet: self.posenet.is_some(),
        };
        term.eval(i, rv, g2, out)
    }

    /// `L_motion` at train frame `i` (γ2 = 1) and its gradient on the model and on the
    /// PoseNet's parameters, assembled as the joint step does (the part on `x(t0)` through
    /// the view's backward pass); for diagnostics and the tests.
    pub fn motion_gradient(
        &mut self,
        r: &TileRasterizer,
        d: &Inputs,
        i: usize,
    ) -> (f64, ModelGrads, Vec<f32>) {
        let view = &d.views[i];
        let rv = self.inner.render_view(r, &view.camera, view.time);
        let mut m = MotionGrads::default();
        let (loss, _, _) = self.motion_term(d, i, &rv, 1.0, &mut m);
        let zero = vec![0.0f32; rv.image.rgb.len()];
        self.posenet_grad.fill(0.0);
        let g = self.backward_with_motion(r, d, &rv, &zero, &m, None);
        (loss, g, self.posenet_grad.clone())
    }

    /// The view's gradients from `d_rgb` with the motion term's joined in: its part on the
    /// rendered centres goes back through the view's pass, its canonical and field parts
    /// are added, and its camera part accumulates into the PoseNet's gradient. At train
    /// view `view`, the warm-up's `L_track` and `L_depth` join too (when the model has
    /// tracks and priors).
    fn backward_with_motion(
        &mut self,
        r: &TileRasterizer,
        d: &Inputs,
        rv: &ViewRender<<TileRasterizer as Rasterizer>::State>,
        d_rgb: &[f32],
        m: &MotionGrads,
        view: Option<usize>,
    ) -> ModelGrads {
        let inner = &mut self.inner;
        let (ids, st) = (&inner.splats.track, &inner.settings.tracks);
        let into_field = st.into_field;
        let track = view.and_then(|k| {
            inner
                .tracks
                .gradient(&rv.deformed.means, ids, k, &rv.camera, st)
        });
        // The track term's gradient joins the motion term's on the rendered centres (back
        // through the field), or with `tracks.into_field = false` goes to the tracked
        // Gaussians' own centres and trajectories only.
        let (summed, own) = match track {
            Some(t) if into_field => {
                self.d_means.clear();
                self.d_means.extend_from_slice(t);
                for (a, b) in self.d_means.iter_mut().zip(&m.at_view) {
                    (0..3).for_each(|c| a[c] += b[c]);
                }
                (true, false)
            }
            Some(t) => {
                self.own_means.clear();
                self.own_means.extend_from_slice(t);
                (false, true)
            }
            None => (false, false),
        };
        let d_means = if summed {
            Some(self.d_means.as_slice())
        } else {
            (!m.at_view.is_empty()).then_some(m.at_view.as_slice())
        };
        let mut g = (self.inner).view_backward_with_prior(r, rv, d_rgb, view, d_means);
        if own {
            let (s, d) = (&self.inner.splats, &self.own_means);
            gaussians::motion::add_centre_gradient(s, rv.time, d, &mut g.splats);
        }
        m.add_to(&self.inner.splats, &mut g);
        for &(t, xi, g_eps) in &m.camera {
            self.posenet_backward(d, t, xi, g_eps);
        }
        g
    }

    /// Accumulate the PoseNet's gradient from `∂L/∂ε` (camera-right twist) of the
    /// corrected camera at `t`, whose correction was `xi`.
    fn posenet_backward(&mut self, d: &Inputs, t: f64, xi: [f64; 6], g_eps: [f64; 6]) {
        let Some(p) = &self.posenet else {
            return;
        };
        let g_xi = correction_backward(xi, g_eps).map(|v| v as f32);
        match self.posenet_times(d, t) {
            (tn, Some((ta, tb))) => p.backward_anchored(tn, ta, tb, g_xi, &mut self.posenet_grad),
            (tn, None) => p.backward(tn, g_xi, &mut self.posenet_grad),
        }
    }

    /// One joint iteration.
    pub fn step(&mut self, r: &TileRasterizer, d: &Inputs) -> JointStep {
        let it = self.iteration as u64;
        let (g1, g2) = (
            self.settings.schedule.gamma1(it),
            self.settings.schedule.gamma2(it),
        );
        let clock = Instant::now();
        let i = self.inner.next_view(d.views.len());
        let view = &d.views[i];
        self.inner.resolve_cap(view.rgb.len() / 3);
        let life_t = self.inner.life_time(&d.views, i);
        let rv = (self.inner).render_view_living(r, &view.camera, view.time, life_t);
        let (l_rgb, grad) = self.inner.rgb_loss(&rv.image, &view.rgb);
        let psnr = psnr_u8(&rv.image.rgb, &view.rgb).min(PSNR_CAP);
        self.timings.rgb += clock.elapsed().as_secs_f64();

        // The motion term first: its gradient on the centres at the view's time joins the
        // RGB gradient on the rendered centres (one pass back through the field).
        let clock = Instant::now();
        let mut motion = MotionGrads::default();
        let (l_motion, bound, dropped) = if g2 > 0.0 {
            self.motion_term(d, i, &rv, g2 as f32, &mut motion)
        } else {
            (0.0, 0, DroppedBindings::default())
        };
        self.timings.motion += clock.elapsed().as_secs_f64();

        let clock = Instant::now();
        self.posenet_grad.fill(0.0);
        let mut grads = self.backward_with_motion(r, d, &rv, &grad, &motion, Some(i));
        let (l_track, l_depth) = (self.inner.tracks.last.0, self.inner.tracks.priors.last.0);
        self.fallbacks.drop_bindings(&dropped);
        self.inner.recycle_view(rv);
        self.timings.rgb += clock.elapsed().as_secs_f64();

        let clock = Instant::now();
        let skipped = self.fallbacks.event_steps_skipped;
        let l_event = if g1 > 0.0 && d.views.len() >= 2 {
            self.event_term(r, d, g1 as f32, &mut grads)
        } else {
            0.0
        };
        self.timings.event += clock.elapsed().as_secs_f64();

        let clock = Instant::now();
        let before = self.inner.splats.len();
        self.inner.apply_gradients(&grads);
        self.inner.recycle_grads(grads);
        if let Some(p) = &mut self.posenet {
            self.posenet_adam.groups[0].lr = self.posenet_lr.at(u64::from(self.iteration));
            self.posenet_adam
                .step(0, p.params_mut(), &self.posenet_grad);
        }
        self.iteration += 1;
        self.timings.update += clock.elapsed().as_secs_f64();
        // The bindings serve `L_motion` only: none to rebuild without it.
        let every = self.settings.rebind_every;
        let changed = self.inner.splats.len() != before;
        let due = changed || (every > 0 && self.iteration.is_multiple_of(every));
        if due && self.settings.schedule.uses_motion() {
            self.rebind(r, d);
        }
        JointStep {
            iteration: self.iteration,
            l_rgb,
            l_event,
            l_motion,
            l_track,
            l_depth,
            total: l_rgb + g1 * l_event + g2 * l_motion + l_track + l_depth,
            psnr,
            bound,
            gaussians: self.inner.splats.len(),
            event_skipped: self.fallbacks.event_steps_skipped > skipped,
            bindings_dropped: dropped.total(),
            contrast: self.contrast,
        }
    }

    /// Eq. 11 at a random `t_e` between two neighbouring train frames: adds `γ1·∂L/∂θ` to
    /// `grads` and the PoseNet's gradient; returns `L_event` (0 when skipped: an empty
    /// interval, one without events, no valid pixel; counted in `fallbacks`).
    fn event_term(
        &mut self,
        r: &TileRasterizer,
        d: &Inputs,
        g1: f32,
        grads: &mut ModelGrads,
    ) -> f64 {
        let j = self.rng.random_range(0..d.views.len() - 1);
        let (ta, tb) = (d.times[j], d.times[j + 1]);
        if let Some(why) = interval_skip(&d.counts.intervals()[j]) {
            self.fallbacks.skip_event(why);
            return 0.0;
        }
        let t_e = ta + self.rng.random::<f64>() * (tb - ta);
        let all = d.events.as_slice();
        let luma = self.settings.event_channels == EventChannels::Luminance;
        let (left, right, channels) = if luma {
            (&d.luma[j], &d.luma[j + 1], 1)
        } else {
            (&d.linear[j], &d.linear[j + 1], 3)
        };
        let inp = PseudoInputs {
            counts: &d.counts.intervals()[j],
            events: Some(&all),
            left,
            right,
            channels,
            contrast: self.contrast as f32,
        };
        pseudo_image(
            &inp,
            t_e,
            self.settings.pseudo_mode,
            &self.settings.pseudo,
            &mut self.pseudo,
        );
        let (camera, xi) = self.camera_at(d, t_e);
        // At 1/s of the resolution, or full.
        let s = self.settings.event_downsample as usize;
        let (camera, pseudo) = if s > 1 {
            crate::coarse::pseudo(&self.pseudo, s, &mut self.pseudo_coarse);
            (crate::coarse::camera(&camera, s), &self.pseudo_coarse)
        } else {
            (camera, &self.pseudo)
        };
        // One of k × k tiles of the image, or all of it.
        let k = self.settings.event_tiles as usize;
        let (camera, pseudo) = if k > 1 {
            let (w, h) = (camera.intrinsics.width, camera.intrinsics.height);
            let tile = self.rng.random_range(0..k * k);
            let crop = Crop::tile(w as usize, h as usize, k, tile);
            crop.pseudo(pseudo, &mut self.pseudo_crop);
            (crop.camera(&camera), &self.pseudo_crop)
        } else {
            (camera, pseudo)
        };
        let rv = self.inner.render_view(r, &camera, field_time(d, t_e));
        let mut g = vec![0.0f32; rv.image.rgb.len()];
        let el = render_event_loss(
            &rv.image.rgb,
            d.srgb,
            self.settings.event_channels,
            pseudo,
            &mut g,
        );
        if el.valid == 0 {
            self.fallbacks.skip_event(EventSkip::NoValidPixels);
            return 0.0;
        }
        if let Some(lc) = &mut self.learned_contrast {
            lc.step(f64::from(el.d_contrast));
            self.contrast = lc.value();
        }
        g.iter_mut().for_each(|x| *x *= g1);
        let ge = self.inner.view_backward(r, &rv, &g, Planes::NONE, None);
        self.inner.recycle_view(rv);
        // While the PoseNet warms up, L_event moves the camera only (not the scene).
        if self.iteration >= self.settings.posenet_warmup || self.posenet.is_none() {
            add_scaled(grads, &ge, 1.0);
        }
        self.posenet_backward(d, t_e, xi, ge.camera);
        self.inner.recycle_grads(ge);
        el.loss as f64
    }
}
