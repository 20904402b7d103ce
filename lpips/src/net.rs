//! The two feature networks of LPIPS (torchvision's AlexNet and VGG16 `features`, up to
//! their last ReLU) as a list of layers, run with burn on the CPU, and the LPIPS head:
//! unit-normalised channel features, squared differences, a 1×1 linear layer per tap,
//! spatial mean, sum over taps.

use burn::tensor::activation::relu;
use burn::tensor::module::{conv2d, max_pool2d};
use burn::tensor::ops::{ConvOptions, MaxPoolOptions};
use burn::tensor::{DType, Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

/// Which feature network.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Variant {
    /// AlexNet (the LPIPS default; official calibration values exist for it).
    Alex,
    /// VGG16 (what the paper reports).
    Vgg,
}

impl Variant {
    pub fn name(self) -> &'static str {
        match self {
            Variant::Alex => "alex",
            Variant::Vgg => "vgg",
        }
    }

    /// The layers in order.
    pub fn layers(self) -> &'static [Layer] {
        use Layer::{Conv, Pool, Tap};
        match self {
            Variant::Alex => &[
                Conv { stride: 4, pad: 2 },
                Tap,
                Pool { size: 3, stride: 2 },
                Conv { stride: 1, pad: 2 },
                Tap,
                Pool { size: 3, stride: 2 },
                Conv { stride: 1, pad: 1 },
                Tap,
                Conv { stride: 1, pad: 1 },
                Tap,
                Conv { stride: 1, pad: 1 },
                Tap,
            ],
            Variant::Vgg => &VGG16,
        }
    }

    /// (out, in, kernel) of each convolution, in order.
    pub(crate) fn conv_shapes(self) -> &'static [(usize, usize, usize)] {
        match self {
            Variant::Alex => &[
                (64, 3, 11),
                (192, 64, 5),
                (384, 192, 3),
                (256, 384, 3),
                (256, 256, 3),
            ],
            Variant::Vgg => &[
                (64, 3, 3),
                (64, 64, 3),
                (128, 64, 3),
                (128, 128, 3),
                (256, 128, 3),
                (256, 256, 3),
                (256, 256, 3),
                (512, 256, 3),
                (512, 512, 3),
                (512, 512, 3),
                (512, 512, 3),
                (512, 512, 3),
                (512, 512, 3),
            ],
        }
    }

    /// Channels of each tap (the inputs of the linear layers).
    pub(crate) fn tap_channels(self) -> &'static [usize] {
        match self {
            Variant::Alex => &[64, 192, 384, 256, 256],
            Variant::Vgg => &[64, 128, 256, 512, 512],
        }
    }
}

const C1: Layer = Layer::Conv { stride: 1, pad: 1 };
const P2: Layer = Layer::Pool { size: 2, stride: 2 };
const VGG16: [Layer; 22] = [
    C1,
    C1,
    Layer::Tap,
    P2,
    C1,
    C1,
    Layer::Tap,
    P2,
    C1,
    C1,
    C1,
    Layer::Tap,
    P2,
    C1,
    C1,
    C1,
    Layer::Tap,
    P2,
    C1,
    C1,
    C1,
    Layer::Tap,
];

/// One step of a feature network.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layer {
    /// Convolution (the next weights) followed by ReLU.
    Conv { stride: usize, pad: usize },
    /// Max pooling without padding (floor mode).
    Pool { size: usize, stride: usize },
    /// The current activations feed LPIPS.
    Tap,
}

/// LPIPS' input scaling (its `ScalingLayer`): `(x − shift) / scale` per RGB channel of
/// an image in [−1, 1].
pub(crate) const SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
pub const SCALE: [f32; 3] = [0.458, 0.448, 0.450];

/// A feature network with its weights and the LPIPS linear layers.
pub struct Network {
    pub variant: Variant,
    /// (weight OIHW, bias) per convolution.
    pub convs: Vec<(Tensor<4>, Tensor<1>)>,
    /// Weights of the 1×1 linear layer of each tap (no bias).
    pub lins: Vec<Vec<f32>>,
    pub device: Device,
}

/// Activations of one tap for a batch: `[n, c, h, w]` values, row-major.
pub struct TapOut {
    pub shape: [usize; 4],
    pub values: Vec<f32>,
}

impl Network {
    /// The taps' activations for RGB images in [0, 1], `[n][h·w·3]` interleaved, all of
    /// size `w × h`.
    pub fn features(&self, images: &[&[f32]], w: usize, h: usize) -> Vec<TapOut> {
        let n = images.len();
        // NCHW, scaled as LPIPS: x ∈ [0,1] → 2x − 1 → (· − shift) / scale.
        let mut input = vec![0f32; n * 3 * h * w];
        for (k, img) in images.iter().enumerate() {
            for (p, px) in img.chunks_exact(3).enumerate() {
                for c in 0..3 {
                    input[((k * 3 + c) * h * w) + p] = (2.0 * px[c] - 1.0 - SHIFT[c]) / SCALE[c];
                }
            }
        }
        let data = TensorData::new(input, [n, 3, h, w]);
        let mut x = Tensor::<4>::from_data(data, (&self.device, DType::F32));
        let mut convs = self.convs.iter();
        let mut taps = Vec::new();
        for layer in self.variant.layers() {
            match *layer {
                Layer::Conv { stride, pad } => {
                    let (wt, b) = convs.next().expect("one weight per convolution");
                    let opts = ConvOptions::new([stride; 2], [pad; 2], [1, 1], 1);
                    x = relu(conv2d(x, wt.clone(), Some(b.clone()), opts));
                }
                Layer::Pool { size, stride } => {
                    x = max_pool2d(x, MaxPoolOptions::new([size; 2]).with_stride([stride; 2]));
                }
                Layer::Tap => {
                    let d = x.dims();
                    taps.push(TapOut {
                        shape: d,
                        values: x.clone().into_data().iter::<f32>().collect(),
                    });
                }
            }
        }
        taps
    }
}

/// The LPIPS distance map of one tap between images 0 and 1 of `t`: at each pixel,
/// `Σ_c w_c (f0_c/‖f0‖ − f1_c/‖f1‖)²` (norms over channels, + 1e-10 as LPIPS), `[h·w]`.
pub(crate) fn tap_distance(t: &TapOut, lin: &[f32]) -> Vec<f64> {
    let [n, c, h, w] = t.shape;
    assert!(
        n >= 2 && lin.len() == c,
        "two images and one weight per channel"
    );
    let hw = h * w;
    let f = |k: usize, ch: usize, p: usize| t.values[(k * c + ch) * hw + p] as f64;
    (0..hw)
        .map(|p| {
            let norm = |k| (0..c).map(|ch| f(k, ch, p).powi(2)).sum::<f64>().sqrt() + 1e-10;
            let (n0, n1) = (norm(0), norm(1));
            (0..c)
                .map(|ch| lin[ch] as f64 * (f(0, ch, p) / n0 - f(1, ch, p) / n1).powi(2))
                .sum()
        })
        .collect()
}

/// Bilinear resampling of a `w × h` map to `ow × oh`, as PyTorch's `Upsample(mode =
/// 'bilinear', align_corners = False)`: source coordinate `(dst + ½)·in/out − ½`,
/// clamped at 0, neighbours clamped at the border.
pub(crate) fn upsample_bilinear(
    map: &[f64],
    (w, h): (usize, usize),
    (ow, oh): (usize, usize),
) -> Vec<f64> {
    let axis = |o: usize, n: usize, out: usize| {
        let s = ((o as f64 + 0.5) * n as f64 / out as f64 - 0.5).max(0.0);
        let i0 = (s.floor() as usize).min(n - 1);
        (i0, (i0 + 1).min(n - 1), s - i0 as f64)
    };
    let mut out = Vec::with_capacity(ow * oh);
    for y in 0..oh {
        let (y0, y1, fy) = axis(y, h, oh);
        for x in 0..ow {
            let (x0, x1, fx) = axis(x, w, ow);
            let v = |yy: usize, xx: usize| map[yy * w + xx];
            let top = v(y0, x0) * (1.0 - fx) + v(y0, x1) * fx;
            let bottom = v(y1, x0) * (1.0 - fx) + v(y1, x1) * fx;
            out.push(top * (1.0 - fy) + bottom * fy);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layer_tables_match_the_weight_shapes() {
        for v in [Variant::Alex, Variant::Vgg] {
            let convs = v
                .layers()
                .iter()
                .filter(|l| matches!(l, Layer::Conv { .. }))
                .count();
            let taps = v
                .layers()
                .iter()
                .filter(|l| matches!(l, Layer::Tap))
                .count();
            assert_eq!(convs, v.conv_shapes().len());
            assert_eq!(taps, 5);
            // Each conv's input channels are the previous one's outputs.
            let s = v.conv_shapes();
            assert!(s.windows(2).all(|p| p[1].1 == p[0].0));
            assert_eq!(s[0].1, 3);
        }
        assert_eq!(Variant::Vgg.conv_shapes().len(), 13);
    }

    #[test]
    fn tap_distance_of_known_features() {
        // Two pixels, two channels: image 0 = (3, 4) and (1, 0); image 1 = (4, 3), (0, 2).
        // Unit vectors (0.6, 0.8) vs (0.8, 0.6): squared differences 0.04, 0.04; (1, 0)
        // vs (0, 1): 1, 1. Weights (1, 2): 0.12 and 3.
        let t = TapOut {
            shape: [2, 2, 1, 2],
            values: vec![3.0, 1.0, 4.0, 0.0, 4.0, 0.0, 3.0, 2.0],
        };
        let d = tap_distance(&t, &[1.0, 2.0]);
        assert!(
            (d[0] - 0.12).abs() < 1e-9 && (d[1] - 3.0).abs() < 1e-9,
            "{d:?}"
        );
    }

    #[test]
    fn bilinear_upsampling_as_pytorch() {
        // torch: F.interpolate([[[[1, 2], [3, 4]]]], size=(4, 4), mode='bilinear',
        // align_corners=False)[0, 0, 0] = [1.0, 1.25, 1.75, 2.0], row 1 = [1.5, 1.75,
        // 2.25, 2.5].
        let up = upsample_bilinear(&[1.0, 2.0, 3.0, 4.0], (2, 2), (4, 4));
        assert_eq!(&up[..8], &[1.0, 1.25, 1.75, 2.0, 1.5, 1.75, 2.25, 2.5]);
        // The mean of a constant map stays; a 1×1 map is spread everywhere.
        assert!(
            upsample_bilinear(&[0.7], (1, 1), (3, 5))
                .iter()
                .all(|&v| v == 0.7)
        );
    }
}
