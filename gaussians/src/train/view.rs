//! What the trainer takes and gives: a training [`View`], the model's render of one
//! ([`ViewRender`], with what its backward pass needs), the gradients of a loss on the
//! model ([`ModelGrads`]) and a step's figures ([`StepInfo`]).

use crate::Rasterizer;
use crate::field;
use crate::raster::RenderedImage;
use crate::splats::{SplatGrads, Splats};
use scene::{Camera, metrics};

/// A training view: camera, normalised time, planar RGB target.
#[derive(Clone, Debug)]
pub struct View {
    pub camera: Camera,
    pub time: f32,
    pub rgb: Vec<f32>,
}

impl super::Trainer {
    /// Render the current model (deformed to `t` when the field is on) at `camera`,
    /// keeping what [`Self::view_backward`] needs (in the buffers of the last view given
    /// to [`Self::recycle_view`], if any).
    pub fn render_view<R: Rasterizer>(&self, r: &R, camera: &Camera, t: f32) -> ViewRender<R::State>
    where
        R::State: Send + 'static,
    {
        self.render_view_living(r, camera, t, t)
    }

    /// [`Self::render_view`] with the lives read at `life_t` ([`crate::motion::life_clock_shared`]).
    pub fn render_view_living<R: Rasterizer>(
        &self,
        r: &R,
        camera: &Camera,
        t: f32,
        life_t: f32,
    ) -> ViewRender<R::State>
    where
        R::State: Send + 'static,
    {
        let old = self.spare.lock().take_view::<R::State>();
        let (mut deformed, old_deltas, reuse) = match old {
            Some(v) => (v.deformed, v.deltas, Some((v.image, v.state))),
            None => (Splats::default(), None, None),
        };
        let deltas = if self.field_on() {
            let (mut d, mut cache) = old_deltas.unwrap_or_default();
            field::splat_deltas_into(
                &self.field,
                &self.splats,
                t,
                self.settings.dynamic_only,
                &mut self.spare.lock().field,
                &mut d,
                &mut cache,
            );
            field::deform_splats_into(&self.splats, &d, &mut deformed);
            Some((d, cache))
        } else {
            deformed.clone_from(&self.splats);
            None
        };
        crate::motion::advance_living(&self.splats, t, life_t, &mut deformed);
        crate::parts::advance(&self.splats.parts, &self.splats.part, t, &mut deformed);
        let (image, state) = r.render_reusing(
            &deformed,
            camera,
            self.sh_degree(),
            self.settings.background,
            reuse,
        );
        ViewRender {
            image,
            camera: *camera,
            time: t,
            life_time: life_t,
            deformed,
            deltas,
            state,
        }
    }

    /// When train view `k` of `views` (in time order) reads the Gaussians' lives: its
    /// own time, or with windowed copies and `tracks.handover = "frame"` at a shared
    /// frame either window's ([`crate::motion::life_clock_shared`]).
    pub fn life_time(&mut self, views: &[View], k: usize) -> f32 {
        let t = views[k].time;
        let shared = self.settings.tracks.handover == crate::tracks::Handover::Frame;
        if !shared || self.splats.life.is_empty() {
            return t;
        }
        let prev = (k.checked_sub(1).map(|j| views[j].time)).filter(|&p| p < t);
        let unit: f32 = rand::RngExt::random(&mut self.rng);
        crate::motion::life_clock_shared(t, prev, unit)
    }

    /// [`Self::view_backward`] with `L_depth` ([`crate::tracks::prior_loss`]) joined at
    /// train view `view` (where it has an aligned prior).
    pub fn view_backward_with_prior<R: crate::Rasterizer>(
        &mut self,
        r: &R,
        v: &ViewRender<R::State>,
        d_rgb: &[f32],
        view: Option<usize>,
        d_means: Option<&[[f32; 3]]>,
    ) -> ModelGrads {
        let mut priors = std::mem::take(&mut self.tracks.priors);
        priors.last = (0.0, 0);
        let st = &self.settings.tracks;
        let planes = view.and_then(|k| priors.gradient(&v.image, k, st, &self.splats));
        let mut g = self.view_backward(r, v, d_rgb, planes.unwrap_or_default(), d_means);
        self.tracks.priors = priors;
        if view.is_some() {
            self.add_shape_term(v.time, v.life_time, &mut g);
        }
        g
    }

    /// The tracked Gaussians' shape term (`tracks.rigidity`, [`crate::tracks::rigid`]) at
    /// a train view of time `t` whose lives were read at `life_t`, into `g`'s centres and
    /// trajectories; its pairs are rebuilt every `RIGID_REFRESH` iterations and whenever
    /// the Gaussians change.
    pub fn add_shape_term(&mut self, t: f32, life_t: f32, g: &mut ModelGrads) {
        let (w, k) = (
            self.settings.tracks.rigidity,
            self.settings.tracks.rigidity_neighbours,
        );
        let term = &mut self.tracks;
        if w <= 0.0 || self.splats.motion.is_empty() {
            (term.shape, term.last_shape) = (None, 0.0);
            return;
        }
        let it = self.iteration;
        let n = self.splats.len();
        let fresh = (term.shape.as_ref())
            .is_some_and(|p| p.gaussians == n && it < p.built_at + RIGID_REFRESH);
        if !fresh {
            term.shape = Some(crate::tracks::rigid::Pairs::build(
                &self.splats,
                k as usize,
                self.settings.tracks.rigidity_far as usize,
                it,
            ));
        }
        let pairs = term.shape.as_ref().expect("built above");
        let gs = &mut g.splats;
        gs.motion.resize(n, [0.0; 6]);
        let s = &self.splats;
        let l = pairs.loss(
            w,
            &s.means,
            &s.motion,
            t,
            life_t,
            &mut gs.means,
            &mut gs.motion,
        );
        term.last_shape = f64::from(l);
    }

    /// The RGB loss of the warm-up (`(1−λ)·L1 + λ·D-SSIM`) of a render against a planar
    /// target, and its gradient w.r.t. the render.
    pub fn rgb_loss(&self, image: &RenderedImage, target: &[f32]) -> (f64, Vec<f32>) {
        let (w, h) = (image.width, image.height);
        let lam = self.settings.dssim_weight;
        let (l1, mut grad) = metrics::l1_loss(&image.rgb, target);
        let mut loss = (1.0 - lam) * l1;
        if lam > 0.0 {
            let (ds, gd) = metrics::dssim_loss(&image.rgb, target, w, h);
            loss += lam * ds;
            for (g, d) in grad.iter_mut().zip(gd) {
                *g = (1.0 - lam) as f32 * *g + lam as f32 * d;
            }
        }
        (loss, grad)
    }

    /// Whether this step trains at half resolution (`coarse_until`); the half views are
    /// built at the first such step and dropped after the last.
    pub(super) fn coarse_views(&mut self, views: &[View]) -> bool {
        let pixels = views.first().map_or(0, View::pixels);
        let on = self.iteration < self.settings.coarse_end(pixels);
        if on && self.coarse.len() != views.len() {
            self.coarse = views.iter().map(View::half).collect();
        } else if !on && !self.coarse.is_empty() {
            self.coarse = Vec::new();
        }
        on
    }
}

impl View {
    /// Pixels of the view's image.
    pub fn pixels(&self) -> usize {
        self.rgb.len() / 3
    }

    /// The view at half resolution (coarse-to-fine): each pixel the mean of a 2 × 2
    /// block (an odd last row or column dropped), the camera's focal lengths halved and
    /// its principal point moved so that each pixel's ray passes through its block's
    /// centre (pixel centres at whole coordinates: `x' = (x − ½) / 2`).
    pub fn half(&self) -> View {
        let k = &self.camera.intrinsics;
        let (w, h) = (k.width as usize, k.height as usize);
        let (w2, h2) = (w / 2, h / 2);
        let mut rgb = Vec::with_capacity(3 * w2 * h2);
        for c in 0..3 {
            let plane = &self.rgb[c * w * h..(c + 1) * w * h];
            for y in 0..h2 {
                let (a, b) = (&plane[2 * y * w..], &plane[(2 * y + 1) * w..]);
                for x in 0..w2 {
                    let s = a[2 * x] + a[2 * x + 1] + b[2 * x] + b[2 * x + 1];
                    rgb.push(0.25 * s);
                }
            }
        }
        let mut camera = self.camera;
        let i = &mut camera.intrinsics;
        (i.width, i.height) = (w2 as u32, h2 as u32);
        (i.fx, i.fy) = (0.5 * k.fx, 0.5 * k.fy);
        (i.cx, i.cy) = (0.5 * (k.cx - 0.5), 0.5 * (k.cy - 0.5));
        View {
            camera,
            time: self.time,
            rgb,
        }
    }
}

/// Iterations between rebuilds of the shape term's pairs.
const RIGID_REFRESH: u32 = 100;

/// A view rendered by the current model, with what its backward needs.
pub struct ViewRender<S> {
    pub image: RenderedImage,
    pub camera: Camera,
    /// Normalised time of the view.
    pub time: f32,
    /// The time the Gaussians' lives were read at ([`crate::motion::advance_living`]).
    pub life_time: f32,
    /// The Gaussians as rendered (deformed to the view's time).
    pub deformed: Splats,
    pub(super) deltas: Option<(field::Deltas, field::MlpCache<f32>)>,
    pub(super) state: S,
}

/// Gradients of a loss on the model: canonical Gaussians (with the densification
/// statistics of the render they came from), the field's parameters (empty when the
/// field is off) and the camera (camera-frame right twist, `raster::apply_twist`).
#[derive(Clone, Debug, Default)]
pub struct ModelGrads {
    pub splats: SplatGrads,
    pub field: Vec<f32>,
    pub camera: [f64; 6],
}

/// Per-step figures.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepInfo {
    pub iteration: u32,
    pub loss: f64,
    pub psnr: f64,
    pub gaussians: usize,
    pub field_on: bool,
    /// With `L_depth` at this view: the render's mean relative depth difference from
    /// the aligned prior.
    pub prior_error: Option<f64>,
}
