//! RGB-only training of a dynamic Gaussian model (DEGS warm-up, `docs/DESIGN.md` §5):
//! canonical Gaussians optimised with Adam under L1 (+ D-SSIM), densified as 3DGS, and
//! after a static phase a deformation field `F(γ(x), γ(t))` (Deform-GS).
//!
//! The rasterizer is reached through the [`Rasterizer`] trait so the loop can be tested on
//! its own; [`Splats`] holds the trainable parameters. The loop calls [`static_split`],
//! [`sizing`] and [`field_probe`] when due and takes on what they decide.

pub mod field_probe;
pub mod init;
pub mod judge;
pub mod rigidity;
mod run;
pub mod settings;
pub mod sh_refit;
pub mod sizing;
mod spare;
pub mod static_split;
pub mod stereo;
mod to_model;
mod view;

use crate::densify::{self, Geometry, GradStats};
use crate::field::{self, Mlp};
use crate::optim::{Adam, ExpSchedule};
use crate::raster::{Planes, Rasterizer, RenderedImage};
use crate::splats::{SplatGrads, Splats};
use field_probe::FieldProbeSummary;
use judge::{Candidate, Judge, spread};
pub use run::{RunSummary, run, work_schedule};
use scene::Camera;
use scene::metrics;
pub use settings::TrainSettings;
use sizing::SizingSummary;
use spare::Spare;
use static_split::SplitSummary;
pub use view::{ModelGrads, StepInfo, View, ViewRender};

/// The training state.
pub struct Trainer {
    pub settings: TrainSettings,
    pub splats: Splats,
    pub field: Mlp<f32>,
    pub adam: Adam,
    pub field_adam: Adam,
    /// The parts' knot poses' optimiser (rotations, translations; [`crate::parts`]).
    pub parts_adam: Adam,
    /// The parts' poses' learning rates as a share of the Gaussians' rotation and
    /// position rates: 1 in the warm-up; 0 keeps them as they are (the members' own
    /// parameters still train).
    pub part_pose_lr: f64,
    pub stats: GradStats,
    pub extent: f32,
    pub iteration: u32,
    /// The static/dynamic split, once made; what the sizing decided, once done.
    pub split: Option<SplitSummary>,
    pub sizing: Option<SizingSummary>,
    /// What the field's width probe measured and chose, once done ([`field_probe`]).
    pub field_probe: Option<FieldProbeSummary>,
    /// Canonical neighbours of the isometry term ([`rigidity`]), while it is on.
    pub neighbours: Option<rigidity::Neighbours>,
    /// The track term `L_track` (`init = "tracks"`; [`crate::tracks::loss`]).
    pub tracks: crate::tracks::loss::TrackTerm,
    order: Vec<usize>,
    /// The train views at half resolution while `coarse_until` says so.
    coarse: Vec<View>,
    rng: rand_chacha::ChaCha8Rng,
    /// Buffers given back by [`Self::recycle_view`] / [`Self::recycle_grads`].
    spare: spare::Pool,
}

const GROUPS: [&str; 7] = [
    "means",
    "log_scales",
    "rotations",
    "opacity",
    "sh_dc",
    "sh_rest",
    "motion",
];

impl Trainer {
    pub fn new(settings: TrainSettings, splats: Splats, extent: f32) -> Self {
        use rand::SeedableRng;
        let n = splats.len();
        let mut adam = Adam::default();
        let s = &settings;
        let widths = [3, 3, 4, 1, 3, 45, crate::motion::WIDTH];
        let lrs = [
            s.position_lr_init * extent as f64,
            s.scaling_lr,
            s.rotation_lr,
            s.opacity_lr,
            s.feature_lr,
            s.feature_lr / 20.0,
            s.position_lr_init * extent as f64,
        ];
        for k in 0..GROUPS.len() {
            adam.add_group(GROUPS[k], lrs[k], 1e-15, widths[k], n * widths[k]);
        }
        let mut field = Mlp::<f32>::new(s.field, s.field.seed);
        if s.field.zero_head_init {
            field.zero_head();
        }
        let mut field_adam = Adam::default();
        field_adam.add_group("field", s.field_lr_init, 1e-15, 1, field.params.len());
        Trainer {
            stats: GradStats::new(n),
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(s.seed),
            settings,
            splats,
            field,
            adam,
            field_adam,
            parts_adam: Adam::default(),
            part_pose_lr: 1.0,
            extent,
            iteration: 0,
            split: None,
            sizing: None,
            field_probe: None,
            neighbours: None,
            tracks: Default::default(),
            order: Vec::new(),
            coarse: Vec::new(),
            spare: spare::Pool::default(),
        }
    }

    /// Replace the deformation field (a loaded or extended one), its Adam state
    /// started afresh at the field's current learning rate.
    pub fn set_field(&mut self, field: Mlp<f32>) {
        let mut adam = Adam::default();
        adam.add_group(
            "field",
            self.settings.field_lr_init,
            1e-15,
            1,
            field.params.len(),
        );
        self.field = field;
        self.field_adam = adam;
    }

    /// Give back a view after [`Self::view_backward`]: a later [`Self::render_view`]
    /// with the same rasterizer reuses its buffers. Optional (else simply dropped).
    pub fn recycle_view<S: Send + 'static>(&self, v: ViewRender<S>) {
        self.spare.lock().put_view(v);
    }

    /// Give back gradients when done with them (after [`Self::apply_gradients`]): a
    /// later [`Self::view_backward`] reuses their buffers. Optional.
    pub fn recycle_grads(&self, g: ModelGrads) {
        self.spare.lock().put_grads(g);
    }

    /// SH degree in use at the current iteration.
    pub fn sh_degree(&self) -> u32 {
        (self.iteration / self.settings.sh_interval.max(1)).min(self.settings.sh_degree)
    }

    pub fn field_on(&self) -> bool {
        self.settings.deform && self.iteration >= self.settings.static_iterations
    }

    /// The Gaussians at time `t` (deformed when the field is on), with the deltas used.
    pub fn deformed(&self, t: f32) -> (Splats, Option<(field::Deltas, field::MlpCache<f32>)>) {
        let (mut s, d) = if self.field_on() {
            let (d, cache) = self.field_deltas(t);
            (field::deform_splats(&self.splats, &d), Some((d, cache)))
        } else {
            (self.splats.clone(), None)
        };
        crate::motion::advance(&self.splats, t, &mut s);
        crate::parts::advance(&self.splats.parts, &self.splats.part, t, &mut s);
        (s, d)
    }

    /// Field deltas for every Gaussian at time `t`.
    fn field_deltas(&self, t: f32) -> (field::Deltas, field::MlpCache<f32>) {
        field::splat_deltas(&self.field, &self.splats, t, self.settings.dynamic_only)
    }

    /// Render the model at a camera and time.
    pub fn render<R: Rasterizer>(&self, r: &R, cam: &Camera, t: f32) -> RenderedImage {
        let (s, _) = self.deformed(t);
        r.render(&s, cam, self.sh_degree(), self.settings.background)
            .0
    }

    /// Gradients of a loss on a rendered view, from `∂L/∂rgb` (planar), `∂L/∂depth` and
    /// `∂L/∂alpha` where given (`d_planes`) and optionally `∂L/∂(rendered centres)` (from
    /// a loss on the deformed centres themselves, one per Gaussian), taken back through
    /// the rasterizer and the field to the canonical Gaussians, the field's parameters
    /// and the camera (in the buffers of the last gradients given to
    /// [`Self::recycle_grads`], if any).
    pub fn view_backward<R: Rasterizer>(
        &self,
        r: &R,
        v: &ViewRender<R::State>,
        d_rgb: &[f32],
        d_planes: Planes,
        d_means: Option<&[[f32; 3]]>,
    ) -> ModelGrads {
        let mut out = self.spare.lock().take_grads();
        let g = &mut out.splats;
        out.camera = r.backward_view_into(&v.deformed, &v.camera, &v.state, d_rgb, d_planes, g);
        if let Some(dm) = d_means {
            assert_eq!(dm.len(), g.means.len(), "view_backward: d_means size");
            for (a, b) in g.means.iter_mut().zip(dm) {
                (0..3).for_each(|c| a[c] += b[c]);
            }
        }
        // The parts' poses, and the Gaussians as the field left them.
        crate::parts::backward(
            &self.splats.parts,
            &self.splats.part,
            v.time,
            &v.deformed,
            g,
        );
        crate::motion::backward(&self.splats, v.time, &g.means, &mut g.motion);
        out.field.clear();
        if let Some((d, cache)) = &v.deltas {
            let mut spare = self.spare.lock();
            let Spare {
                field: work,
                delta_grads,
                rigidity_loss,
                ..
            } = &mut *spare;
            // The means' gradient passes through unchanged (it is also δx's).
            field::apply_deltas_backward_in_place(
                &self.splats.log_scales,
                &self.splats.rotations,
                d,
                &g.means,
                &g.sh_dc,
                &mut g.log_scales,
                &mut g.rotations,
                delta_grads,
            );
            // L_iso on the deformed centres, into δx (the canonical ones held fixed).
            *rigidity_loss = rigidity::Neighbours::backward(
                self.neighbours.as_ref(),
                &self.settings.rigidity,
                &v.deformed.means,
                delta_grads,
            );
            let dynamic_only = self.settings.dynamic_only;
            field::splat_deltas_backward_into(
                &self.field,
                &self.splats,
                dynamic_only,
                cache,
                delta_grads,
                work,
                &mut out.field,
            );
        }
        out
    }

    /// One Adam step of the canonical Gaussians (and of the field when `g.field` is not
    /// empty), then the densification statistics of `g` and the densification schedule.
    pub fn apply_gradients(&mut self, g: &ModelGrads) {
        let it = self.iteration;
        if !g.field.is_empty() {
            self.field_adam.groups[0].lr = ExpSchedule::new(
                self.settings.field_lr_init,
                self.settings.field_lr_final,
                self.settings.iterations as u64,
            )
            .at(it as u64);
            self.field_adam.step(0, &mut self.field.params, &g.field);
        }
        self.apply_grads(&g.splats, it);
        self.stats.add(&g.splats.screen_grad_norm, &g.splats.radius);
        self.iteration += 1;
        self.densify_if_due();
        let (on, s) = (self.field_on(), &self.settings);
        let nb = &mut self.neighbours;
        rigidity::Neighbours::refresh(nb, &s.rigidity, on, &self.splats, s.dynamic_only, it + 1);
    }

    /// The isometry term of the last [`Self::view_backward`] (0 when it is off).
    pub fn rigidity_loss(&self) -> f64 {
        self.spare.lock().rigidity_loss
    }

    /// The next view index of the shuffled epoch order (each view once per epoch).
    pub fn next_view(&mut self, views: usize) -> usize {
        use rand::seq::SliceRandom;
        if self.order.is_empty() {
            self.order = (0..views).collect();
            self.order.shuffle(&mut self.rng);
        }
        self.order.pop().expect("views")
    }

    /// Resolve the automatic Gaussian cap from the size of the train frames (once).
    pub fn resolve_cap(&mut self, pixels: usize) {
        if self.settings.densify.max_gaussians == 0 {
            self.settings.densify.max_gaussians = self.settings.gaussian_cap(pixels);
        }
    }

    /// One optimisation step on a random view (each view once per epoch).
    pub fn step<R: Rasterizer>(&mut self, r: &R, views: &[View]) -> StepInfo
    where
        R::State: Send + 'static,
    {
        self.resolve_cap(views[0].pixels());
        self.probe_field_if_due(r, views);
        let k = self.next_view(views.len());
        let life_t = self.life_time(views, k);
        let (view, field_on) = (&views[k], self.field_on());
        let target = if self.coarse_views(views) {
            &self.coarse[k]
        } else {
            view
        };
        let rendered = self.render_view_living(r, &target.camera, target.time, life_t);
        let (loss, grad) = self.rgb_loss(&rendered.image, &target.rgb);
        let psnr = metrics::psnr_u8(&rendered.image.rgb, &target.rgb);
        let mut tracks = std::mem::take(&mut self.tracks);
        let mut priors = std::mem::take(&mut tracks.priors);
        let (ids, st) = (&self.splats.track, &self.settings.tracks);
        let d_means = tracks.gradient(&rendered.deformed.means, ids, k, &view.camera, st);
        let (d_field, d_own) = if st.into_field {
            (d_means, None)
        } else {
            (None, d_means)
        };
        let planes =
            (priors.gradient(&rendered.image, k, st, &self.splats)).unwrap_or(Planes::NONE);
        let mut g = self.view_backward(r, &rendered, &grad, planes, d_field);
        if let Some(d) = d_own {
            crate::motion::add_centre_gradient(&self.splats, view.time, d, &mut g.splats);
        }
        let prior_error = (priors.last.1 > 0).then_some(priors.last_rel_error);
        tracks.priors = priors;
        self.tracks = tracks;
        self.add_shape_term(rendered.time, rendered.life_time, &mut g);
        self.recycle_view(rendered);
        self.apply_gradients(&g);
        self.recycle_grads(g);
        self.split_static_if_due(views);
        self.size_if_due(r, views);
        StepInfo {
            iteration: self.iteration,
            loss,
            psnr,
            gaussians: self.splats.len(),
            field_on,
            prior_error,
        }
    }

    /// The model as it renders now: its field while on, at the SH degree in use.
    fn candidate(&self) -> Candidate<'_> {
        Candidate {
            splats: &self.splats,
            field: self.field_on().then_some(&self.field),
            dynamic_only: self.settings.dynamic_only,
            sh_degree: self.sh_degree(),
            deltas: None,
        }
    }

    /// Make the static/dynamic split when its iteration has come ([`static_split`]).
    pub(crate) fn split_static_if_due(&mut self, views: &[View]) {
        if self.split.is_some() || self.static_split_iteration() != Some(self.iteration) {
            return;
        }
        let tol = self.settings.static_tolerance_px;
        let (model, summary) =
            static_split::decide(&self.field, &self.splats, views, tol, self.iteration);
        self.splats = model;
        self.settings.dynamic_only = true;
        // The isometry term's lists hold the Gaussians the field moved until now.
        self.neighbours = None;
        if summary.dynamic == 0 {
            // Nothing moves: the model needs no field at all.
            self.settings.deform = false;
            self.settings.dynamic_only = false;
            self.splats.dynamic.clear();
        }
        self.split = Some(summary);
    }

    /// Size the model when its iteration has come ([`sizing`]): the sizing decides, the
    /// trainer goes on with the sized model and the settings that go with it.
    pub fn size_if_due<R: Rasterizer>(&mut self, r: &R, views: &[View]) {
        if self.sizing.is_some() || self.sizing_iteration() != Some(self.iteration) {
            return;
        }
        let start = std::time::Instant::now();
        let judged = spread(views, self.settings.size.views);
        let mut judge = Judge::new(r, &judged, self.settings.background);
        let field_trained = self.iteration > self.settings.static_iterations;
        let size = self.settings.size;
        let d = sizing::decide(&mut judge, self.candidate(), &size, field_trained);
        // The settings the sized model trains with.
        let s = &mut self.settings;
        let cap_before = s.densify.max_gaussians;
        if d.summary.field_dropped {
            (s.deform, s.dynamic_only) = (false, false);
        } else if d.summary.split.is_some() {
            s.dynamic_only = true;
        }
        s.sh_degree = d.sh_degree.unwrap_or(s.sh_degree);
        s.densify.max_gaussians = d.kept().unwrap_or(cap_before);
        let sum = d.apply(&mut self.splats, &mut self.adam, &mut self.stats);
        // The sized model as it renders now.
        let train_psnr_after = judge.psnr(&self.candidate());
        self.sizing = Some(SizingSummary {
            iteration: self.iteration,
            gaussian_cap_before: cap_before,
            train_psnr_after,
            gaussians: self.splats.len(),
            views: judged.len(),
            evaluations: judge.evaluations,
            seconds: start.elapsed().as_secs_f64(),
            ..sum
        });
    }

    /// Run the field's width probe when the field is switched on ([`field_probe`]): the
    /// model goes on from the chosen candidate, `iteration` advanced by the probe's length.
    pub fn probe_field_if_due<R: Rasterizer>(&mut self, r: &R, views: &[View])
    where
        R::State: Send + 'static,
    {
        if self.field_probe.is_some() || self.iteration != self.settings.static_iterations {
            return;
        }
        let Some(k) = self.field_probe_iterations() else {
            return;
        };
        let s = &self.settings;
        let widths = field_probe::candidate_widths(s.field.width, s.size.field_halvings);
        let train = |width, train_views: &[View]| {
            let mut p = self.fork_with_field_width(width);
            for _ in 0..k {
                p.step(r, train_views);
            }
            p
        };
        let score = |p: &Trainer, held: &[View]| {
            Judge::new(r, held, p.settings.background).psnr(&p.candidate())
        };
        let tolerance_db = s.size.tolerance_db;
        let Some((chosen, sum)) = field_probe::run(views, widths, tolerance_db, train, score)
        else {
            return;
        };
        self.adopt_probe(chosen);
        self.field_probe = Some(FieldProbeSummary {
            iteration: self.settings.static_iterations,
            probe_iterations: k,
            ..sum
        });
    }

    /// A copy of the training state with a fresh field of `width` (no probe of its own).
    fn fork_with_field_width(&self, width: usize) -> Trainer {
        let mut settings = self.settings.clone();
        settings.field.width = width;
        settings.size.field_probe = 0;
        let mut t = Trainer::new(settings, self.splats.clone(), self.extent);
        t.adam = self.adam.clone();
        t.parts_adam = self.parts_adam.clone();
        t.stats = self.stats.clone();
        t.iteration = self.iteration;
        (t.split, t.tracks) = (self.split, self.tracks.clone());
        t
    }

    /// Go on from a probe's state (its Gaussians, field, optimiser and iteration).
    fn adopt_probe(&mut self, p: Trainer) {
        self.settings.field = p.settings.field;
        self.splats = p.splats;
        self.field = p.field;
        self.adam = p.adam;
        self.field_adam = p.field_adam;
        self.parts_adam = p.parts_adam;
        self.stats = p.stats;
        self.iteration = p.iteration;
        // Buffers sized for the old field.
        self.spare.clear();
    }

    fn apply_grads(&mut self, g: &SplatGrads, it: u32) {
        let s = &self.settings;
        let pos = ExpSchedule::new(
            s.position_lr_init * self.extent as f64,
            s.position_lr_final * self.extent as f64,
            s.iterations as u64,
        );
        self.adam.groups[0].lr = pos.at(it as u64);
        self.adam.groups[6].lr = pos.at(it as u64);
        let sp = &mut self.splats;
        self.adam
            .step(0, sp.means.as_flattened_mut(), g.means.as_flattened());
        self.adam.step(
            1,
            sp.log_scales.as_flattened_mut(),
            g.log_scales.as_flattened(),
        );
        self.adam.step(
            2,
            sp.rotations.as_flattened_mut(),
            g.rotations.as_flattened(),
        );
        self.adam.step(3, &mut sp.opacity_logits, &g.opacity_logits);
        self.adam
            .step(4, sp.sh_dc.as_flattened_mut(), g.sh_dc.as_flattened());
        self.adam
            .step(5, sp.sh_rest.as_flattened_mut(), g.sh_rest.as_flattened());
        if !sp.motion.is_empty() && g.motion.len() == sp.motion.len() {
            self.adam
                .step(6, sp.motion.as_flattened_mut(), g.motion.as_flattened());
        }
        let parts = &mut sp.parts;
        let share = self.part_pose_lr;
        let train = share > 0.0;
        if train && !parts.rot.is_empty() && g.part_rot.len() == parts.rot.len() {
            let n = parts.rot.len();
            if self.parts_adam.groups.len() != 2 || self.parts_adam.groups[0].m.len() != 4 * n {
                self.parts_adam = Adam::default();
                self.parts_adam
                    .add_group("part_rot", s.rotation_lr, 1e-15, 4, 4 * n);
                self.parts_adam
                    .add_group("part_shift", 0.0, 1e-15, 3, 3 * n);
            }
            self.parts_adam.groups[0].lr = share * s.rotation_lr;
            self.parts_adam.groups[1].lr = share * pos.at(it as u64);
            let a = &mut self.parts_adam;
            a.step(0, parts.rot.as_flattened_mut(), g.part_rot.as_flattened());
            a.step(
                1,
                parts.shift.as_flattened_mut(),
                g.part_shift.as_flattened(),
            );
        }
    }

    fn densify_if_due(&mut self) {
        let d = self.settings.densify;
        let it = self.iteration;
        if it < d.until_iter && it > d.from_iter && d.interval > 0 && it.is_multiple_of(d.interval)
        {
            let size_prune = d.opacity_reset_interval > 0 && it > d.opacity_reset_interval;
            let sp = &self.splats;
            let plan = densify::plan(
                &Geometry {
                    means: &sp.means,
                    log_scales: &sp.log_scales,
                    rotations: &sp.rotations,
                    opacity_logits: &sp.opacity_logits,
                },
                &self.stats,
                &d,
                self.extent,
                size_prune,
                self.settings.seed ^ it as u64,
            );
            let new = plan.apply(sp);
            let src = plan.moment_sources();
            for k in 0..GROUPS.len() {
                self.adam.remap(k, &src);
            }
            self.splats = new;
            self.stats = GradStats::new(self.splats.len());
        }
        if d.opacity_reset_interval > 0
            && it < d.until_iter
            && it.is_multiple_of(d.opacity_reset_interval)
        {
            densify::reset_opacity(&mut self.splats.opacity_logits);
            let n = self.splats.len();
            self.adam.reset_items(3, 0..n);
        }
    }
}
