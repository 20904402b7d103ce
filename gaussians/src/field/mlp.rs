//! The Deform-GS deformation MLP, hand-written on `gemm`:
//! `(δx, δq, δs) = F(γ(x), γ(t))` (DEGS §3.1, the deformation field of Eq. 3).
//! Layers `D × W` with ReLU, the encoded input concatenated back after layer
//! `D / 2` when `D ≥ 5` (Deform-GS: after layer 4 of 8), one linear head of 10 outputs
//! (δx 3, δq 4, δs 3; equal to three separate heads), 13 with a colour field (δc 3),
//! no output activation.

use super::linalg::{Real, View, matmul};
use super::settings::FieldSettings;
use rand::{RngExt, SeedableRng};

pub use super::settings::HEAD_OUT;

/// Offsets of one linear layer inside the flat parameter vector. Weights are stored
/// `[in × out]` row-major (so `y = a · W + b`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LayerLayout {
    pub weight: usize,
    pub bias: usize,
    pub fan_in: usize,
    pub fan_out: usize,
}

/// NeRF positional encoding with the raw input kept:
/// `[v, sin(2⁰v), cos(2⁰v), …, sin(2^{L−1}v), cos(2^{L−1}v)]`.
pub(crate) fn encoded_len(dims: usize, freqs: usize) -> usize {
    dims * (1 + 2 * freqs)
}

fn encode_into<T: Real>(v: &[T], freqs: usize, out: &mut [T]) {
    let d = v.len();
    out[..d].copy_from_slice(v);
    // sin/cos of 2^l·x by the double-angle recurrence, in f64 (exact to ~1e-13 after
    // 10 doublings, far below f32 resolution; one libm call per input value).
    for (i, &x) in v.iter().enumerate() {
        let (mut sn, mut cs) = x.to_f64().sin_cos();
        for l in 0..freqs {
            out[d + 2 * l * d + i] = T::from_f64(sn);
            out[d + (2 * l + 1) * d + i] = T::from_f64(cs);
            (sn, cs) = (2.0 * sn * cs, cs * cs - sn * sn);
        }
    }
}

/// Multi-layer perceptron with all parameters in one flat vector.
#[derive(Clone, Debug)]
pub struct Mlp<T: Real> {
    pub settings: FieldSettings,
    pub params: Vec<T>,
    pub layers: Vec<LayerLayout>,
}

/// Activations kept from the forward pass for the backward pass.
#[derive(Clone, Debug, Default)]
pub struct MlpCache<T: Real> {
    pub n: usize,
    /// Encoded input `n × in_dim`.
    pub input: Vec<T>,
    /// Post-ReLU output of each hidden layer, `n × W`.
    pub hidden: Vec<Vec<T>>,
}

impl<T: Real> Mlp<T> {
    pub fn input_dim(s: &FieldSettings) -> usize {
        encoded_len(3, s.pos_freqs) + encoded_len(1, s.time_freqs)
    }

    /// Index of the hidden layer after which the input is concatenated back, if any.
    pub fn skip_after(s: &FieldSettings) -> Option<usize> {
        (s.depth >= 5).then_some(s.depth / 2)
    }

    /// Layout of the flat parameter vector.
    pub fn layout(s: &FieldSettings) -> Vec<LayerLayout> {
        let in_dim = Self::input_dim(s);
        let skip = Self::skip_after(s);
        let mut layers = Vec::new();
        let mut off = 0;
        let mut push = |fan_in: usize, fan_out: usize| {
            layers.push(LayerLayout {
                weight: off,
                bias: off + fan_in * fan_out,
                fan_in,
                fan_out,
            });
            off += fan_in * fan_out + fan_out;
        };
        for i in 0..s.depth {
            let fan_in = if i == 0 {
                in_dim
            } else if Some(i - 1) == skip {
                s.width + in_dim
            } else {
                s.width
            };
            push(fan_in, s.width);
        }
        let head_in = if s.depth == 0 { in_dim } else { s.width };
        push(head_in, s.head_out());
        layers
    }

    pub fn param_count(s: &FieldSettings) -> usize {
        Self::layout(s)
            .last()
            .map(|l| l.bias + l.fan_out)
            .unwrap_or(0)
    }

    /// PyTorch `nn.Linear` default init: weight and bias ~ U(±1/√fan_in).
    pub fn new(settings: FieldSettings, seed: u64) -> Self {
        let layers = Self::layout(&settings);
        let mut params = vec![T::ZERO; Self::param_count(&settings)];
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        for l in &layers {
            let bound = 1.0 / (l.fan_in as f64).sqrt();
            for p in &mut params[l.weight..l.bias + l.fan_out] {
                *p = T::from_f64(rng.random_range(-bound..bound));
            }
        }
        Mlp {
            settings,
            params,
            layers,
        }
    }

    /// The same network with a colour head ([`FieldSettings::color`]): every weight
    /// kept, the three colour outputs starting at zero (weights and bias), so it deforms
    /// exactly as before until trained. Itself when it has one.
    pub fn with_color(&self) -> Self {
        if self.settings.color {
            return self.clone();
        }
        let settings = FieldSettings {
            color: true,
            ..self.settings
        };
        let layers = Self::layout(&settings);
        let mut params = vec![T::ZERO; Self::param_count(&settings)];
        let (old, new) = (
            self.layers.last().expect("head"),
            layers.last().expect("head"),
        );
        params[..old.weight].copy_from_slice(&self.params[..old.weight]);
        for j in 0..old.fan_in {
            let (a, b) = (old.weight + j * old.fan_out, new.weight + j * new.fan_out);
            params[b..b + old.fan_out].copy_from_slice(&self.params[a..a + old.fan_out]);
        }
        params[new.bias..new.bias + old.fan_out]
            .copy_from_slice(&self.params[old.bias..old.bias + old.fan_out]);
        Mlp {
            settings,
            params,
            layers,
        }
    }

    /// Set the output head's weights and bias to zero: the field outputs zero deltas
    /// until trained. The head's weight gradient `aᵀ·g` is non-zero, so training moves
    /// the head first and the hidden layers follow.
    pub fn zero_head(&mut self) {
        if let Some(head) = self.layers.last().copied() {
            self.params[head.weight..head.bias + head.fan_out].fill(T::ZERO);
        }
    }

    /// Build the encoded input rows `[γ(x), γ(t)]`. `t` has length 1 (broadcast) or n.
    pub fn encode(&self, x: &[[T; 3]], t: &[T]) -> Vec<T> {
        let mut out = Vec::new();
        self.encode_into_buf(x, t, &mut out);
        out
    }

    /// [`Self::encode`] into `out` (resized; its allocation reused).
    fn encode_into_buf(&self, x: &[[T; 3]], t: &[T], out: &mut Vec<T>) {
        let s = &self.settings;
        let in_dim = Self::input_dim(s);
        let px = encoded_len(3, s.pos_freqs);
        assert!(t.len() == 1 || t.len() == x.len(), "time batch length");
        fit(out, x.len() * in_dim);
        let chunk = 256;
        use rayon::prelude::*;
        out.par_chunks_mut(in_dim * chunk)
            .enumerate()
            .for_each(|(c, rows)| {
                for (r, row) in rows.chunks_mut(in_dim).enumerate() {
                    let i = c * chunk + r;
                    let ti = if t.len() == 1 { t[0] } else { t[i] };
                    encode_into(&x[i], s.pos_freqs, &mut row[..px]);
                    encode_into(&[ti], s.time_freqs, &mut row[px..]);
                }
            });
    }

    /// Forward pass: returns `n × head_out` outputs (δx, δq, δs and δc per row) and the
    /// cache.
    pub fn forward(&self, x: &[[T; 3]], t: &[T]) -> (Vec<T>, MlpCache<T>) {
        let (mut out, mut cache) = (Vec::new(), MlpCache::default());
        self.forward_into(x, t, &mut cache, &mut MlpScratch::default(), &mut out);
        (out, cache)
    }

    /// [`Self::forward`] into reused buffers: `cache` and `out` are overwritten (same
    /// values as `forward`'s, bit for bit); their allocations and the scratch's are kept
    /// from call to call, so a training loop allocates nothing here once warm.
    pub fn forward_into(
        &self,
        x: &[[T; 3]],
        t: &[T],
        cache: &mut MlpCache<T>,
        scratch: &mut MlpScratch<T>,
        out: &mut Vec<T>,
    ) {
        let n = x.len();
        let s = &self.settings;
        let in_dim = Self::input_dim(s);
        let skip = Self::skip_after(s);
        cache.n = n;
        self.encode_into_buf(x, t, &mut cache.input);
        cache.hidden.resize_with(s.depth, Vec::new);
        for (i, l) in self.layers[..s.depth].iter().enumerate() {
            let (done, rest) = cache.hidden.split_at_mut(i);
            let a: &[T] = if i == 0 {
                &cache.input
            } else if Some(i - 1) == skip {
                concat_rows(
                    &cache.input,
                    in_dim,
                    &done[i - 1],
                    s.width,
                    n,
                    &mut scratch.cat,
                );
                &scratch.cat
            } else {
                &done[i - 1]
            };
            let z = &mut rest[0];
            self.linear(a, n, l, z);
            relu_inplace(z);
        }
        let head = *self.layers.last().expect("head layer");
        let last: &[T] = cache
            .hidden
            .last()
            .map(|h| h.as_slice())
            .unwrap_or(&cache.input);
        self.linear(last, n, &head, out);
    }

    /// `z = a · W + b` into `z` (resized).
    fn linear(&self, a: &[T], n: usize, l: &LayerLayout, z: &mut Vec<T>) {
        use rayon::prelude::*;
        fit(z, n * l.fan_out);
        let bias = &self.params[l.bias..l.bias + l.fan_out];
        z.par_chunks_mut(l.fan_out * 1024).for_each(|rows| {
            for row in rows.chunks_mut(l.fan_out) {
                row.copy_from_slice(bias);
            }
        });
        let w = View::new(
            &self.params[l.weight..l.bias],
            l.fan_in,
            l.fan_out,
            l.fan_out,
        );
        matmul(z, l.fan_out, View::new(a, n, l.fan_in, l.fan_in), w, true);
    }

    /// Backward pass: `grad_out` is `n × 10`; returns the gradient of every parameter
    /// (same layout as `params`). No gradient flows into x or t (the field sees the
    /// canonical positions detached, as in Deform-GS).
    pub fn backward(&self, cache: &MlpCache<T>, grad_out: &[T]) -> Vec<T> {
        let mut grads = Vec::new();
        self.backward_into(cache, grad_out, &mut MlpScratch::default(), &mut grads);
        grads
    }

    /// [`Self::backward`] into `grads` (overwritten, resized to the parameter count),
    /// with reused scratch buffers; same values as `backward`, bit for bit.
    pub fn backward_into(
        &self,
        cache: &MlpCache<T>,
        grad_out: &[T],
        scratch: &mut MlpScratch<T>,
        grads: &mut Vec<T>,
    ) {
        use rayon::prelude::*;
        let n = cache.n;
        let s = &self.settings;
        let in_dim = Self::input_dim(s);
        let skip = Self::skip_after(s);
        assert_eq!(grad_out.len(), n * self.settings.head_out());
        grads.clear();
        grads.resize(self.params.len(), T::ZERO);
        let head = *self.layers.last().expect("head layer");
        let last: &[T] = cache
            .hidden
            .last()
            .map(|h| h.as_slice())
            .unwrap_or(&cache.input);
        let MlpScratch { dz, da, cat } = scratch;
        dz.clear();
        dz.extend_from_slice(grad_out);
        self.linear_backward(last, dz, n, &head, grads, s.depth > 0, da);
        for i in (0..s.depth).rev() {
            let l = self.layers[i];
            // dz = da ⊙ [h > 0]
            std::mem::swap(dz, da);
            dz.par_chunks_mut(1 << 14)
                .zip(cache.hidden[i].par_chunks(1 << 14))
                .for_each(|(g, h)| {
                    for (g, &h) in g.iter_mut().zip(h) {
                        *g = if h > T::ZERO { *g } else { T::ZERO };
                    }
                });
            let a: &[T] = if i == 0 {
                &cache.input
            } else if Some(i - 1) == skip {
                concat_rows(&cache.input, in_dim, &cache.hidden[i - 1], s.width, n, cat);
                cat
            } else {
                &cache.hidden[i - 1]
            };
            let need_da = i > 0;
            self.linear_backward(a, dz, n, &l, grads, need_da, da);
            if i > 0 && Some(i - 1) == skip {
                // keep only the hidden part of the concatenated input's gradient
                let w = l.fan_in;
                fit(cat, n * s.width);
                cat.par_chunks_mut(s.width * 256)
                    .zip(da.par_chunks(w * 256))
                    .for_each(|(dst, src)| {
                        for (d, r) in dst.chunks_mut(s.width).zip(src.chunks(w)) {
                            d.copy_from_slice(&r[in_dim..]);
                        }
                    });
                std::mem::swap(da, cat);
            }
        }
    }

    /// Accumulate dW = aᵀ dz and db = Σ dz into `grads`; da = dz Wᵀ into `da` if asked.
    #[allow(clippy::too_many_arguments)]
    fn linear_backward(
        &self,
        a: &[T],
        dz: &[T],
        n: usize,
        l: &LayerLayout,
        grads: &mut [T],
        need_da: bool,
        da: &mut Vec<T>,
    ) {
        let va = View::new(a, n, l.fan_in, l.fan_in);
        let vdz = View::new(dz, n, l.fan_out, l.fan_out);
        matmul(&mut grads[l.weight..l.bias], l.fan_out, va.t(), vdz, true);
        column_sums(dz, l.fan_out, &mut grads[l.bias..l.bias + l.fan_out]);
        if !need_da {
            return;
        }
        fit(da, n * l.fan_in);
        let w = View::new(
            &self.params[l.weight..l.bias],
            l.fan_in,
            l.fan_out,
            l.fan_out,
        );
        matmul(da, l.fan_in, vdz, w.t(), false);
    }
}

/// Reusable buffers of [`Mlp::forward_into`] and [`Mlp::backward_into`] (their contents
/// between calls mean nothing).
#[derive(Clone, Debug, Default)]
pub struct MlpScratch<T> {
    dz: Vec<T>,
    da: Vec<T>,
    cat: Vec<T>,
}

/// Resize `v` to `len` keeping its allocation (contents are to be overwritten).
fn fit<T: Real>(v: &mut Vec<T>, len: usize) {
    v.truncate(len);
    v.resize(len, T::ZERO);
}

/// `acc[c] += Σ_r m[r][c]` over the rows of `m` (`cols` wide), rows in order for every
/// column (the serial loop's sums exactly), columns split across threads.
fn column_sums<T: Real>(m: &[T], cols: usize, acc: &mut [T]) {
    use rayon::prelude::*;
    const STRIP: usize = 16;
    acc.par_chunks_mut(STRIP).enumerate().for_each(|(k, acc)| {
        let c0 = k * STRIP;
        for row in m.chunks(cols) {
            for (g, &v) in acc.iter_mut().zip(&row[c0..]) {
                *g += v;
            }
        }
    });
}

fn relu_inplace<T: Real>(z: &mut [T]) {
    use rayon::prelude::*;
    z.par_chunks_mut(1 << 14).for_each(|c| {
        for v in c {
            // select form, so it vectorises
            *v = if *v > T::ZERO { *v } else { T::ZERO };
        }
    });
}

fn concat_rows<T: Real>(a: &[T], wa: usize, b: &[T], wb: usize, n: usize, out: &mut Vec<T>) {
    use rayon::prelude::*;
    fit(out, n * (wa + wb));
    out.par_chunks_mut((wa + wb) * 256)
        .enumerate()
        .for_each(|(c, rows)| {
            for (k, row) in rows.chunks_mut(wa + wb).enumerate() {
                let r = c * 256 + k;
                row[..wa].copy_from_slice(&a[r * wa..(r + 1) * wa]);
                row[wa..].copy_from_slice(&b[r * wb..(r + 1) * wb]);
            }
        });
}
