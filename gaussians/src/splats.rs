//! The Gaussians as trainable parameters: [`Splats`] (struct of arrays, what the
//! rasterizer, the trainer and the model files share), [`Gaussian`] (one row of it) and
//! [`SplatGrads`] (what a rasterizer's backward returns).

/// Trainable Gaussians (raw: log-scale, logit opacity, quaternion w-first; SH DC and
/// rest stored apart as 3DGS `features_dc` / `features_rest`, rest coefficient-major:
/// `rest[i][(k−1)·3 + c]` for k = 1..16).
///
/// Build one with [`Splats::push`] or by collecting [`Gaussian`]s. `clone_from` keeps
/// the destination's allocations (a training loop copies the model every iteration).
#[derive(Debug, Default, PartialEq)]
pub struct Splats {
    pub means: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    pub rotations: Vec<[f32; 4]>,
    pub opacity_logits: Vec<f32>,
    pub sh_dc: Vec<[f32; 3]>,
    pub sh_rest: Vec<[f32; 45]>,
    /// Per Gaussian: deformed by the field (used when `TrainSettings::dynamic_only`).
    /// Empty when the Gaussians carry no flags (every Gaussian counts as dynamic).
    pub dynamic: Vec<bool>,
    /// Per Gaussian: its own trajectory `[v; a]` (`motion.rs`). Empty when the
    /// Gaussians have none (every centre still unless the field moves it).
    pub motion: Vec<[f32; 6]>,
    /// Per Gaussian: the index of the track that pulls it (`tracks::loss`, the warm-up's
    /// `L_track`), [`NO_TRACK`] for none. Empty when no Gaussian has a track.
    pub track: Vec<u32>,
    /// Per Gaussian: the span of normalised time it exists in, `[from, to)`
    /// (`motion::advance` hides it outside: a trajectory fitted over a window of the
    /// tracks, `tracks.window`). Empty when every Gaussian exists at every time.
    pub life: Vec<[f32; 2]>,
    /// Per Gaussian: the rigid part that moves it ([`crate::parts`]), `parts::NO_PART`
    /// for none. Empty when there are no parts.
    pub part: Vec<u32>,
    /// The parts' poses (shared by their members; empty without parts).
    pub parts: crate::parts::Parts,
}

/// A life spanning every time (an entry of [`Splats::life`]).
pub const ALWAYS: [f32; 2] = [f32::MIN, f32::MAX];

/// No track (a Gaussian's entry in [`Splats::track`]).
pub const NO_TRACK: u32 = u32::MAX;

/// A track pulls one Gaussian: after densification has copied Gaussians (each copy with
/// its source's entry), the first copy of each keeps the track, the others none.
pub fn first_copies(mut ids: Vec<u32>) -> Vec<u32> {
    let mut seen = std::collections::HashSet::new();
    for id in ids.iter_mut() {
        if *id != NO_TRACK && !seen.insert(*id) {
            *id = NO_TRACK;
        }
    }
    ids
}

impl Clone for Splats {
    fn clone(&self) -> Self {
        let mut s = Splats::default();
        s.clone_from(self);
        s
    }
    fn clone_from(&mut self, src: &Self) {
        self.means.clone_from(&src.means);
        self.log_scales.clone_from(&src.log_scales);
        self.rotations.clone_from(&src.rotations);
        self.opacity_logits.clone_from(&src.opacity_logits);
        self.sh_dc.clone_from(&src.sh_dc);
        self.sh_rest.clone_from(&src.sh_rest);
        self.dynamic.clone_from(&src.dynamic);
        self.motion.clone_from(&src.motion);
        self.track.clone_from(&src.track);
        self.life.clone_from(&src.life);
        self.part.clone_from(&src.part);
        self.parts.clone_from(&src.parts);
    }
}

/// One Gaussian's raw parameters (a row of [`Splats`], same conventions).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gaussian {
    pub mean: [f32; 3],
    pub log_scale: [f32; 3],
    /// Quaternion `(w, x, y, z)`, not necessarily normalised.
    pub rotation: [f32; 4],
    pub opacity_logit: f32,
    pub sh_dc: [f32; 3],
    pub sh_rest: [f32; 45],
    pub dynamic: bool,
}

impl Gaussian {
    /// An isotropic Gaussian (scale `exp(log_scale)` on every axis, identity rotation)
    /// of constant colour (SH DC only), flagged static.
    pub fn isotropic(mean: [f32; 3], log_scale: f32, opacity_logit: f32, sh_dc: [f32; 3]) -> Self {
        Gaussian {
            mean,
            log_scale: [log_scale; 3],
            rotation: [1.0, 0.0, 0.0, 0.0],
            opacity_logit,
            sh_dc,
            sh_rest: [0.0; 45],
            dynamic: false,
        }
    }
}

impl Splats {
    /// No Gaussians, room for `n`.
    pub fn with_capacity(n: usize) -> Self {
        Splats {
            means: Vec::with_capacity(n),
            log_scales: Vec::with_capacity(n),
            rotations: Vec::with_capacity(n),
            opacity_logits: Vec::with_capacity(n),
            sh_dc: Vec::with_capacity(n),
            sh_rest: Vec::with_capacity(n),
            dynamic: Vec::with_capacity(n),
            motion: Vec::new(),
            track: Vec::new(),
            life: Vec::new(),
            part: Vec::new(),
            parts: Default::default(),
        }
    }

    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Append a Gaussian, its dynamic flag included (and a still trajectory when the
    /// Gaussians have trajectories).
    pub fn push(&mut self, g: Gaussian) {
        if !self.motion.is_empty() {
            self.motion.push([0.0; 6]);
        }
        if !self.track.is_empty() {
            self.track.push(NO_TRACK);
        }
        if !self.life.is_empty() {
            self.life.push(ALWAYS);
        }
        if !self.part.is_empty() {
            self.part.push(crate::parts::NO_PART);
        }
        self.means.push(g.mean);
        self.log_scales.push(g.log_scale);
        self.rotations.push(g.rotation);
        self.opacity_logits.push(g.opacity_logit);
        self.sh_dc.push(g.sh_dc);
        self.sh_rest.push(g.sh_rest);
        self.dynamic.push(g.dynamic);
    }

    /// Gaussian `i` (a missing flag reads as dynamic). Panics when `i ≥ len()`.
    pub fn get(&self, i: usize) -> Gaussian {
        Gaussian {
            mean: self.means[i],
            log_scale: self.log_scales[i],
            rotation: self.rotations[i],
            opacity_logit: self.opacity_logits[i],
            sh_dc: self.sh_dc[i],
            sh_rest: self.sh_rest[i],
            dynamic: self.is_dynamic(i),
        }
    }

    /// Whether the field deforms Gaussian `i` (a missing flag counts as dynamic).
    pub fn is_dynamic(&self, i: usize) -> bool {
        self.dynamic.get(i).copied().unwrap_or(true)
    }
}

impl Extend<Gaussian> for Splats {
    fn extend<I: IntoIterator<Item = Gaussian>>(&mut self, iter: I) {
        for g in iter {
            self.push(g);
        }
    }
}

impl FromIterator<Gaussian> for Splats {
    fn from_iter<I: IntoIterator<Item = Gaussian>>(iter: I) -> Self {
        let mut s = Splats::default();
        s.extend(iter);
        s
    }
}

/// Gradients from the rasterizer, per Gaussian, plus densification statistics.
#[derive(Clone, Debug, Default)]
pub struct SplatGrads {
    pub means: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    pub rotations: Vec<[f32; 4]>,
    pub opacity_logits: Vec<f32>,
    pub sh_dc: Vec<[f32; 3]>,
    pub sh_rest: Vec<[f32; 45]>,
    /// ‖∂L/∂(projected mean)‖ in NDC units as 3DGS (for densification).
    pub screen_grad_norm: Vec<f32>,
    /// Screen radius in pixels (0 = not rendered).
    pub radius: Vec<f32>,
    /// The trajectories' gradient (`motion.rs`; empty without them).
    pub motion: Vec<[f32; 6]>,
    /// The parts' knot poses' gradient (`parts.rs`; empty without parts).
    pub part_rot: Vec<[f32; 4]>,
    pub part_shift: Vec<[f32; 3]>,
}

impl SplatGrads {
    /// All-zero gradients for `n` Gaussians.
    pub fn zeros(n: usize) -> Self {
        SplatGrads {
            means: vec![[0.0; 3]; n],
            log_scales: vec![[0.0; 3]; n],
            rotations: vec![[0.0; 4]; n],
            opacity_logits: vec![0.0; n],
            sh_dc: vec![[0.0; 3]; n],
            sh_rest: vec![[0.0; 45]; n],
            screen_grad_norm: vec![0.0; n],
            radius: vec![0.0; n],
            motion: Vec::new(),
            part_rot: Vec::new(),
            part_shift: Vec::new(),
        }
    }

    /// Resize every column to `n` keeping the allocations; the values are left for the
    /// caller to overwrite (new entries are zero).
    pub fn resize(&mut self, n: usize) {
        fn fit<T: Copy + Default>(v: &mut Vec<T>, n: usize) {
            v.truncate(n);
            v.resize(n, T::default());
        }
        fit(&mut self.means, n);
        fit(&mut self.log_scales, n);
        fit(&mut self.rotations, n);
        fit(&mut self.opacity_logits, n);
        fit(&mut self.sh_dc, n);
        self.sh_rest.truncate(n);
        self.sh_rest.resize(n, [0.0; 45]);
        fit(&mut self.screen_grad_norm, n);
        fit(&mut self.radius, n);
    }
}
