//! The flow network (EV-FlowNet with LoRA adapters) in one folder:
//!
//! - [`flownet`]: the network itself ([`FlowNet`], [`NetConfig`], the layer [`layout`]);
//! - [`lora`]: LoRA adapters on its convolutions, the math only;
//! - [`tensor`]: conversions between burn tensors and plain vectors;
//! - [`adam`]: Adam steps on the trainable tensors (`stagekit::optim::Adam`);
//! - [`io`]: every weight and adapter file (safetensors, JSON sidecars, bare weights).
//!
//! Dependencies point one way: `io` → `flownet` → `lora`, never back.

pub mod adam;
pub mod flownet;
pub mod io;
pub mod lora;
pub mod tensor;

pub use adam::{adam_step, adam_step_conv};
pub use flownet::{Conv, FlowNet, NetConfig, layout, px_per_window_to_px_per_s, upsample2};
pub use lora::Lora;
pub use tensor::{tensor4, to_f32, to_f64};
