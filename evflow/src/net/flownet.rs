//! EV-FlowNet (Zhu et al. 2018; `docs/DESIGN.md` §5, `docs/REFERENCES.md` "EV-FlowNet")
//! written with burn 0.22.1 tensors on a run-time `Device` (flex CPU by default).
//!
//! Layout for base width `C` and a `B`-bin voxel grid `[1, B, H, W]`:
//! - encoders `enc1..enc4`: conv 3×3 stride 2 + ReLU, `C, 2C, 4C, 8C` channels;
//! - two residual blocks at `8C`: conv-ReLU-conv-ReLU, then `+ input`;
//! - decoders `dec0..dec3`: `concat(features, skip[, previous flow])`, nearest ×2
//!   upsampling, conv 3×3 + ReLU → `4C, 2C, C, C/2` channels;
//! - a flow head after each decoder: conv 1×1 → 2 channels, `tanh · max_flow`.
//!
//! Zero padding instead of reflect padding. Inputs whose size is not a multiple of 16
//! are zero-padded to one and the flow is cropped back.
//!
//! **Units**: the network's flow is the pixel displacement over the whole window
//! (px per window, u right, v down), at full input resolution. Divide by the window
//! length for px/s ([`px_per_window_to_px_per_s`]); `.evflow` files hold px/s.
//!
//! Every convolution is a [`Conv`] with an optional LoRA bypass ([`Lora`]); parameters
//! are plain tensors kept in a fixed, named order ([`layout`]) so the optimiser, the
//! weight files and LoRA adapters all address them by name. Reading and writing them is
//! `net::io`'s job, not this module's.

use super::lora::Lora;
use burn::tensor::module::{conv2d, interpolate};
use burn::tensor::ops::{ConvOptions, InterpolateMode, InterpolateOptions};
use burn::tensor::{DType, Device, Tensor, TensorData, activation::relu};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

/// Hyper-parameters of the flow network (stored in the weights' JSON sidecar).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct NetConfig {
    /// Base width C (the paper's network: 64).
    pub base: usize,
    /// Voxel-grid time bins B.
    pub bins: usize,
    /// Scale of the tanh heads: the largest flow the network can output, px per window.
    pub max_flow: f64,
}

impl Default for NetConfig {
    fn default() -> Self {
        NetConfig {
            base: 16,
            bins: 5,
            max_flow: 32.0,
        }
    }
}

/// One convolution: kernel `[out, in, k, k]`, bias `[out]`, stride, optional LoRA.
#[derive(Clone, Debug)]
pub struct Conv {
    pub name: String,
    pub weight: Tensor<4>,
    pub bias: Tensor<1>,
    pub stride: usize,
    pub lora: Option<Lora>,
}

impl Conv {
    /// Effective kernel: `W0 + (α/r)·B·A` when a LoRA adapter is attached.
    // Eq. 7
    pub fn kernel(&self) -> Tensor<4> {
        match &self.lora {
            None => self.weight.clone(),
            Some(l) => self.weight.clone() + l.delta(self.weight.dims()),
        }
    }

    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let k = self.weight.dims()[2];
        let opts = ConvOptions::new([self.stride; 2], [k / 2; 2], [1, 1], 1);
        conv2d(x, self.kernel(), Some(self.bias.clone()), opts)
    }

    pub fn shape(&self) -> [usize; 4] {
        self.weight.dims()
    }
}

/// The flow network: all convolutions in a fixed order (see [`layout`]).
#[derive(Clone, Debug)]
pub struct FlowNet {
    pub config: NetConfig,
    pub convs: Vec<Conv>,
    pub device: Device,
    pub dtype: DType,
}

/// Name, output channels, input channels, kernel size, stride of every convolution.
pub fn layout(cfg: &NetConfig) -> Vec<(String, usize, usize, usize, usize)> {
    let c = cfg.base;
    let half = (c / 2).max(1);
    let mut l = vec![
        ("enc1".to_string(), c, cfg.bins, 3, 2),
        ("enc2".to_string(), 2 * c, c, 3, 2),
        ("enc3".to_string(), 4 * c, 2 * c, 3, 2),
        ("enc4".to_string(), 8 * c, 4 * c, 3, 2),
    ];
    for r in 1..=2 {
        l.push((format!("res{r}a"), 8 * c, 8 * c, 3, 1));
        l.push((format!("res{r}b"), 8 * c, 8 * c, 3, 1));
    }
    // decoder inputs: concat(features, skip, previous flow)
    let dec = [
        (16 * c, 4 * c),
        (4 * c + 4 * c + 2, 2 * c),
        (2 * c + 2 * c + 2, c),
        (c + c + 2, half),
    ];
    for (i, (cin, cout)) in dec.into_iter().enumerate() {
        l.push((format!("dec{i}"), cout, cin, 3, 1));
        l.push((format!("flow{i}"), 2, cout, 1, 1));
    }
    l
}

/// px per window → px/s.
pub fn px_per_window_to_px_per_s(flow: f64, window_s: f64) -> f64 {
    if window_s > 0.0 { flow / window_s } else { 0.0 }
}

fn tensor_from(values: Vec<f64>, shape: &[usize], device: &Device, dtype: DType) -> TensorData {
    let _ = device;
    let data = TensorData::new(values, shape.to_vec());
    data.convert_dtype(dtype)
}

impl FlowNet {
    /// A freshly initialised network (Kaiming-normal kernels, zero biases), seeded.
    pub fn new(config: NetConfig, seed: u64, device: &Device, dtype: DType) -> FlowNet {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let convs = layout(&config)
            .into_iter()
            .map(|(name, out, inp, k, stride)| {
                let fan_in = (inp * k * k) as f64;
                let std = if name.starts_with("flow") {
                    0.1 / fan_in.sqrt()
                } else {
                    (2.0 / fan_in).sqrt()
                };
                let normal = Normal::new(0.0, std).expect("finite std");
                let w: Vec<f64> = (0..out * inp * k * k)
                    .map(|_| normal.sample(&mut rng))
                    .collect();
                let weight = Tensor::<4>::from_data(
                    tensor_from(w, &[out, inp, k, k], device, dtype),
                    (device, dtype),
                );
                let bias = Tensor::<1>::from_data(
                    tensor_from(vec![0.0; out], &[out], device, dtype),
                    (device, dtype),
                );
                Conv {
                    name,
                    weight,
                    bias,
                    stride,
                    lora: None,
                }
            })
            .collect();
        FlowNet {
            config,
            convs,
            device: device.clone(),
            dtype,
        }
    }

    pub fn conv(&self, name: &str) -> &Conv {
        self.convs
            .iter()
            .find(|c| c.name == name)
            .expect("conv name from layout()")
    }

    /// Number of base parameters (kernels and biases, without LoRA).
    pub fn param_count(&self) -> usize {
        self.convs
            .iter()
            .map(|c| c.shape().iter().product::<usize>() + c.shape()[0])
            .sum()
    }

    /// Forward pass on a voxel grid `[N, B, H, W]`: flows at 1/8, 1/4, 1/2 and full
    /// resolution, each `[N, 2, h, w]`, px per window (coarse levels in their own px).
    pub fn forward_all(&self, voxel: Tensor<4>) -> Vec<Tensor<4>> {
        let [n, b, h, w] = voxel.dims();
        assert_eq!(
            b, self.config.bins,
            "voxel grid has {b} bins, network expects {}",
            self.config.bins
        );
        let (hp, wp) = (h.div_ceil(16) * 16, w.div_ceil(16) * 16);
        let x = if (hp, wp) != (h, w) {
            let z = Tensor::<4>::zeros([n, b, hp, wp], (&self.device, self.dtype));
            z.slice_assign([0..n, 0..b, 0..h, 0..w], voxel)
        } else {
            voxel
        };
        let e1 = relu(self.conv("enc1").forward(x));
        let e2 = relu(self.conv("enc2").forward(e1.clone()));
        let e3 = relu(self.conv("enc3").forward(e2.clone()));
        let e4 = relu(self.conv("enc4").forward(e3.clone()));
        let mut f = e4.clone();
        for r in 1..=2 {
            let a = relu(self.conv(&format!("res{r}a")).forward(f.clone()));
            let bb = relu(self.conv(&format!("res{r}b")).forward(a));
            f = bb + f;
        }
        let skips = [e4, e3, e2, e1];
        let mut flows = Vec::with_capacity(4);
        let mut prev: Option<Tensor<4>> = None;
        for (i, skip) in skips.into_iter().enumerate() {
            let mut parts = vec![f, skip];
            if let Some(p) = prev.take() {
                parts.push(p);
            }
            let cat = Tensor::cat(parts, 1);
            let up = upsample2(cat);
            f = relu(self.conv(&format!("dec{i}")).forward(up));
            let flow = self
                .conv(&format!("flow{i}"))
                .forward(f.clone())
                .tanh()
                .mul_scalar(self.config.max_flow);
            prev = Some(flow.clone());
            flows.push(flow);
        }
        if (hp, wp) != (h, w) {
            let last = flows.pop().expect("four levels");
            flows.push(last.slice([0..n, 0..2, 0..h, 0..w]));
        }
        flows
    }

    /// Full-resolution flow `[N, 2, H, W]` in px per window.
    pub fn forward(&self, voxel: Tensor<4>) -> Tensor<4> {
        self.forward_all(voxel).pop().expect("four levels")
    }

    /// Every parameter with its name, in layout order: `NAME.weight`, `NAME.bias`.
    pub fn named_params(&self) -> Vec<(String, Tensor<4>)> {
        let mut v = Vec::new();
        for c in &self.convs {
            v.push((format!("{}.weight", c.name), c.weight.clone()));
            let [o] = c.bias.dims();
            v.push((
                format!("{}.bias", c.name),
                c.bias.clone().reshape([o, 1, 1, 1]),
            ));
        }
        v
    }

    /// Attach fresh LoRA adapters (rank `r`, scale `α/r`) to every convolution.
    pub fn attach_lora(&mut self, rank: usize, alpha: f64, seed: u64) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x10a4);
        for c in &mut self.convs {
            c.lora = Some(Lora::new(
                c.shape(),
                rank,
                alpha,
                &mut rng,
                &self.device,
                self.dtype,
            ));
        }
    }

    /// Fold every adapter into its kernel (`W0 ← W0 + (α/r)·B·A`) and drop it.
    pub fn merge_lora(&mut self) {
        for c in &mut self.convs {
            if c.lora.is_some() {
                c.weight = c.kernel().detach();
                c.lora = None;
            }
        }
    }

    /// Move every tensor to `requires_grad` according to the training mode: `full`
    /// trains the base weights, `lora` only the adapters (base frozen).
    pub fn set_trainable(&mut self, base: bool, lora: bool) {
        for c in &mut self.convs {
            c.weight = c.weight.clone().detach().set_require_grad(base);
            c.bias = c.bias.clone().detach().set_require_grad(base);
            if let Some(l) = &mut c.lora {
                l.a = l.a.clone().detach().set_require_grad(lora);
                l.b = l.b.clone().detach().set_require_grad(lora);
            }
        }
    }
}

/// Nearest-neighbour ×2 upsampling.
pub fn upsample2(x: Tensor<4>) -> Tensor<4> {
    let [_, _, h, w] = x.dims();
    interpolate(
        x,
        InterpolateOptions::new(InterpolateMode::Nearest).with_output_size([2 * h, 2 * w]),
    )
}
