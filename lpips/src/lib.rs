//! `lpips` — the LPIPS perceptual distance (Zhang et al. 2018, v0.1 linear layers) with
//! AlexNet or VGG16 features, on the CPU (`docs/DESIGN.md` §5, "Metrics").
//!
//! `d(x0, x1) = Σ_l mean_hw ( w_l · (f̂0_l − f̂1_l)² )`, with `f̂` the channel-normalised
//! activations of tap `l` of the network fed `(2x − 1 − shift) / scale`. The weights are
//! fetched and converted at first use ([`fetch`]); see [`Lpips::load`].

pub mod fetch;
pub mod net;
pub mod pickle;
pub mod weights;

pub use net::Variant;
use scene::error::{Error, Result};
use std::path::{Path, PathBuf};

/// An RGB image, values in [0, 1], interleaved row-major (`w · h · 3`).
#[derive(Clone, Copy, Debug)]
pub struct Rgb<'a> {
    pub data: &'a [f32],
    pub width: usize,
    pub height: usize,
}

/// The LPIPS metric with one feature network.
pub struct Lpips {
    net: net::Network,
    /// The weights file it was loaded from.
    pub weights: PathBuf,
}

impl Lpips {
    /// Load the weights of `v` from the cache, fetching and converting them first when
    /// they are not there; `Err` says why they cannot be had (offline, no cache
    /// directory, a bad download) and what to do.
    pub fn load(v: Variant) -> Result<Lpips> {
        let dir = fetch::cache_dir()?;
        let (bytes, path) = fetch::ensure(&dir, v)?;
        Ok(Lpips {
            net: weights::load_network(&bytes, &path, v)?,
            weights: path,
        })
    }

    /// Load the weights of `v` only if they are already in the cache (never downloads).
    pub fn load_cached(v: Variant) -> Result<Lpips> {
        let path = fetch::weights_path(&fetch::cache_dir()?, v);
        let bytes = std::fs::read(&path)
            .map_err(|_| Error::Other(format!("no LPIPS weights at {}", path.display())))?;
        if blake3::hash(&bytes).to_hex().as_str() != fetch::converted_blake3(v) {
            return Err(Error::invalid(
                &path,
                "not the expected LPIPS weights (hash)",
            ));
        }
        Ok(Lpips {
            net: weights::load_network(&bytes, &path, v)?,
            weights: path,
        })
    }

    /// Load converted weights from `path` (no hash check: for other conversions).
    pub fn from_file(path: &Path, v: Variant) -> Result<Lpips> {
        Ok(Lpips {
            net: weights::read_network(path, v)?,
            weights: path.to_path_buf(),
        })
    }

    pub fn variant(&self) -> Variant {
        self.net.variant
    }

    /// The LPIPS distance of two images of the same size (the spatial mean of each
    /// tap's map, summed: what `lpips.LPIPS(net)(x0, x1)` returns).
    pub fn distance(&self, a: Rgb, b: Rgb) -> Result<f64> {
        Ok(self.maps(a, b)?.iter().map(|(m, _)| mean(m)).sum())
    }

    /// The mean of the spatial distance map upsampled to the image size (what the
    /// official `test_network.py` prints, with `spatial=True`); close to
    /// [`Lpips::distance`], not equal.
    pub fn distance_spatial_mean(&self, a: Rgb, b: Rgb) -> Result<f64> {
        Ok(mean(&self.distance_and_map(a, b)?.map))
    }

    /// [`Lpips::distance`] and the spatial distance map at the image size (`w · h`,
    /// row-major: each tap's map upsampled bilinearly and summed, the official
    /// `spatial=True` output), from one pass of the network. The map's mean over a mask
    /// is the masked LPIPS ([`Scored::masked_mean`]).
    pub fn distance_and_map(&self, a: Rgb, b: Rgb) -> Result<Scored> {
        let size = (a.width, a.height);
        let taps = self.maps(a, b)?;
        let mut map = vec![0.0; a.width * a.height];
        for (m, wh) in &taps {
            for (o, v) in map.iter_mut().zip(net::upsample_bilinear(m, *wh, size)) {
                *o += v;
            }
        }
        Ok(Scored {
            distance: taps.iter().map(|(m, _)| mean(m)).sum(),
            map,
        })
    }

    /// Per tap: the distance map and its (w, h).
    fn maps(&self, a: Rgb, b: Rgb) -> Result<Vec<TapMap>> {
        check_pair(self.variant(), a, b)?;
        let (w, h) = (a.width, a.height);
        let taps = self.net.features(&[a.data, b.data], w, h);
        Ok(taps
            .iter()
            .zip(&self.net.lins)
            .map(|(t, lin)| (net::tap_distance(t, lin), (t.shape[3], t.shape[2])))
            .collect())
    }
}

/// A tap's distance map and its (w, h).
type TapMap = (Vec<f64>, (usize, usize));

/// One image pair's LPIPS ([`Lpips::distance_and_map`]).
#[derive(Clone, Debug)]
pub struct Scored {
    /// The distance ([`Lpips::distance`]).
    pub distance: f64,
    /// The spatial map at the image size, row-major.
    pub map: Vec<f64>,
}

impl Scored {
    /// The map's mean over the pixels where `mask` holds (masked LPIPS, as the masked
    /// PSNR of Gao et al. 2022); None where it holds nowhere. `Err` when the mask is not
    /// the map's size.
    pub fn masked_mean(&self, mask: &[bool]) -> Result<Option<f64>> {
        if mask.len() != self.map.len() {
            return Err(Error::Other(format!(
                "a mask of {} pixels for an LPIPS map of {}",
                mask.len(),
                self.map.len()
            )));
        }
        let (sum, n) = (self.map.iter().zip(mask))
            .filter(|(_, m)| **m)
            .fold((0.0, 0usize), |(s, n), (v, _)| (s + v, n + 1));
        Ok((n > 0).then(|| sum / n as f64))
    }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Whether `a` and `b` can be compared by the `v` network: the same size, `w · h · 3`
/// values each, and at least the network's smallest input (no weights needed).
pub fn check_pair(v: Variant, a: Rgb, b: Rgb) -> Result<()> {
    let (w, h) = (a.width, a.height);
    if (b.width, b.height) != (w, h) {
        return Err(Error::Other(format!(
            "LPIPS of images of different sizes: {w}x{h} and {}x{}",
            b.width, b.height
        )));
    }
    for img in [a, b] {
        if img.data.len() != w * h * 3 {
            return Err(Error::Other(format!(
                "an RGB image of {w}x{h} has {} values, not {}",
                img.data.len(),
                w * h * 3
            )));
        }
    }
    // AlexNet's first conv (11×11, stride 4) and two 3×3 pools need ≥ 31 px;
    // VGG's four 2×2 pools need ≥ 16 px.
    let min = match v {
        Variant::Alex => 31,
        Variant::Vgg => 16,
    };
    if w < min || h < min {
        return Err(Error::Other(format!(
            "LPIPS ({}) needs images of at least {min}x{min} px, got {w}x{h}",
            v.name()
        )));
    }
    Ok(())
}
