//! LoRA adapters on convolutions (paper Eq. 7; `docs/REFERENCES.md` "LoRA on
//! convolutions"): the math only.
//!
//! A kernel `W0` of shape `[out, in, k, k]` is seen as the matrix `[out, in·k·k]`; the
//! adapter adds `ΔW = (α/r)·B·A` with `A: [r, in·k·k]` Gaussian (std `1/√(in·k·k)`)
//! and `B: [out, r]` zero, so at initialisation the network is exactly the base one.
//! `W0` stays frozen during LoCM. Adapters can be merged into the kernels
//! (`FlowNet::merge_lora`); `net::io` saves and loads them on their own.

use burn::tensor::{DType, Device, Tensor, TensorData};
use rand_distr::{Distribution, Normal};

/// One adapter.
#[derive(Clone, Debug)]
pub struct Lora {
    /// `[r, in·k·k]`.
    pub a: Tensor<2>,
    /// `[out, r]`.
    pub b: Tensor<2>,
    pub rank: usize,
    pub alpha: f64,
}

impl Lora {
    pub fn new(
        shape: [usize; 4],
        rank: usize,
        alpha: f64,
        rng: &mut impl rand::Rng,
        device: &Device,
        dtype: DType,
    ) -> Lora {
        let [out, inp, kh, kw] = shape;
        let fan = inp * kh * kw;
        let normal = Normal::new(0.0, 1.0 / (fan as f64).sqrt()).expect("finite std");
        let a: Vec<f64> = (0..rank * fan).map(|_| normal.sample(rng)).collect();
        let a = Tensor::<2>::from_data(
            TensorData::new(a, [rank, fan]).convert_dtype(dtype),
            (device, dtype),
        );
        let b = Tensor::<2>::zeros([out, rank], (device, dtype));
        Lora { a, b, rank, alpha }
    }

    /// `(α/r)·B·A` reshaped to the kernel.
    // Eq. 7
    pub fn delta(&self, shape: [usize; 4]) -> Tensor<4> {
        self.b
            .clone()
            .matmul(self.a.clone())
            .mul_scalar(self.alpha / self.rank as f64)
            .reshape(shape)
    }
}
