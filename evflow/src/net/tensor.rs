//! Conversions between burn tensors and plain vectors (any float dtype).

use burn::tensor::{DType, Device, Tensor, TensorData};

/// Flatten a tensor into f64 values (any float dtype).
pub fn to_f64<const D: usize>(t: Tensor<D>) -> Vec<f64> {
    t.into_data().iter::<f64>().collect()
}

/// Flatten a tensor into f32 values (any float dtype).
pub fn to_f32<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().iter::<f32>().collect()
}

/// A tensor of the given shape from f32 values, in the network's dtype.
pub fn tensor4(values: Vec<f32>, shape: [usize; 4], device: &Device, dtype: DType) -> Tensor<4> {
    Tensor::<4>::from_data(
        TensorData::new(values, shape).convert_dtype(dtype),
        (device, dtype),
    )
}
