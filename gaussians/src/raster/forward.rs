//! Forward pass: project every Gaussian (rayon), sort the visible ones by depth, bin
//! them into 16×16 tiles (a stable counting sort, so every tile list stays in depth
//! order), then composite each tile front to back (DEGS Eq. 1) in parallel.

use super::alpha::{T_MIN, eval_alpha};
use super::project::{CamSetup, ScreenGrad};
use super::project_lanes::{Projection, project_span};
use super::rasterizer::RenderedImage;
use super::simd::{self, F4, Lanes, Mask};
use crate::splats::Splats;
use rayon::prelude::*;

/// Tile side in pixels.
pub const TILE: usize = 16;

/// Everything the backward needs from a forward pass.
pub struct RenderState {
    pub(crate) cam: CamSetup,
    pub(crate) sh_degree: u32,
    pub(crate) background: [f32; 3],
    pub(crate) n: usize,
    pub(crate) proj: Projected,
    pub(crate) tiles: Tiles,
    pub(crate) radius: Vec<f32>,
    pub(crate) t_final: Vec<f32>,
    /// Per pixel: number of entries of its tile list processed up to and including the
    /// last one that contributed.
    pub(crate) last: Vec<u32>,
    /// Buffers of the forward pass, kept for the next render into this state.
    scratch: ForwardScratch,
    /// Buffers of the backward pass (behind a lock: the backward borrows the state).
    pub(crate) back: std::sync::Mutex<BackScratch>,
}

/// Reused buffers of the backward pass (kept in the [`RenderState`]).
#[derive(Default)]
pub(crate) struct BackScratch {
    /// Screen gradient per (Gaussian, tile) pair.
    pub pairs: Vec<ScreenGrad>,
    /// Per projected Gaussian: the sum of its pairs.
    pub screen: Vec<ScreenGrad>,
    /// Per input Gaussian: its index into the projected ones (`u32::MAX`: culled).
    pub slot: Vec<u32>,
}

/// Reused buffers of [`render_into`].
#[derive(Default)]
struct ForwardScratch {
    splats: Vec<Projection>,
    order: Vec<(u32, u32)>,
    fill: Vec<u32>,
    outs: Vec<TileOut>,
}

impl RenderState {
    /// A state with no render in it, whose buffers [`render_into`] fills and reuses.
    pub(crate) fn empty(cam: &CamSetup) -> Self {
        RenderState {
            cam: *cam,
            sh_degree: 0,
            background: [0.0; 3],
            n: 0,
            proj: Projected::default(),
            tiles: Tiles::default(),
            radius: Vec::new(),
            t_final: Vec::new(),
            last: Vec::new(),
            scratch: ForwardScratch::default(),
            back: Default::default(),
        }
    }
    /// The visible Gaussians in depth order.
    pub fn projected(&self) -> &Projected {
        &self.proj
    }
    /// Screen radius per input Gaussian (0 = culled).
    pub fn radius(&self) -> &[f32] {
        &self.radius
    }
    /// Number of (Gaussian, tile) pairs composited.
    pub fn pairs(&self) -> usize {
        self.tiles.list.len()
    }
}

/// Visible projected Gaussians in depth order (struct of arrays).
#[derive(Clone, Debug, Default)]
pub struct Projected {
    /// Index into the input `Splats`.
    pub id: Vec<u32>,
    pub xy: Vec<[f32; 2]>,
    pub conic: Vec<[f32; 3]>,
    pub opacity: Vec<f32>,
    pub color: Vec<[f32; 3]>,
    pub depth: Vec<f32>,
    /// Inclusive pixel box `[x0, x1, y0, y1]`.
    pub bbox: Vec<[u32; 4]>,
    /// Largest composited `dᵀΣ⁻¹d` (see [`super::project::reach`]).
    pub cut: Vec<f32>,
}

impl Projected {
    /// Empty, with room for `n` (allocations kept).
    fn clear_for(&mut self, n: usize) {
        self.id.clear();
        self.xy.clear();
        self.conic.clear();
        self.opacity.clear();
        self.color.clear();
        self.depth.clear();
        self.bbox.clear();
        self.cut.clear();
        self.id.reserve(n);
        self.xy.reserve(n);
        self.conic.reserve(n);
        self.opacity.reserve(n);
        self.color.reserve(n);
        self.depth.reserve(n);
        self.bbox.reserve(n);
        self.cut.reserve(n);
    }
}

/// Columns `[lo, hi)` (tile-relative, within `[x0, x1)`) of the row at offset `dy` from
/// the mean where `dᵀQd ≤ cut` can hold; empty when the row misses the ellipse.
#[inline(always)]
pub(crate) fn row_span(
    conic: [f32; 3],
    cut: f32,
    u: f32,
    dy: f32,
    xr: [usize; 3],
) -> (usize, usize) {
    let [x0, x1, base] = xr;
    let [a, b, c] = conic;
    let disc = b * b * dy * dy - a * (c * dy * dy - cut);
    if !(disc >= 0.0) {
        return (0, 0);
    }
    let (mid, half) = (u - b * dy / a, disc.sqrt() / a);
    let lo = ((mid - half - 0.01).ceil().max(x0 as f32) as usize).max(x0);
    let hi = (((mid + half + 0.01).floor() + 1.0).max(0.0) as usize).min(x1);
    if lo >= hi {
        return (0, 0);
    }
    (lo - base, hi - base)
}

/// Per-pixel planes of one tile, row-major `[row][column]`.
pub(crate) type Plane<T> = [[T; TILE]; TILE];

/// One tile's composited output, before it is scattered into the frame.
struct TileOut {
    rgb: [Plane<f32>; 3],
    depth: Plane<f32>,
    t: Plane<f32>,
    /// Entries processed up to the last contributor (f32 for vector selects; exact
    /// below 2^24).
    last: Plane<f32>,
}

#[derive(Default)]
pub(crate) struct Tiles {
    pub nx: usize,
    pub ny: usize,
    /// `ranges[t]..ranges[t + 1]` indexes `list` for tile `t`.
    pub ranges: Vec<u32>,
    /// Indices into [`Projected`], depth-ordered within each tile.
    pub list: Vec<u32>,
}

impl Tiles {
    pub fn of(&self, t: usize) -> &[u32] {
        &self.list[self.ranges[t] as usize..self.ranges[t + 1] as usize]
    }
    /// Pixel rectangle `[x0, x1, y0, y1]` (exclusive ends) of tile `t`.
    pub fn rect(&self, t: usize, width: usize, height: usize) -> [usize; 4] {
        let (tx, ty) = (t % self.nx, t / self.nx);
        [
            tx * TILE,
            ((tx + 1) * TILE).min(width),
            ty * TILE,
            ((ty + 1) * TILE).min(height),
        ]
    }
}

/// Project all Gaussians: the visible ones in depth order into `p`, every radius into
/// `radius` (both overwritten; allocations reused).
fn project_all(
    s: &Splats,
    cam: &CamSetup,
    sh_degree: u32,
    sc: &mut ForwardScratch,
    p: &mut Projected,
    radius: &mut Vec<f32>,
) {
    // Blocks of 256 (a multiple of every lane count) over the threads.
    const BLOCK: usize = 256;
    sc.splats.clear();
    sc.splats.resize(s.len(), (0.0, None));
    sc.splats
        .par_chunks_mut(BLOCK)
        .enumerate()
        .for_each(|(c, out)| project_span(s, c * BLOCK, cam, sh_degree, out));
    let splats = &sc.splats;
    radius.clear();
    radius.extend(splats.iter().map(|g| g.0));
    let order = &mut sc.order;
    order.clear();
    order.extend(
        splats
            .iter()
            .enumerate()
            .filter_map(|(i, g)| g.1.as_ref().map(|g| (g.depth.to_bits(), i as u32))),
    );
    // Depth > 0, so the IEEE bit pattern orders like the value; ties by index.
    order.par_sort_unstable();
    p.clear_for(order.len());
    for &(_, i) in order.iter() {
        let g = splats[i as usize].1.as_ref().expect("visible");
        p.id.push(i);
        p.xy.push(g.xy);
        p.conic.push(g.conic);
        p.opacity.push(g.opacity);
        p.color.push(g.color);
        p.depth.push(g.depth);
        p.bbox.push(g.bbox);
        p.cut.push(g.cut);
    }
}

/// Counting sort of (Gaussian, tile) pairs by tile, stable in depth order, into `tiles`
/// (overwritten; allocations reused).
fn bin(p: &Projected, width: usize, height: usize, fill: &mut Vec<u32>, tiles: &mut Tiles) {
    let nx = width.div_ceil(TILE);
    let ny = height.div_ceil(TILE);
    tiles.nx = nx;
    tiles.ny = ny;
    let counts = &mut tiles.ranges;
    counts.clear();
    counts.resize(nx * ny + 1, 0);
    let tiles_of = |b: &[u32; 4]| {
        let (tx0, tx1) = (b[0] as usize / TILE, b[1] as usize / TILE);
        let (ty0, ty1) = (b[2] as usize / TILE, b[3] as usize / TILE);
        (ty0..=ty1).flat_map(move |ty| (tx0..=tx1).map(move |tx| ty * nx + tx))
    };
    for b in &p.bbox {
        for t in tiles_of(b) {
            counts[t + 1] += 1;
        }
    }
    for t in 0..nx * ny {
        counts[t + 1] += counts[t];
    }
    fill.clone_from(counts);
    let list = &mut tiles.list;
    list.clear();
    list.resize(counts[nx * ny] as usize, 0);
    for (k, b) in p.bbox.iter().enumerate() {
        for t in tiles_of(b) {
            list[fill[t] as usize] = k as u32;
            fill[t] += 1;
        }
    }
}

/// Bits of the lanes `[lo, hi)` of a tile row (a Gaussian's box within the tile).
#[inline(always)]
pub(crate) fn lane_bits(lo: usize, hi: usize) -> u32 {
    ((1u64 << hi) - 1) as u32 & !((1u32 << lo) - 1)
}

/// Composite one tile front to back with the widest lanes this CPU has.
fn tile_forward(p: &Projected, list: &[u32], r: [usize; 4]) -> TileOut {
    #[cfg(target_arch = "x86_64")]
    if simd::use_wide() {
        // SAFETY: `use_wide` checked that the CPU has AVX-512F.
        return unsafe { tile_forward_avx512(p, list, r) };
    }
    tile_forward_lanes::<F4>(p, list, r)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn tile_forward_avx512(p: &Projected, list: &[u32], r: [usize; 4]) -> TileOut {
    tile_forward_lanes::<simd::F16>(p, list, r)
}

impl TileOut {
    fn blank() -> Self {
        TileOut {
            rgb: [[[0.0; TILE]; TILE]; 3],
            depth: [[0.0; TILE]; TILE],
            t: [[1.0; TILE]; TILE],
            last: [[0.0; TILE]; TILE],
        }
    }
}

/// What a front-to-back walk over one tile ([`walk_tile`]) does with the Gaussians'
/// blending weights: the forward composites colour and depth, the contribution pass
/// sums each Gaussian's weight. Monomorphised and inlined into each walk.
pub(crate) trait TileSink<V: Lanes> {
    /// Entry `k` of the tile's list, Gaussian `g`, comes next.
    fn gaussian(&mut self, p: &Projected, k: usize, g: usize);
    /// Its blending weights `w = α·T` on the lanes `lanes` of tile row `row`; `used`
    /// marks the lanes it composites on (`w` is 0 on the others).
    fn chunk(&mut self, row: usize, lanes: std::ops::Range<usize>, w: V, used: V::M);
    /// Done with entry `k`.
    fn done(&mut self, k: usize);
}

/// Walk one tile front to back: Gaussian-outer, then for each row of the Gaussian's box
/// the lane chunks that meet its ellipse; per lane branch-free (masked lanes get α = 0).
/// `tt` is the tile's transmittance (all 1 at the start, final T at the end); a pixel
/// stops before the Gaussian that would take its T below `T_MIN`.
// Eq. 1: C = Σᵢ cᵢ αᵢ Πⱼ₍ⱼ<ᵢ₎ (1 − αⱼ), front to back (depth and alpha alike).
#[inline(always)]
pub(crate) fn walk_tile<V: Lanes, S: TileSink<V>>(
    p: &Projected,
    list: &[u32],
    r: [usize; 4],
    tt: &mut Plane<f32>,
    sink: &mut S,
) {
    let n = V::N;
    let chunk_bits = lane_bits(0, n);
    // Bit per pixel of each row: set while the pixel still composites.
    let mut active = [lane_bits(0, r[1] - r[0]); TILE];
    let mut remaining = ((r[1] - r[0]) * (r[3] - r[2])) as u32;
    let s = V::splat;
    let xs: [V; 4] = std::array::from_fn(|c| V::iota((r[0] + (c * n) % TILE) as f32));
    for (k, &g) in list.iter().enumerate() {
        if remaining == 0 {
            break;
        }
        let g = g as usize;
        let b = p.bbox[g];
        let (x0, x1) = ((b[0] as usize).max(r[0]), (b[1] as usize + 1).min(r[1]));
        let (y0, y1) = ((b[2] as usize).max(r[2]), (b[3] as usize + 1).min(r[3]));
        let [u, v] = p.xy[g];
        let (conic, op, u4) = (p.conic[g], p.opacity[g], s(u));
        sink.gaussian(p, k, g);
        for y in y0..y1 {
            let row = y - r[2];
            let dyf = y as f32 - v;
            // One vector covers the row: the ellipse test per lane is enough. Narrow
            // lanes skip the chunks outside the ellipse's span on this row.
            let (lo, hi) = if n == TILE {
                (x0 - r[0], x1 - r[0])
            } else {
                row_span(conic, p.cut[g], u, dyf, [x0, x1, r[0]])
            };
            let inb = lane_bits(lo, hi);
            let dy = s(dyf);
            for c in lo / n..hi.div_ceil(n) {
                let bits = (inb & active[row]) >> (n * c) & chunk_bits;
                if bits == 0 {
                    continue;
                }
                let l = n * c..n * c + n;
                let (a0, _) = eval_alpha(conic, op, xs[c] - u4, dy);
                let a0 = a0.and(V::M::from_bits(bits));
                let t = V::load(&tt[row][l.clone()]);
                let test_t = t * (s(1.0) - a0);
                let stop = a0.gt(s(0.0)).and(test_t.lt(s(T_MIN)));
                let sb = stop.bits();
                active[row] &= !(sb << (n * c));
                remaining -= sb.count_ones();
                // Lanes that stop take nothing: α = 0 leaves colour and T as they are
                // (`T·(1 − 0)` is T exactly).
                let used = a0.gt(s(0.0)).and(V::M::from_bits(!sb));
                let w = a0.and(used) * t;
                sink.chunk(row, l.clone(), w, used);
                V::select(used, test_t, t).store(&mut tt[row][l]);
            }
        }
        sink.done(k);
    }
}

/// The forward's sink: colour, depth and the last contributing entry per pixel.
struct Composite<'a, V> {
    rgb: &'a mut [Plane<f32>; 3],
    depth: &'a mut Plane<f32>,
    last: &'a mut Plane<f32>,
    col: [V; 3],
    dep: V,
    kk: V,
}

impl<V: Lanes> TileSink<V> for Composite<'_, V> {
    #[inline(always)]
    fn gaussian(&mut self, p: &Projected, k: usize, g: usize) {
        self.col = p.color[g].map(V::splat);
        self.dep = V::splat(p.depth[g]);
        self.kk = V::splat((k + 1) as f32);
    }

    #[inline(always)]
    fn chunk(&mut self, row: usize, l: std::ops::Range<usize>, w: V, used: V::M) {
        for ch in 0..3 {
            let dst = &mut self.rgb[ch][row][l.clone()];
            w.mul_add(self.col[ch], V::load(dst)).store(dst);
        }
        let dst = &mut self.depth[row][l.clone()];
        w.mul_add(self.dep, V::load(dst)).store(dst);
        let dst = &mut self.last[row][l];
        V::select(used, self.kk, V::load(dst)).store(dst);
    }

    #[inline(always)]
    fn done(&mut self, _k: usize) {}
}

/// Composite one tile ([`walk_tile`] with the colour, depth and last-entry sink).
#[inline(always)]
fn tile_forward_lanes<V: Lanes>(p: &Projected, list: &[u32], r: [usize; 4]) -> TileOut {
    let mut o = TileOut::blank();
    let zero = V::splat(0.0);
    let mut sink = Composite {
        rgb: &mut o.rgb,
        depth: &mut o.depth,
        last: &mut o.last,
        col: [zero; 3],
        dep: zero,
        kk: zero,
    };
    walk_tile(p, list, r, &mut o.t, &mut sink);
    o
}

/// Render; fills the frame and the per-pixel state the backward needs.
pub(crate) fn render(
    s: &Splats,
    cam: &CamSetup,
    sh_degree: u32,
    background: [f32; 3],
) -> (RenderedImage, RenderState) {
    let mut f = RenderedImage::default();
    let mut st = RenderState::empty(cam);
    render_into(s, cam, sh_degree, background, &mut f, &mut st);
    (f, st)
}

/// [`render`] into an image and a state from an earlier render (both overwritten, the
/// same values bit for bit; their buffers reused).
pub(crate) fn render_into(
    s: &Splats,
    cam: &CamSetup,
    sh_degree: u32,
    background: [f32; 3],
    f: &mut RenderedImage,
    st: &mut RenderState,
) {
    let (w, h) = (cam.width, cam.height);
    st.cam = *cam;
    st.sh_degree = sh_degree;
    st.background = background;
    st.n = s.len();
    let sc = &mut st.scratch;
    project_all(s, cam, sh_degree, sc, &mut st.proj, &mut st.radius);
    bin(&st.proj, w, h, &mut sc.fill, &mut st.tiles);
    let (proj, tiles) = (&st.proj, &st.tiles);
    let ntiles = tiles.nx * tiles.ny;
    (0..ntiles)
        .into_par_iter()
        .map(|t| tile_forward(proj, tiles.of(t), tiles.rect(t, w, h)))
        .collect_into_vec(&mut sc.outs);
    let np = w * h;
    f.width = w;
    f.height = h;
    for (v, len) in [
        (&mut f.rgb, 3 * np),
        (&mut f.depth, np),
        (&mut f.alpha, np),
        (&mut st.t_final, np),
    ] {
        v.resize(len, 0.0);
    }
    st.last.resize(np, 0);
    // Scatter the tiles into the frame, rayon over rows of tiles (each a band of
    // `TILE` image rows in every plane).
    let band = TILE * w;
    let (r, rest) = f.rgb.split_at_mut(np);
    let (g, b) = rest.split_at_mut(np);
    let outs = &sc.outs;
    (
        r.par_chunks_mut(band),
        g.par_chunks_mut(band),
        b.par_chunks_mut(band),
        f.depth.par_chunks_mut(band),
        f.alpha.par_chunks_mut(band),
        st.t_final.par_chunks_mut(band),
        st.last.par_chunks_mut(band),
    )
        .into_par_iter()
        .enumerate()
        .for_each(|(ty, (r, g, b, depth, alpha, t_final, last))| {
            let rgb = [r, g, b];
            for tx in 0..tiles.nx {
                let t = ty * tiles.nx + tx;
                let o = &outs[t];
                let rc = tiles.rect(t, w, h);
                for y in rc[2]..rc[3] {
                    for x in rc[0]..rc[1] {
                        let (oy, ox) = (y - rc[2], x - rc[0]);
                        let pix = oy * w + x;
                        let tt = o.t[oy][ox];
                        for c in 0..3 {
                            rgb[c][pix] = o.rgb[c][oy][ox] + tt * background[c];
                        }
                        depth[pix] = o.depth[oy][ox];
                        alpha[pix] = 1.0 - tt;
                        t_final[pix] = tt;
                        last[pix] = o.last[oy][ox] as u32;
                    }
                }
            }
        });
}
